"""Move a policy's weights onto a robot with more joints or a wider observation (pure state-dict functions).

The state starts with three per-joint blocks (position, velocity, acceleration; D columns each); what follows
depends on the path joints only and keeps its order; task inputs come last. A source network keeps the weights of
each of its inputs at the input's new column and of each of its actions at the action's new row; new inputs get
zero weights (and a normaliser at mean 0 / std 1), new actions zero weights and bias: action 0, the middle of the
joint's valid range. The widened network therefore computes the source's actions on the source's joints.
Used by warm starts (:mod:`pathrl.train.warm_start`) and by controllers that drive part of a robot with a policy
trained on that part alone (:mod:`pathrl.baselines.balance`).
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import torch
from torch import Tensor

__all__ = ["LayoutError", "actor_for_joints", "input_columns", "joint_rows", "widen_inputs", "widen_outputs"]


class LayoutError(ValueError):
    """A source network does not fit the new robot or observation."""


def joint_rows(src_joints: Sequence[str], joints: Sequence[str]) -> Tensor:
    """(D_src,) index of every source joint among the new robot's `joints`."""
    missing = [j for j in src_joints if j not in joints]
    if missing:
        raise LayoutError(f"the source policy controls joints the new robot lacks: {missing}")
    return torch.tensor([list(joints).index(j) for j in src_joints])


def input_columns(rows: Tensor, d: int, src_obs: int, num_obs: int) -> Tensor:
    """(src_obs,) column in the new state of every source input, the source joints at `rows` of `d` joints.

    The state starts with three per-joint blocks (position, velocity, acceleration; D columns each); what
    follows depends on the path joints only and keeps its order; new task inputs come last.
    """
    d_src = len(rows)
    rest = src_obs - 3 * d_src
    if rest < 0 or 3 * d + rest > num_obs:
        raise LayoutError(f"source policy has {src_obs} inputs for {d_src} joints; the new env has "
                             f"{num_obs} for {d}: the states do not line up")
    return torch.cat([*(b * d + rows for b in range(3)), 3 * d + torch.arange(rest)])


def widen_inputs(state: dict[str, Tensor], num_obs: int, columns: Tensor | None = None) -> dict[str, Tensor]:
    """An MLPModel state dict with `num_obs` inputs: source input i moves to `columns[i]` (default: i, new inputs
    appended); new inputs get zero weights in mlp.0 and the obs normalizer at mean 0 / std 1."""
    w = state["mlp.0.weight"]
    if columns is None:
        if num_obs < w.shape[1]:
            raise LayoutError(f"source policy has {w.shape[1]} inputs, the new env only {num_obs}")
        columns = torch.arange(w.shape[1])
    out = dict(state)
    out["mlp.0.weight"] = w.new_zeros(w.shape[0], num_obs)
    out["mlp.0.weight"][:, columns] = w
    for key, fill in (("obs_normalizer._mean", 0.0), ("obs_normalizer._var", 1.0), ("obs_normalizer._std", 1.0)):
        if key in state:
            v = state[key]
            out[key] = v.new_full((*v.shape[:-1], num_obs), fill)
            out[key][..., columns] = v
    return out


def widen_outputs(state: dict[str, Tensor], rows: Tensor, num_out: int, std: float | None) -> dict[str, Tensor]:
    """An MLPModel actor state dict with `num_out` actions: source action i moves to `rows[i]`; new actions get
    zero weights and bias in the last layer (mean action 0) and the action std `std` (or the mean source std)."""
    last = max(int(m.group(1)) for k in state if (m := re.fullmatch(r"mlp\.(\d+)\.weight", k)))
    out = dict(state)
    for key in (f"mlp.{last}.weight", f"mlp.{last}.bias"):
        v = state[key]
        out[key] = v.new_zeros(num_out, *v.shape[1:])
        out[key][rows] = v
    if "distribution.std_param" in state:
        v = state["distribution.std_param"]
        out["distribution.std_param"] = v.new_full((num_out,), float(std) if std is not None else float(v.mean()))
        out["distribution.std_param"][rows] = v
    return out


def actor_for_joints(actor: dict[str, Tensor], src_joints: Sequence[str], joints: Sequence[str], num_obs: int,
                     std: float | None = None) -> dict[str, Tensor]:
    """An MLPModel actor state dict of a policy trained on `src_joints`, moved onto a robot with `joints` (a
    superset, same path joints) and `num_obs` inputs; the new joints' actions are 0 with action std `std`."""
    rows = joint_rows(src_joints, joints)
    cols = input_columns(rows, len(joints), actor["mlp.0.weight"].shape[1], num_obs)
    return widen_outputs(widen_inputs(actor, num_obs, cols), rows, len(joints), std)
