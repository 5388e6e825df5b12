"""The package's shape, checked: sizes, parameter counts, layering and import cycles.

Read from the source with `ast`, nothing is imported: a module over 500 lines, a function over 80, a class over
350, a function taking more than 8 parameters (:data:`MAX_PARAMETERS`; the flat-tensor kernels of
:data:`MANY_PARAMETERS` excepted), Hydra imported outside `pathrl/cli`, an import of a higher layer (:data:`LAYERS`)
or a cycle of imports fails here with the offending names. Imports count wherever they are made, inside functions
too (a function-level import is a dependency all the same, only a later one); an import under
``if TYPE_CHECKING:`` (annotations only) does not.
"""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "pathrl"
MAX_MODULE_LINES, MAX_FUNCTION_LINES, MAX_CLASS_LINES = 500, 80, 350
#: Most parameters a function or method takes (self / cls not counted; ``*args`` and ``**kwargs`` one each): more
#: go into a small frozen dataclass of related settings.
MAX_PARAMETERS = 8


def _modules() -> dict[str, Path]:
    """Dotted module name -> file, for every module of the package."""
    out = {}
    for path in sorted(PKG.rglob("*.py")):
        parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = _modules()
TREES = {name: ast.parse(path.read_text(), filename=str(path)) for name, path in MODULES.items()}


def _span(node: ast.AST) -> int:
    return node.end_lineno - node.lineno + 1


def _imported(name: str, node: ast.Import | ast.ImportFrom) -> list[str]:
    """Absolute names an import statement of module `name` refers to (the module and, for `from`, its members)."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    base = node.module or ""
    if node.level:
        is_pkg = MODULES[name].name == "__init__.py"
        anchor = name.split(".")[: len(name.split(".")) - node.level + (1 if is_pkg else 0)]
        base = ".".join(anchor + ([base] if base else []))
    return [base] + [f"{base}.{alias.name}" for alias in node.names]


def _annotation_only(node: ast.AST) -> bool:
    """An ``if TYPE_CHECKING:`` block (its imports serve annotations only)."""
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def _runtime_imports(name: str) -> dict[str, int]:
    """pathrl modules that module `name` imports, at module level or inside functions (not under TYPE_CHECKING),
    each with the line of its first import."""
    found: dict[str, int] = {}

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if _annotation_only(child):
                for stmt in child.orelse:
                    visit_stmt(stmt)
                continue
            visit_stmt(child)

    def visit_stmt(node: ast.AST) -> None:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            for n in _imported(name, node):
                if n in MODULES and n != name:
                    found.setdefault(n, node.lineno)
        visit(node)

    visit(TREES[name])
    return found


def _all_imports(name: str) -> set[str]:
    """Every absolute name module `name` imports anywhere (functions included)."""
    return {n for node in ast.walk(TREES[name]) if isinstance(node, (ast.Import, ast.ImportFrom))
            for n in _imported(name, node)}


def test_module_function_and_class_sizes():
    long_modules = [f"{n} ({len(p.read_text().splitlines())})" for n, p in MODULES.items()
                    if len(p.read_text().splitlines()) > MAX_MODULE_LINES]
    long_defs = [f"{n}.{d.name} ({_span(d)})" for n, tree in TREES.items() for d in ast.walk(tree)
                 if isinstance(d, (ast.FunctionDef, ast.AsyncFunctionDef)) and _span(d) > MAX_FUNCTION_LINES]
    long_classes = [f"{n}.{c.name} ({_span(c)})" for n, tree in TREES.items() for c in ast.walk(tree)
                    if isinstance(c, ast.ClassDef) and _span(c) > MAX_CLASS_LINES]
    assert not long_modules, f"modules over {MAX_MODULE_LINES} lines: {long_modules}"
    assert not long_defs, f"functions over {MAX_FUNCTION_LINES} lines: {long_defs}"
    assert not long_classes, f"classes over {MAX_CLASS_LINES} lines: {long_classes}"


def test_only_the_cli_imports_hydra():
    offenders = [n for n in MODULES if not n.startswith("pathrl.cli")
                 and any(i == "hydra" or i.startswith("hydra.") for i in _all_imports(n))]
    assert not offenders, f"Hydra imported outside pathrl.cli: {offenders}"


#: The layers of the package, bottom first. A module imports its own package and the packages of lower layers,
#: never a package of its own layer or of a higher one; a package (or top-level module) not listed fails the test.
LAYERS: list[tuple[str, ...]] = [
    ("pathrl",),  # the package root: its version only
    # leaves, no pathrl import: C kernels, files and checkpoints, MCAP, path geometry, network classes, where conf/ is
    # and how saved run configs are brought up to date, where a shipped model is
    ("pathrl.native", "pathrl.storage", "pathrl.logging", "pathrl.paths", "pathrl.policy", "pathrl.config",
     "pathrl.models"),
    ("pathrl.limits",),  # joint limits: valid acceleration ranges, braking, integration (torch and native)
    ("pathrl.robot",),  # robot specs from conf/robot and PATHRL_ROBOT_PATH, kinematics, collision
    ("pathrl.sim",),  # physics of the feedback tasks behind their Feedback protocol: analytic ball, PyBullet scenes
    ("pathrl.dataset",),  # datasets on disk: path and trajectory banks, waypoint files, imported sets
    ("pathrl.envs",),  # the batched envs and the task registry (make_env)
    ("pathrl.schema", "pathrl.baselines"),  # the apps' config schemas; TOPP-RA, Ruckig, model-based controllers
    ("pathrl.datagen", "pathrl.runs"),  # dataset generation (uses TOPP-RA); a run's config, policy or controller
    ("pathrl.deploy",),  # a policy in a robot's control loop (Follower), exported actors
    ("pathrl.eval",),  # evaluation: rollouts, metrics, realtime timing, path changes
    ("pathrl.train",),  # training: PPO, distillation, warm starts, evaluation curves
    ("pathrl.industrial", "pathrl.repro"),  # the industrial controller; the paper's tables from results
    ("pathrl.viz",),  # viewers (rerun) of runs, evaluations and recordings
    ("pathrl.families",),  # the family registry: each task family's env, evaluation, recording, viewer, tables
    ("pathrl.bench",),  # the benchmarks of `make bench` (a family's realtime timing through the registry)
    ("pathrl.cli",),  # the command-line front doors (Hydra)
]

#: Imports that still go against :data:`LAYERS` or close a cycle, "importer -> imported": reason. Only shrinks.
ALLOWED: dict[str, str] = {}


def _package(module: str) -> str | None:
    """The package (or top-level module) of :data:`LAYERS` that `module` belongs to: the longest listed prefix."""
    return max((p for ps in LAYERS for p in ps if module == p or module.startswith(p + ".")), key=len, default=None)


def _layer(module: str) -> int | None:
    """Index in :data:`LAYERS` of the layer of `module`'s package, None if the package is not listed."""
    return next((i for i, packages in enumerate(LAYERS) if _package(module) in packages), None)


