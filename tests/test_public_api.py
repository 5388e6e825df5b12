"""Every module of the package declares ``__all__``: it exports names bound in it and lists every public function and
class defined in it (so ``__all__`` stays in step with the code); every function and class it exports has a docstring.
Read from the sources (no imports: fast)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "pathrl"
#: Modules exempt from the ``__all__`` check (none left).
PENDING: set[str] = set()


def _checked_modules() -> dict[str, ast.Module]:
    """Relative path -> parsed source of every module checked: all of ``pathrl/`` (subpackages included) except
    private modules (``_name.py``) and a package ``__init__.py`` that only documents or re-exports (one that defines
    a public function or class, or declares ``__all__``, is checked)."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        tree = ast.parse(path.read_text())
        if rel in PENDING or (path.name.startswith("_") and not (path.name == "__init__.py" and (
                _declared(tree) is not None or _defined(tree)))):
            continue
        out[rel] = tree
    return out


def _declared(tree: ast.Module) -> ast.Assign | None:
    """The module's top-level ``__all__ = [...]`` statement, if any."""
    return next((n for n in tree.body if isinstance(n, ast.Assign)
                 and any(getattr(t, "id", "") == "__all__" for t in n.targets)), None)


def _defined(tree: ast.Module) -> dict[str, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef]:
    """Public functions and classes defined at the module's top level, by name."""
    return {n.name: n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
            and not n.name.startswith("_")}


def _bound_names(tree: ast.Module) -> set[str]:
    """Names bound at a module's top level (definitions, assignments incl. tuple unpacking, imports, also inside
    try / if blocks)."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and node in tree.body:
            out.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            out |= {(a.asname or a.name).split(".")[0] for a in node.names}
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                elts = t.elts if isinstance(t, ast.Tuple) else [t]
                out |= {e.id for e in elts if isinstance(e, ast.Name)}
    return out


MODULES = _checked_modules()


def test_every_package_is_checked():
    packages = {rel.split("/")[0] for rel in MODULES if "/" in rel}
    expected = {p.name for p in ROOT.iterdir() if (p / "__init__.py").is_file()}
    assert packages == expected and "datagen/generators/paths.py" in MODULES and len(MODULES) >= 130


def test_all_names_exist_and_cover_public_definitions():
    problems = []
    for rel, tree in MODULES.items():
        node = _declared(tree)
        if node is None:
            problems.append(f"{rel}: no __all__")
            continue
        names = ast.literal_eval(node.value)
        unbound = set(names) - _bound_names(tree)
        unlisted = set(_defined(tree)) - set(names)
        if unbound or unlisted or len(set(names)) != len(names):
            problems.append(f"{rel}: not bound {sorted(unbound)}, not listed {sorted(unlisted)}")
    assert problems == []


def test_exported_functions_and_classes_have_docstrings():
    """Every function or class a module defines and lists in ``__all__`` says what it is (re-exports are documented
    where they are defined)."""
    missing = []
    for rel, tree in MODULES.items():
        node = _declared(tree)
        names = set(ast.literal_eval(node.value)) if node is not None else set()
        missing += [f"{rel}:{name}" for name, d in _defined(tree).items() if name in names and not ast.get_docstring(d)]
    assert missing == []
