"""Reward terms of the path-tracking MDP: pure functions of one step's quantities.

Every term maps a :class:`StepQuantities` (all (N,) tensors) and its own parameters to a (N,)
tensor in [0, 1]; the env weights and sums them (weights in ``conf/reward/*.yaml``). All terms are
non-negative (as in the paper), so ending an episode early never pays off.
"""

from __future__ import annotations

import difflib
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import torch
from torch import Tensor

__all__ = ["ENV_VALUES", "REWARD_TERMS", "TASK_VALUES", "RewardFn", "RewardTerm", "StepQuantities", "action_saturation",
           "ball_centre", "ball_drive", "ball_signed", "base_orientation", "base_position", "base_tilt",
           "build_reward_terms", "deviation_max", "deviation_mean", "path_length", "tcp_deviation"]


@dataclass(frozen=True)
class StepQuantities:
    """What one decision step did, per env (all (N,)).

    moved: joint-space arc length commanded during the step, L_a (rad).
    l_state: path length still covered by the observation the action was chosen from,
        l_State = s(last knot in the window) - s(before the step) (rad); 0 at the path end.
    horizon: K * D, the longest path length a window can cover (rad).
    dev_max, dev_mean: weighted joint-space deviation from the reference over the step (rad).
    action_absmax: max_j |action_j| (raw action, before clipping).
    close_to_end: the window already reaches the path's end knot.
    task: named (N,) values of the env's feedback source (e.g. ``ball_dist``); empty without one.
    """

    moved: Tensor
    l_state: Tensor
    horizon: Tensor
    dev_max: Tensor
    dev_mean: Tensor
    action_absmax: Tensor
    close_to_end: Tensor
    task: Mapping[str, Tensor] = field(default_factory=dict)


def path_length(q: StepQuantities, overshoot_factor: float = 1.0) -> Tensor:
    """Paper's R_l: 1 when the step moves exactly l_State, quadratically less for shorter or longer moves.

    Shorter: 1 - (L_a / l_State - 1)^2 (0 at standstill). Longer: (min(1, (L_a - l_State) /
    (f K D)) - 1)^2 (0 once the overshoot reaches f K D). At the path end l_State = 0, so standing
    still earns 1.
    """
    short = q.moved < q.l_state
    rho_short = q.moved / q.l_state.clamp(min=1e-12)
    r_short = 1.0 - (rho_short - 1.0) ** 2
    rho_long = ((q.moved - q.l_state) / (overshoot_factor * q.horizon)).clamp(max=1.0)
    r_long = (rho_long - 1.0) ** 2
    return torch.where(short, r_short, r_long)


def _closeness(dev: Tensor, threshold: float) -> Tensor:
    return (1.0 - (dev / threshold).clamp(max=1.0)) ** 2


def deviation_max(q: StepQuantities, threshold: float = 0.25) -> Tensor:
    """Paper's R_d (max part): (1 - min(1, max deviation / threshold))^2."""
    return _closeness(q.dev_max, threshold)


def deviation_mean(q: StepQuantities, threshold: float = 0.25) -> Tensor:
    """Paper's R_d (mean part): (1 - min(1, mean deviation / threshold))^2."""
    return _closeness(q.dev_mean, threshold)


def tcp_deviation(q: StepQuantities, threshold: float = 0.1) -> Tensor:
    """Cartesian closeness: (1 - min(1, d / threshold))^2, d = mean distance (m) of the commanded TCPs from the
    reference TCPs at the step's end (value ``tcp_dev``, computed by the env). The authors' code had such a
    Cartesian variant of R_d (0.1 m threshold), unused in their releases; it prices an offset of a joint by its
    lever on the hands, which the joint-space terms do not (a torso offset costs what a wrist offset costs)."""
    return _closeness(q.task["tcp_dev"], threshold)


def action_saturation(q: StepQuantities, threshold: float = 0.9) -> Tensor:
    """Authors' iiwa action reward: rewards using the limits fully (max |action| near 1), 1 near the end.

    0 below `threshold`, rising quadratically to 1 at |action| = 1 (and above).
    """
    m = q.action_absmax.clamp(max=1.0)
    r = (1.0 - ((m - 1.0) / (threshold - 1.0)) ** 2).clamp(min=0.0)
    r = torch.where(m > threshold, r, torch.zeros_like(r))
    return torch.where(q.close_to_end, torch.ones_like(r), r)


def ball_centre(q: StepQuantities, margin: float = 0.06) -> Tensor:
    """Ball-on-plate reward: (1 - min(1, d / (1 - margin)))^2 while the ball is on the plate, else 0.

    d = distance of the ball from the plate centre relative to the usable half-size (task value
    ``ball_dist``). The authors used the signed coordinates (only +x / +y offsets were penalized); the
    distance penalizes an offset in every direction alike.
    """
    d, on = q.task["ball_dist"], q.task["ball_on_plate"]
    return (1.0 - (d / (1.0 - margin)).clamp(max=1.0)) ** 2 * on