def _against_layers() -> list[str]:
    """Imports of a higher layer or of another package of the same layer, "importer:line -> imported"."""
    out = []
    for name in MODULES:
        for target, line in sorted(_runtime_imports(name).items()):
            src, dst = _package(name), _package(target)
            if src != dst and None not in (_layer(target), _layer(name)) and _layer(target) >= _layer(name):
                out.append(f"{name}:{line} -> {target}")
    return out


def _unallowed(found: list[str]) -> list[str]:
    return [f for f in found if f"{f.split(':')[0]} -> {f.split(' -> ')[1]}" not in ALLOWED]


def test_imports_inside_functions_count_and_annotation_only_ones_do_not(monkeypatch):
    src = ("from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n    from pathrl.eval import evaluate\n\n\n"
           "def f():\n    from pathrl.train import runner\n")
    monkeypatch.setitem(MODULES, "pathrl.limits.fake", MODULES["pathrl.limits"])
    monkeypatch.setitem(TREES, "pathrl.limits.fake", ast.parse(src))
    assert set(_runtime_imports("pathrl.limits.fake")) == {"pathrl.train", "pathrl.train.runner"}
    assert "pathrl.limits.fake:8 -> pathrl.train.runner" in _against_layers()


def test_every_module_is_in_a_layer():
    assert [n for n in MODULES if _layer(n) is None] == []


def test_imports_point_down_the_layers():
    """Module-level and function-level imports point to lower layers only (annotation-only imports exempt)."""
    assert _unallowed(_against_layers()) == []


