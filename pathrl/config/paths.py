"""Where the shipped configs live: ``pathrl/conf`` inside the installed package (``conf/`` in a checkout is a
symlink to it), so the CLIs find their YAML from a wheel install as well as from the source tree."""

from __future__ import annotations

from pathlib import Path

__all__ = ["CONF_DIR"]

#: The Hydra config directory (``train.yaml``, ``robot/``, ``dataset/``, ...), package data of ``pathrl``.
CONF_DIR = Path(__file__).resolve().parent.parent / "conf"
