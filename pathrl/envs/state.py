"""Snapshot and restore of what changes while an env steps, so that a resumed training continues the very
episodes (and random streams) the interrupted one was in.

Captured: every tensor attribute of the env, dicts of tensors, the state of every ``torch.Generator``, and the
same recursively for the env's parts defined in :mod:`pathrl.envs` and :mod:`pathrl.sim.feedback` (the analytic
ball and its sensors: :data:`CAPTURED_MODULES`). Static
parts (robot, limits, path set) are rebuilt from the config and not stored. A PyBullet feedback keeps its state
in the simulator processes: its snapshot is not exact (:func:`snapshot_is_exact`).
"""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor

__all__ = ["CAPTURED_MODULES", "restore", "snapshot", "snapshot_is_exact", "unwrapped"]


_GEN = "__generator__"
#: Modules whose objects the snapshot walks into (not the PyBullet feedback of :mod:`pathrl.sim.vec`).
CAPTURED_MODULES = ("pathrl.envs.", "pathrl.sim.feedback")


def _captured_part(x: Any) -> bool:
    return hasattr(x, "__dict__") and type(x).__module__.startswith(CAPTURED_MODULES) and not isinstance(x, type)


def unwrapped(env: Any) -> Any:
    """The tracking env inside wrappers that keep it as ``.env`` (e.g. distillation's teacher labels)."""
    while not hasattr(env, "generator") and hasattr(env, "env"):
        env = env.env
    return env


def snapshot(obj: Any) -> dict[str, Any]:
    """A copy of the changing state of `obj` (an env or one of its parts): tensors, generators, nested parts."""
    out: dict[str, Any] = {}
    for name, v in vars(obj).items():
        if isinstance(v, Tensor):
            out[name] = v.detach().clone()
        elif isinstance(v, torch.Generator):
            out[name] = {_GEN: v.get_state()}
        elif isinstance(v, dict) and v and all(isinstance(t, Tensor) for t in v.values()):
            out[name] = {str(k): t.detach().clone() for k, t in v.items()}
        elif _captured_part(v):
            out[name] = {"__part__": snapshot(v)}
    return out


def restore(obj: Any, state: dict[str, Any], device: torch.device | str | None = None) -> None:
    """Put a :func:`snapshot` back into `obj` (the same kind of object, built from the same config). Every tensor,
    also those in dicts, goes to the device the same entry of `obj` is on (a new entry: to ``obj.device``, else
    `device`), so a checkpoint loaded to the CPU restores a CUDA env; generator states are set as saved."""
    device = getattr(obj, "device", device)
    for name, v in state.items():
        cur = getattr(obj, name, None)
        if isinstance(v, Tensor):
            setattr(obj, name, v.to(_target(cur, device, v)))
        elif _GEN in v:
            if not isinstance(cur, torch.Generator):
                raise ValueError(f"env state: {name} is not a generator in this env")
            cur.set_state(v[_GEN].cpu())  # a generator's state is a CPU byte tensor on every device
        elif "__part__" in v:
            if cur is None:
                raise ValueError(f"env state: this env has no part {name!r}")
            restore(cur, v["__part__"], device)
        else:
            old = cur if isinstance(cur, dict) else {}
            setattr(obj, name, {k: t.to(_target(old.get(k), device, t)) for k, t in v.items()})


def _target(cur: Any, device: torch.device | str | None, saved: Tensor) -> torch.device | str:
    """Where a restored tensor goes: where `cur` (the entry it replaces) is, else `device`, else where it was saved."""
    if isinstance(cur, Tensor):
        return cur.device
    return saved.device if device is None else device


def snapshot_is_exact(env: Any) -> bool:
    """Whether :func:`snapshot` holds all of the env's changing state (false with an out-of-process simulator)."""
    fb = getattr(unwrapped(env), "feedback", None)
    return fb is None or _captured_part(fb)
