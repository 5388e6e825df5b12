"""Checkpoints: saved atomically with a digest of their content, verified on load; a run resumes from its
newest checkpoint that verifies.

A checkpoint is a ``torch.save`` of a dict of tensors and plain values (``weights_only`` loadable). Its key
``sha256`` holds :func:`content_digest` of everything else, so a flipped byte in a weight is an error on load
instead of a policy that silently evaluates to other numbers. Checkpoints written before the digest existed
(no ``sha256`` key) load unverified.
"""

from __future__ import annotations

import hashlib
import re
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from pathrl.storage.atomic import atomic_write

__all__ = [
    "CHECKPOINT_RE", "CheckpointError", "LEFTOVER_GLOBS", "checkpoint_iteration", "clean_leftovers", "content_digest",
    "latest_checkpoint", "latest_valid_checkpoint", "load_checkpoint", "run_checkpoints", "save_checkpoint",
]

CHECKPOINT_RE = re.compile(r"^model_(\d+)\.pt$")
DIGEST_KEY = "sha256"
#: Leftovers of writes a kill interrupted: checkpoints, logs, configs, summaries (``pathrl.storage.atomic``).
LEFTOVER_GLOBS = ("*.tmp", ".*.tmp", ".*.tmp.*")


class CheckpointError(ValueError):
    """A checkpoint file is missing, unreadable, not a checkpoint, or its content does not match its digest."""


def content_digest(state: Any) -> str:
    """SHA-256 (hex) over the names, types, shapes and bytes of a nested dict/list of tensors and plain values,
    independent of dict order and of the device the tensors are on."""
    h = hashlib.sha256()
    _feed(h, state)
    return h.hexdigest()


def _feed(h, x: Any) -> None:
    if isinstance(x, torch.Tensor):
        t = x.detach().cpu().contiguous()
        h.update(f"T{t.dtype}{tuple(t.shape)}".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())
    elif isinstance(x, Mapping):
        h.update(f"D{len(x)}".encode())
        for k in sorted(x, key=str):
            h.update(f"K{k!r}".encode())
            _feed(h, x[k])
    elif isinstance(x, (list, tuple)):
        h.update(f"L{len(x)}".encode())
        for v in x:
            _feed(h, v)
    else:
        h.update(f"V{type(x).__name__}{x!r}".encode())


def save_checkpoint(state: dict[str, Any], path: Path) -> str:
    """Write `state` plus its digest to `path` atomically (temp file, fsync, rename); returns the digest."""
    body = {k: v for k, v in state.items() if k != DIGEST_KEY}
    digest = content_digest(body)
    atomic_write(Path(path), lambda tmp: torch.save({**body, DIGEST_KEY: digest}, tmp))
    return digest


def load_checkpoint(path: Path, map_location: str | None = "cpu") -> dict[str, Any]:
    """The checkpoint at `path` (weights only), its digest verified; any problem is one :class:`CheckpointError`."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: checkpoint not found")
    try:
        state = torch.load(path, weights_only=True, map_location=map_location)
    except Exception as exc:  # torch raises RuntimeError, UnpicklingError, EOFError, ... for a damaged file
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise CheckpointError(f"{path}: unreadable checkpoint ({first[:200]})") from None
    if not isinstance(state, dict):
        raise CheckpointError(f"{path}: not a pathrl checkpoint (a {type(state).__name__}, expected a dict)")
    digest = state.pop(DIGEST_KEY, None)
    if digest is not None and digest != content_digest(state):
        raise CheckpointError(f"{path}: content does not match its sha256 digest (damaged or modified file)")
    return state


def checkpoint_iteration(path: Path) -> int:
    """K of ``model_K.pt``: the iteration whose update the checkpoint holds."""
    m = CHECKPOINT_RE.match(Path(path).name)
    if m is None:
        raise CheckpointError(f"{path}: not a model_<iteration>.pt file name")
    return int(m.group(1))


def run_checkpoints(run_dir: Path) -> list[Path]:
    """The ``model_<K>.pt`` files of a run directory, oldest iteration first."""
    found = [(int(m.group(1)), p) for p in Path(run_dir).glob("model_*.pt") if (m := CHECKPOINT_RE.match(p.name))]
    return [p for _, p in sorted(found)]


def latest_checkpoint(run_dir: Path) -> Path | None:
    """The checkpoint with the highest iteration in `run_dir` (not verified), if any."""
    found = run_checkpoints(run_dir)
    return found[-1] if found else None


def latest_valid_checkpoint(run_dir: Path, warn: bool = True) -> Path | None:
    """The newest checkpoint of `run_dir` that loads and verifies; damaged newer ones are skipped (and named on
    stderr), so a run killed while a file was being damaged resumes one save interval back."""
    for path in reversed(run_checkpoints(run_dir)):
        try:
            load_checkpoint(path)
        except CheckpointError as exc:
            if warn:
                print(f"warning: skipping {exc}", file=sys.stderr)
            continue
        return path
    return None


def clean_leftovers(run_dir: Path) -> list[Path]:
    """Remove the temp files of writes a kill interrupted in `run_dir`; returns what was removed."""
    found = {p for pattern in LEFTOVER_GLOBS for p in Path(run_dir).glob(pattern) if p.is_file()}
    for p in found:
        p.unlink()
    return sorted(found)
