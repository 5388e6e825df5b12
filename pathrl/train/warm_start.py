"""Warm start: begin a run from the weights of another (e.g. the tracking policy before adding ball feedback).

The new task's observation may be longer: its extra inputs are appended at the end of the state, so the
first layer gets zero columns for them (the policy initially ignores them and behaves exactly like the
source) and the observation normalizers start at mean 0 / std 1 there.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import Tensor


class WarmStartError(ValueError):
    """The warm-start source is missing or does not fit the new run."""


def source_checkpoint(path: str | Path) -> Path:
    """The checkpoint of a shipped model dir (model.pt) or a training run (latest model_<it>.pt)."""
    from pathrl.train.runner import latest_checkpoint

    p = Path(path)
    if p.is_file():
        return p
    if (p / "model.pt").is_file():
        return p / "model.pt"
    ckpt = latest_checkpoint(p) if p.is_dir() else None
    if ckpt is None:
        raise WarmStartError(f"init_from={path}: no model.pt or model_<iteration>.pt there")
    return ckpt


def widen_inputs(state: dict[str, Tensor], num_obs: int) -> dict[str, Tensor]:
    """An MLPModel state dict widened to `num_obs` inputs: new inputs at the end, zero weights in mlp.0, the
    obs normalizer at mean 0 / std 1 there."""
    w = state["mlp.0.weight"]
    extra = num_obs - w.shape[1]
    if extra < 0:
        raise WarmStartError(f"source policy has {w.shape[1]} inputs, the new env only {num_obs}")
    out = dict(state)
    out["mlp.0.weight"] = torch.cat([w, w.new_zeros(w.shape[0], extra)], dim=1)
    for key, fill in (("obs_normalizer._mean", 0.0), ("obs_normalizer._var", 1.0), ("obs_normalizer._std", 1.0)):
        if key in state:
            v = state[key]
            out[key] = torch.cat([v, v.new_full((*v.shape[:-1], extra), fill)], dim=-1)
    return out


def warm_start(alg, source: str | Path, num_obs: int, init_std: float | None = None) -> Path:
    """Load actor and critic of `source` into the PPO `alg` (inputs widened to `num_obs`); the action std is
    reset to `init_std` (a converged source has almost no exploration left). Returns the checkpoint used."""
    ckpt = source_checkpoint(source)
    try:
        loaded = torch.load(ckpt, weights_only=True, map_location="cpu")
        actor, critic = dict(loaded["actor_state_dict"]), dict(loaded["critic_state_dict"])
    except (RuntimeError, KeyError, EOFError, OSError) as exc:
        raise WarmStartError(f"{ckpt}: unreadable checkpoint ({str(exc).splitlines()[0]})") from None
    actor, critic = widen_inputs(actor, num_obs), widen_inputs(critic, num_obs)
    if init_std is not None and "distribution.std_param" in actor:
        actor["distribution.std_param"] = torch.full_like(actor["distribution.std_param"], init_std)
    try:
        alg.load({"actor_state_dict": actor, "critic_state_dict": critic}, {"actor": True, "critic": True}, True)
    except RuntimeError as exc:
        raise WarmStartError(f"init_from={source}: network does not fit ({str(exc).splitlines()[0]})") from None
    return ckpt
