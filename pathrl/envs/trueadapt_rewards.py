"""TrueAdapt reward: R = R_T (1 - P_S)(1 - P_D), P_S = (P_A + P_J) / 2 (TrueAdapt eqs. 1-7).

Every term is a pure function of one step's :class:`AdaptQuantities` (all (N,) or (N, D) float64 tensors) and
its own parameters (``conf/reward/trueadapt_*.yaml``), with values in [0, 1]. The weights of the penalties
scale them (weight 0 removes a penalty: the ablations "no jerk penalty" / "no acceleration penalty"); with all
weights 1 the product is the paper's eq. 1:

    R = w_T R_T (1 - (w_A P_A + w_J P_J) / 2) (1 - w_D P_D)
"""

from __future__ import annotations

import difflib
import inspect
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

__all__ = ["PENALTIES", "TASK_TERMS", "AdaptQuantities", "AdaptReward", "TermFn", "acceleration_penalty",
           "build_adapt_reward", "deviation_penalty", "in_place", "jerk_penalty", "on_plate"]


@dataclass(frozen=True)
class AdaptQuantities:
    """One decision step of N envs.

    acc_norm: (N, D) |a_{t+1}| / a_max per joint (the new acceleration knot).
    jerk: (N, D) |a_{t+1} - a_t| / dt (rad/s^3); jerk_max: (D,) jerk limits.
    deviation: (N,) max_i |p_{t+1,i} - p_{t+1,ref,i}| (rad).
    ball_rel: (N,) Chebyshev position of the ball in the usable area: max(|x| / h_x, |y| / h_y) (1 = border).
    ball_offset: (N,) distance of the ball from its initial position (m).
    ball_ok: (N,) 1 while the task has not failed, else 0.
    """

    acc_norm: Tensor
    jerk: Tensor
    jerk_max: Tensor
    deviation: Tensor
    ball_rel: Tensor
    ball_offset: Tensor
    ball_ok: Tensor


def on_plate(q: AdaptQuantities, inner: float = 0.6) -> Tensor:
    """R_T, on plate: 1 while the ball is within `inner` of the usable half-size, falling quadratically to 0 at
    the border: 1 - ((rel - inner) / (1 - inner))^2; 0 once the task failed."""
    over = ((q.ball_rel - inner) / (1.0 - inner)).clamp(0.0, 1.0)
    return (1.0 - over**2) * q.ball_ok


def in_place(q: AdaptQuantities, radius: float = 0.06) -> Tensor:
    """R_T, in place: (1 - min(1, d / radius))^2, d = distance from the initial ball position (m); 0 once failed."""
    return (1.0 - (q.ball_offset / radius).clamp(max=1.0)) ** 2 * q.ball_ok


def acceleration_penalty(q: AdaptQuantities, threshold: float = 0.2) -> Tensor:
    """P_A (eq. 3): 0 up to `threshold` (a_th) of the largest normalised |a_{t+1}|, then ((a - a_th) / (1 - a_th))^2."""
    a = q.acc_norm.amax(dim=1).clamp(max=1.0)
    return ((a - threshold).clamp(min=0.0) / (1.0 - threshold)) ** 2


def jerk_penalty(q: AdaptQuantities, c: float = 100.0) -> Tensor:
    """P_J (eqs. 4-6): j_p = sum_i jerk_i^2, j_sat = sum_i jerk_max_i^2 / c; (j_p / j_sat)^2, 1 above j_sat."""
    j_p = (q.jerk**2).sum(dim=1)
    j_sat = float((q.jerk_max**2).sum()) / c
    return (j_p / j_sat).clamp(max=1.0) ** 2


def deviation_penalty(q: AdaptQuantities, low: float = math.radians(2.0), high: float = math.radians(6.0)) -> Tensor:
    """P_D (eq. 7): 0 up to `low` (dp_l, rad), ((dp - low) / (high - low))^2 up to `high` (dp_h), then 1."""
    return ((q.deviation - low) / (high - low)).clamp(0.0, 1.0) ** 2


