"""Write a file so that a reader (or a process killed mid-write) sees either the old content or the new one."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO


def atomic_write(path: Path, data: bytes | str | Callable[[BinaryIO], None]) -> None:
    """Write `data` (bytes, text, or a function writing into a binary file) to ``<path>.tmp``, flush it to disk
    and rename it over `path`. The temp file sits in the same directory, so the rename is atomic."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        if callable(data):
            data(f)
        else:
            f.write(data.encode() if isinstance(data, str) else data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def write_json_atomic(path: Path, obj: Any) -> None:
    """`obj` as indented JSON (non-JSON values as their str), written atomically."""
    atomic_write(path, json.dumps(obj, indent=2, default=str))
