"""Check where a command will write before it computes anything: an output that cannot be written should fail in
one line at the start, not with a traceback after minutes of work (or leave a temp file behind).

Nothing is created by these checks: a missing directory is fine if its nearest existing ancestor is a writable
directory (the writer creates the rest). Writability is probed with an anonymous temp file, so it also holds for
root on a read-only mount or a pseudo file system, where permission bits say nothing.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path

__all__ = ["DestinationError", "check_dir_destination", "check_file_destination", "inside_models",
           "models_dirs"]


class DestinationError(ValueError):
    """An output destination that cannot be written (one line, naming the argument)."""


def _arg(what: str, path: object) -> str:
    """How the argument reads in a message: ``out=DIR`` for a key, ``--save FILE`` for a flag."""
    return f"{what} {path}" if what.startswith("-") else f"{what}={path}"


def _existing_ancestor(path: Path) -> Path:
    """The nearest ancestor of `path` (or `path` itself) that exists (resolved against the working directory)."""
    p = Path(os.path.abspath(path))
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _check_writable_dir(what: str, path: Path, base: Path) -> None:
    """DestinationError unless `base` (the nearest existing ancestor of `path`) is a directory files can be made in."""
    if not base.is_dir():
        raise DestinationError(f"{_arg(what, path)}: {base} is a file, not a directory")
    try:
        with tempfile.TemporaryFile(dir=base):
            pass
    except OSError as exc:
        raise DestinationError(f"{_arg(what, path)}: cannot write in {base} ({exc.strerror or exc})") from None


def check_file_destination(path: str | os.PathLike, what: str) -> Path:
    """`path` as a Path if a file can be written there: not an existing directory, its directory (or the nearest
    existing ancestor) writable. `what` names the argument in the message (``out``, ``--save``)."""
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise DestinationError(f"{_arg(what, repr(str(path)))}: not a file name")
    if p.is_dir():
        raise DestinationError(f"{_arg(what, p)} is a directory; give a file name")
    _check_writable_dir(what, p, _existing_ancestor(p.parent))
    return p


def check_dir_destination(path: str | os.PathLike, what: str, files: Sequence[str] = ()) -> Path:
    """`path` as a Path if a directory of outputs can be made or written there: not an existing file, the nearest
    existing ancestor a writable directory, and none of the `files` to be written in it an existing directory."""
    p = Path(path)
    if str(path) == "":
        raise DestinationError(f"{_arg(what, repr(''))}: not a directory name")
    if p.exists() and not p.is_dir():
        raise DestinationError(f"{_arg(what, p)} is a file, not a directory")
    _check_writable_dir(what, p, _existing_ancestor(p))
    for name in files:
        if (p / name).is_dir():
            raise DestinationError(f"{_arg(what, p)}: {p / name} is a directory, not a file")
    return p


def models_dirs() -> list[Path]:
    """The directories of shipped policies: ``models/`` of the working directory and of the checkout pathrl runs
    from (when it is one)."""
    checkout = Path(__file__).resolve().parents[2] / "models"
    return list(dict.fromkeys(p.resolve() for p in (Path.cwd() / "models", checkout)))


def inside_models(path: str | os.PathLike, roots: Sequence[Path] | None = None) -> bool:
    """Whether `path` is one of the `roots` (default :func:`models_dirs`) or inside one: where shipped policies
    live, which commands write into only when asked to."""
    p = Path(path).resolve()
    return any(p == r or r in p.parents for r in (models_dirs() if roots is None else roots))