TermFn = Callable[..., Tensor]
TASK_TERMS: dict[str, TermFn] = {"on_plate": on_plate, "in_place": in_place}
PENALTIES: dict[str, TermFn] = {"acceleration_penalty": acceleration_penalty, "jerk_penalty": jerk_penalty,
                                "deviation_penalty": deviation_penalty}


@dataclass(frozen=True)
class AdaptReward:
    """The configured terms: exactly one task term; penalties may be missing (weight 0)."""

    task: str
    weights: Mapping[str, float]
    params: Mapping[str, Mapping[str, Any]]

    def terms(self, q: AdaptQuantities) -> dict[str, Tensor]:
        """Every configured term's value (N,), unweighted."""
        return {name: {**TASK_TERMS, **PENALTIES}[name](q, **self.params[name]) for name in self.params}

    def combine(self, values: Mapping[str, Tensor]) -> Tensor:
        """R = w_T R_T (1 - (w_A P_A + w_J P_J) / 2) (1 - w_D P_D), (N,)."""
        w, zero = self.weights, torch.zeros_like(values[self.task])
        smooth = (w.get("acceleration_penalty", 0.0) * values.get("acceleration_penalty", zero)
                  + w.get("jerk_penalty", 0.0) * values.get("jerk_penalty", zero)) / 2.0
        dev = w.get("deviation_penalty", 0.0) * values.get("deviation_penalty", zero)
        return w[self.task] * values[self.task] * (1.0 - smooth) * (1.0 - dev)


def build_adapt_reward(terms_cfg: Mapping[str, Mapping[str, Any]]) -> AdaptReward:
    """From ``reward.terms`` ({name: {weight, <param>: value}}); one-line ValueError for anything unusable."""
    known = {**TASK_TERMS, **PENALTIES}
    tasks = [n for n in terms_cfg if n in TASK_TERMS]
    if len(tasks) != 1:
        raise ValueError(f"reward.terms: a TrueAdapt reward needs exactly one task term of {sorted(TASK_TERMS)}, "
                         f"got {tasks}")
    weights, params = {}, {}
    for name, spec in terms_cfg.items():
        if name not in known:
            raise ValueError(f"unknown TrueAdapt reward term {name!r}; known: {sorted(known)}")
        if not isinstance(spec, Mapping) or spec.get("weight") is None:
            raise ValueError(f"reward.terms.{name}.weight is missing; give every reward term its weight")
        w = float(spec["weight"])
        if not 0.0 <= w <= 1.0:
            raise ValueError(f"reward.terms.{name}.weight must be in [0, 1] (the reward is a product), got {w}")
        allowed = [p for p in inspect.signature(known[name]).parameters if p != "q"]
        for k in spec:
            if k != "weight" and k not in allowed:
                near = difflib.get_close_matches(k, ["weight", *allowed], n=1)
                raise ValueError(f"reward.terms.{name}.{k}: unknown parameter"
                                 + (f"; did you mean {near[0]}?" if near else f"; {name} takes {allowed}"))
        weights[name] = w
        params[name] = {k: float(v) for k, v in spec.items() if k != "weight"}
        full = {k: p.default for k, p in inspect.signature(known[name]).parameters.items() if k != "q"}
        if not _VALID[name]({**full, **params[name]}):
            raise ValueError(f"reward.terms.{name}: {_RULES[name]}, got {params[name]}")
    return AdaptReward(tasks[0], weights, params)


_VALID: dict[str, Callable[[dict[str, float]], bool]] = {
    "on_plate": lambda p: 0.0 <= p["inner"] < 1.0, "in_place": lambda p: p["radius"] > 0.0,
    "acceleration_penalty": lambda p: 0.0 <= p["threshold"] < 1.0, "jerk_penalty": lambda p: p["c"] > 0.0,
    "deviation_penalty": lambda p: 0.0 <= p["low"] < p["high"]}
_RULES = {"on_plate": "inner must be in [0, 1)", "in_place": "radius must be > 0",
          "acceleration_penalty": "threshold must be in [0, 1)", "jerk_penalty": "c must be > 0",
          "deviation_penalty": "need 0 <= low < high"}
