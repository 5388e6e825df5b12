"""Opening recordings: the bundled ``rerun`` CLI, the native viewer, the web viewer."""

from __future__ import annotations

import shutil
import subprocess
import sys
from collections.abc import Iterable
from pathlib import Path

__all__ = ["rerun_command", "serve_web", "spawn_viewer"]


def rerun_command() -> list[str]:
    """The bundled ``rerun`` CLI (next to the interpreter, else ``python -m rerun``)."""
    exe = Path(sys.executable).with_name("rerun")
    if exe.is_file():
        return [str(exe)]
    found = shutil.which("rerun")
    return [found] if found else [sys.executable, "-m", "rerun"]


def spawn_viewer(files: Iterable[Path]) -> subprocess.Popen:
    """Open the native viewer on `files` (detached)."""
    return subprocess.Popen([*rerun_command(), *map(str, files)], start_new_session=True)


def serve_web(files: Iterable[Path], port: int = 9090) -> int:
    """Serve `files` in Rerun's web viewer (blocks until interrupted); returns the viewer's exit code."""
    try:
        return subprocess.call(
            [*rerun_command(), "--serve-web", "--web-viewer-port", str(port), *map(str, files)]
        )
    except KeyboardInterrupt:  # the normal way to stop serving
        return 0
