"""The package's shape, checked: sizes, layering and import cycles (issue 23's bars, kept from regressing).

Read from the source with `ast`, nothing is imported: a module over 500 lines, a function over 80, a class over
350, Hydra imported outside `pathrl/cli`, `pathrl.eval` importing `pathrl.train`, or a cycle among module-level
imports fails here with the offending names.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "pathrl"
MAX_MODULE_LINES, MAX_FUNCTION_LINES, MAX_CLASS_LINES = 500, 80, 350


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


def _module_level_imports(name: str) -> set[str]:
    """pathrl modules that module `name` imports at import time (not inside functions or TYPE_CHECKING)."""
    found: set[str] = set()

    def visit(body: list[ast.stmt]) -> None:
        for stmt in body:
            if isinstance(stmt, (ast.Import, ast.ImportFrom)):
                found.update(n for n in _imported(name, stmt) if n in MODULES)
            elif isinstance(stmt, ast.If) and "TYPE_CHECKING" not in ast.unparse(stmt.test):
                visit(stmt.body)
                visit(stmt.orelse)
            elif isinstance(stmt, ast.Try):
                visit(stmt.body)

    visit(TREES[name].body)
    found.discard(name)
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


@pytest.mark.parametrize("lower, upper", [("pathrl.eval", "pathrl.train"), ("pathrl.envs", "pathrl.train"),
                                          ("pathrl.envs", "pathrl.eval"), ("pathrl.envs", "pathrl.viz")])
def test_layering(lower: str, upper: str):
    """`lower` never imports `upper` (evaluation stands without training; the env without logging and viewing)."""
    offenders = [f"{n} -> {i}" for n in MODULES if n == lower or n.startswith(lower + ".")
                 for i in sorted(_all_imports(n)) if i == upper or i.startswith(upper + ".")]
    assert not offenders, offenders


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


def _package_edges(name: str) -> set[str]:
    """Module-level imports, without the edge from a package to its own submodules (its `__init__` re-exports)."""
    return {i for i in _module_level_imports(name) if not i.startswith(name + ".")}


def test_cycles_detects_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycle():
    graph = {name: _package_edges(name) for name in MODULES}
    assert _cycles(graph) == []
