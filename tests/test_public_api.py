"""Every module of the user-facing packages that declares ``__all__`` exports names bound in it, and lists every
public function and class defined in it (so ``__all__`` stays in step with the code). Read from the sources (no
imports: fast)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGES = ("envs", "eval", "baselines", "policy", "deploy", "limits")
ROOT = Path(__file__).resolve().parents[1] / "pathrl"
#: Modules exempt from the ``__all__`` check (none left).
PENDING: set[str] = set()


def _bound_names(tree: ast.Module) -> set[str]:
    """Names bound at a module's top level (definitions, assignments, imports, also inside try / if blocks)."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and node in tree.body:
            out.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            out |= {(a.asname or a.name).split(".")[0] for a in node.names}
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            out |= {t.id for t in targets if isinstance(t, ast.Name)}
    return out


def test_all_names_exist_and_cover_public_definitions():
    problems, declared = [], 0
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).glob("*.py")):
            rel = f"{pkg}/{path.name}"
            if path.name.startswith("_") or rel in PENDING:
                continue
            tree = ast.parse(path.read_text())
            node = next((n for n in tree.body if isinstance(n, ast.Assign)
                         and any(getattr(t, "id", "") == "__all__" for t in n.targets)), None)
            if node is None:
                problems.append(f"{rel}: no __all__")
                continue
            declared += 1
            names = ast.literal_eval(node.value)
            defined = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))
                       and not n.name.startswith("_")}
            unbound = set(names) - _bound_names(tree)
            unlisted = defined - set(names)
            if unbound or unlisted or len(set(names)) != len(names):
                problems.append(f"{rel}: not bound {sorted(unbound)}, not listed {sorted(unlisted)}")
    assert problems == [] and declared >= 30