def ball_signed(q: StepQuantities, margin: float = 0.06) -> Tensor:
    """The authors' ball-on-plate reward: min(1, (1 - m) / (1 - margin))^2 while the ball is on the plate, else 0.

    m = max(x_rel, y_rel) of the ball in the authors' board axes relative to the usable half-sizes (task value
    ``ball_reach``, :func:`pathrl.sim.feedback.ball_reach`): only offsets toward the board's +x or +y lower it,
    an offset toward -x / -y is free (1 at m <= margin, 0 at the usable edge). As their code computes it.
    """
    m, on = q.task["ball_reach"], q.task["ball_on_plate"]
    return ((1.0 - m) / (1.0 - margin)).clamp(0.0, 1.0) ** 2 * on


def ball_drive(q: StepQuantities, threshold: float = 0.1) -> Tensor:
    """Ball-on-plate shaping: (1 - min(1, F / threshold))^2 while the ball is on the plate, else 0.

    F = mean in-plane specific force on the plate during the step (task value ``ball_drive``, units of g,
    :class:`pathrl.sim.feedback.PlateDrive`): what accelerates the ball relative to the plate (by 5/7 of
    it). Rewards the waiter's way of carrying a tray, tilted into the acceleration; not in the paper.
    """
    return _closeness(q.task["ball_drive"], threshold) * q.task["ball_on_plate"]


def base_tilt(q: StepQuantities, threshold: float = 0.125) -> Tensor:
    """Standing robot: (1 - min(1, tilt / threshold))^2, tilt = angle of the pelvis z axis to world z (rad)."""
    return _closeness(q.task["base_tilt"], threshold)


def base_position(q: StepQuantities, threshold: float = 0.2) -> Tensor:
    """Standing robot: (1 - min(1, |pelvis offset| / threshold))^2 (m)."""
    return _closeness(q.task["base_offset"], threshold)


def base_orientation(q: StepQuantities, threshold: float = 0.5) -> Tensor:
    """Standing robot: (1 - min(1, d / threshold))^2, d = arccos|w| 2/pi in [0, 1] from the initial orientation."""
    return _closeness(q.task["base_orientation"], threshold)


RewardFn = Callable[..., Tensor]

REWARD_TERMS: dict[str, RewardFn] = {
    "path_length": path_length,
    "deviation_max": deviation_max,
    "deviation_mean": deviation_mean,
    "tcp_deviation": tcp_deviation,
    "action_saturation": action_saturation,
    "ball_centre": ball_centre,
    "ball_signed": ball_signed,
    "ball_drive": ball_drive,
    "base_tilt": base_tilt,
    "base_position": base_position,
    "base_orientation": base_orientation,
}

#: Feedback values (StepQuantities.task) a term reads; the env refuses terms its feedback cannot serve.
TASK_VALUES: dict[str, tuple[str, ...]] = {"ball_centre": ("ball_dist", "ball_on_plate"),
                                           "ball_signed": ("ball_reach", "ball_on_plate"),
                                           "ball_drive": ("ball_drive", "ball_on_plate"), "base_tilt": ("base_tilt",),
                                           "base_position": ("base_offset",),
                                           "base_orientation": ("base_orientation",),
                                           "tcp_deviation": ("tcp_dev",)}

#: Task values the env computes itself (no feedback source needed) when a reward term reads them.
ENV_VALUES: tuple[str, ...] = ("tcp_dev",)


@dataclass(frozen=True)
class RewardTerm:
    """A configured reward term: ``weight * fn(q, **params)`` per env (E,)."""

    name: str
    weight: float
    fn: RewardFn
    params: Mapping[str, Any]

    def __call__(self, q: StepQuantities) -> Tensor:
        """The unweighted term (E,) of the step quantities `q`."""
        return self.fn(q, **self.params)


def build_reward_terms(terms_cfg: Mapping[str, Mapping[str, Any]]) -> list[RewardTerm]:
    """Terms from ``{name: {weight: w, <param>: value, ...}}``; unknown names are an error."""
    out = []
    for name, spec in terms_cfg.items():
        if name not in REWARD_TERMS:
            raise ValueError(f"unknown reward term {name!r}; known: {sorted(REWARD_TERMS)}")
        if not isinstance(spec, Mapping) or spec.get("weight") is None:
            raise ValueError(f"reward.terms.{name}.weight is missing; give every reward term its weight")
        params = {k: v for k, v in dict(spec).items() if k != "weight"}
        known = [p for p in inspect.signature(REWARD_TERMS[name]).parameters if p != "q"]
        for k in params:
            if k not in known:
                near = difflib.get_close_matches(k, ["weight", *known], n=1)
                hint = f"; did you mean {near[0]}?" if near else f"; {name} takes weight, {', '.join(known)}"
                raise ValueError(f"reward.terms.{name}.{k}: unknown parameter{hint}")
        out.append(RewardTerm(name, float(spec["weight"]), REWARD_TERMS[name], params))
    return out
