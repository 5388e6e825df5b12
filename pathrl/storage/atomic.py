"""Write a file so that a reader (or a process killed mid-write) sees either the old content or the new one."""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["atomic_write", "write_json_atomic"]


def atomic_write(path: Path, data: bytes | str | Callable[[Path], object]) -> None:
    """Write `data` (bytes, text, or a function that writes the file at the path it is given) to a temp file
    beside `path`, flush it to disk and rename it over `path`.

    The temp file ``.<name>.<random>.tmp<suffix>`` sits in the same directory (so the rename is atomic), keeps
    the suffix (writers such as ``savefig`` or ``np.savez`` go by it), is unique (concurrent writers do not
    clash) and gets the mode of any new file. On an error it is removed and the error propagates.
    """
    path = Path(path)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=f".tmp{path.suffix}")
    tmp = Path(name)
    try:
        with os.fdopen(fd, "wb") as f:
            if not callable(data):
                f.write(data.encode() if isinstance(data, str) else data)
        if callable(data):
            data(tmp)
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes the file private
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_json_atomic(path: Path, obj: Any, allow_nan: bool = True) -> None:
    """`obj` as indented JSON (values JSON lacks as their str), newline-terminated, written atomically."""
    atomic_write(path, json.dumps(obj, indent=2, default=str, allow_nan=allow_nan) + "\n")