def test_allow_list_is_current():
    """Every allowed exception still exists (fixed ones leave the list)."""
    found = {f"{f.split(':')[0]} -> {f.split(' -> ')[1]}" for f in _against_layers()} | set(_cycle_edges())
    assert sorted(set(ALLOWED) - found) == []


def test_env_never_imports_mcap_or_rerun():
    offenders = [f"{n} -> {i}" for n in MODULES if n.startswith("pathrl.envs")
                 for i in sorted(_all_imports(n)) if i.split(".")[0] in ("mcap", "rerun")]
    assert not offenders, offenders


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            connect(v)
    return out


def _graph() -> dict[str, set[str]]:
    """Module -> the pathrl modules it imports at run time, without the edges from a package to its own submodules
    (its ``__init__`` re-exports)."""
    return {name: {i for i in _runtime_imports(name) if not i.startswith(name + ".")} for name in MODULES}


def _cycle_edges() -> list[str]:
    """Imports inside a cycle of modules, "importer -> imported"."""
    graph = _graph()
    return [f"{a} -> {b}" for comp in _cycles(graph) for a in comp for b in sorted(graph[a]) if b in comp]


def test_cycles_detects_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycle():
    """No cycle among modules, counting imports inside functions (annotation-only imports exempt)."""
    assert [e for e in _cycle_edges() if e not in ALLOWED] == []


def test_no_package_cycle():
    graph: dict[str, set[str]] = {}
    for name, targets in _graph().items():
        graph.setdefault(_package(name), set()).update(_package(t) for t in targets if _package(t) != _package(name)
                                                       and f"{name} -> {t}" not in ALLOWED)
    graph = {k: {t for t in v if t in graph} for k, v in graph.items()}
    assert _cycles(graph) == []


#: Functions that take more than :data:`MAX_PARAMETERS` parameters, "module.qualname": reason. Only flat-tensor
#: kernels, which take many tensors for speed (no container built or unpacked per call). Only shrinks.
MANY_PARAMETERS: dict[str, str] = {
    "pathrl.envs.observations.observe_state": "observation kernel over the env's state tensors",
    "pathrl.envs.tracking.advance": "one decision step over the env's state tensors",
    "pathrl.native.advance": "C kernel wrapper: one decision step over flat tensors",
    "pathrl.native.valid_range": "C kernel wrapper: the valid acceleration range from flat tensors",
    "pathrl.limits._braking._illinois": "root finder over flat tensors (braking law)",
}


def _parameter_count(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Named parameters (positional and keyword-only, without self / cls), +1 for ``*args``, +1 for ``**kwargs``."""
    a = node.args
    named = [p for p in (*a.posonlyargs, *a.args, *a.kwonlyargs) if p.arg not in ("self", "cls")]
    return len(named) + (a.vararg is not None) + (a.kwarg is not None)


def _qualified_functions(tree: ast.Module) -> list[tuple[str, ast.FunctionDef | ast.AsyncFunctionDef]]:
    """(qualified name, node) of every function and method of a module, nested ones too (``Class.method``,
    ``outer.inner``)."""
    out = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef):
                    out.append((name, child))
                visit(child, name + ".")
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def _many_parameters() -> dict[str, int]:
    """"module.qualname" -> parameter count, of every function over :data:`MAX_PARAMETERS`."""
    return {f"{n}.{q}": _parameter_count(f) for n, tree in TREES.items() for q, f in _qualified_functions(tree)
            if _parameter_count(f) > MAX_PARAMETERS}


def test_parameter_count_counts_named_and_star_parameters_without_self():
    f = ast.parse("class C:\n    def m(self, a, /, b, *args, c, **kw):\n        def g(x): pass\n").body[0]
    counted = [(q, _parameter_count(d)) for q, d in _qualified_functions(ast.Module([f], []))]
    assert counted == [("C.m", 5), ("C.m.g", 1)]


def test_functions_take_few_parameters():
    """No function or method takes more than MAX_PARAMETERS parameters, except the allow-listed kernels."""
    over = {k: v for k, v in _many_parameters().items() if k not in MANY_PARAMETERS}
    assert over == {}, f"functions over {MAX_PARAMETERS} parameters (group them in a frozen dataclass): {over}"


def test_many_parameters_allow_list_is_current():
    """Every allow-listed kernel still exists and still takes more than MAX_PARAMETERS parameters."""
    assert sorted(set(MANY_PARAMETERS) - set(_many_parameters())) == []
