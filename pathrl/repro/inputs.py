"""What a reproduction result was made from, so that ``--reuse`` keeps a result only while its inputs are unchanged.

A result (``results/raw/<id>/metrics.json``, or a ``.json`` file under ``results/raw``) gets a sidecar
(``inputs.json`` beside a ``metrics.json``, ``<name>.inputs.json`` beside any other file) holding the SHA-256 of
every file it was made from: the model directory's ``config.yaml`` and ``*.pt`` weights, those of the model its
config names under ``controller.policy`` (followed recursively), and the split's ``dataset.json`` and ``test.npz``.
Paths are recorded relative to the repository root (committed sidecars name no machine's checkout).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path

import yaml

from pathrl.storage.atomic import write_json_atomic

__all__ = ["DATASET_FILES", "fingerprint", "inputs_file", "record", "stale"]

#: Files of a dataset split directory that are fingerprinted (when present).
DATASET_FILES = ("dataset.json", "test.npz")


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _shown(path: Path, root: Path) -> str:
    """`path` relative to `root` when inside it (POSIX form), else as given."""
    path = path if path.is_absolute() else root / path
    return path.relative_to(root).as_posix() if path.is_relative_to(root) else path.as_posix()


def _controller_policy(config: Path) -> str | None:
    """The ``controller.policy`` a model's ``config.yaml`` names (empty or absent: None)."""
    cfg = yaml.safe_load(config.read_text()) or {}
    ctrl = cfg.get("controller") if isinstance(cfg, dict) else None
    policy = ctrl.get("policy") if isinstance(ctrl, dict) else None
    return str(policy) if policy else None


def _model_files(model: Path, root: Path, seen: set[Path]) -> list[Path]:
    """``config.yaml`` and ``*.pt`` of `model`, then those of the model its ``controller.policy`` names."""
    model = (model if model.is_absolute() else root / model).resolve()
    if model in seen:
        return []
    seen.add(model)
    files = sorted(model.glob("*.pt"))
    config = model / "config.yaml"
    if not config.is_file():
        return files
    files.append(config)
    policy = _controller_policy(config)
    return files + (_model_files(Path(policy), root, seen) if policy else [])


def fingerprint(root: Path, model: Path | None = None, dataset: Path | None = None) -> dict[str, str]:
    """{file relative to `root`: SHA-256} of what an evaluation of `model` (a model directory; None: no model) on
    the split directory `dataset` (None: not fingerprinted) reads. Relative paths (also ``controller.policy``
    values) are taken relative to `root`, the directory the evaluations run in."""
    root = root.resolve()
    files = [] if model is None else _model_files(model, root, set())
    if dataset is not None:
        data = dataset if dataset.is_absolute() else root / dataset
        files += [data / name for name in DATASET_FILES if (data / name).is_file()]
    return {_shown(p.resolve(), root): _sha256(p) for p in files}


def inputs_file(result: Path) -> Path:
    """The sidecar of `result`: ``inputs.json`` beside a ``metrics.json``, else ``<stem>.inputs.json``."""
    return result.with_name("inputs.json") if result.name == "metrics.json" else result.with_suffix(".inputs.json")


def stale(result: Path, current: Mapping[str, str]) -> str | None:
    """Why `result` must be (re)made under ``--reuse`` ("no result", "inputs changed (<files>)"), or None to keep it.

    A result without a sidecar is kept: results made before fingerprints were recorded (the committed ones) stay
    reusable, so ``--reuse`` on a fresh clone does not re-run everything; its next evaluation writes the sidecar.
    """
    if not result.is_file():
        return "no result"
    side = inputs_file(result)
    if not side.is_file():
        return None
    try:
        stored = json.loads(side.read_text())["files"]
    except (OSError, ValueError, KeyError, TypeError):
        return f"inputs changed ({side.name} unreadable)"
    if stored == dict(current):
        return None
    changed = sorted(k for k in stored.keys() | current.keys() if stored.get(k) != current.get(k))
    return f"inputs changed ({', '.join(changed)})"


def record(result: Path, current: Mapping[str, str]) -> None:
    """Write the sidecar of `result` (atomically) with the fingerprint `current` it was made from."""
    side = inputs_file(result)
    side.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(side, {"files": dict(sorted(current.items()))})
