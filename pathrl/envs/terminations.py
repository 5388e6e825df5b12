"""Why an episode of the path-tracking env ended: one :class:`TerminationReason` per env and step.

:class:`~pathrl.envs.tracking.PathTrackingEnv` evaluates the termination terms below once per step (step 6 of
its step order) and stores the result as ``env.termination``, an (N,) ``int8`` tensor of reason codes
(``NONE`` while the episode goes on). Evaluation rollouts (:mod:`pathrl.eval.rollout`) and the env's episode
log read that tensor; nothing re-derives a reason from the individual flags.

When several terms hold in the same step the first of ``STOPPED, DEVIATION, TASK_FAILED, TIME_OUT`` wins:
a stop is a success even if the step also deviated, and a time-out counts only when nothing terminated.
"""

from __future__ import annotations

from enum import IntEnum

import torch
from torch import Tensor

from pathrl.limits.braking import is_stopped

__all__ = [
    "ENDINGS",
    "TERMINATION_REASONS",
    "TerminationReason",
    "deviation_exceeded",
    "end_reached",
    "robot_stopped",
    "termination_reason",
    "timed_out",
]


class TerminationReason(IntEnum):
    """Reason codes of ``env.termination``; :attr:`label` is the name written to metrics.json and logs."""

    NONE = 0  # the episode goes on
    STOPPED = 1  # the end of the path was reached and the robot came to rest (the only success)
    DEVIATION = 2  # a step's max deviation exceeded ``env.max_deviation``
    TASK_FAILED = 3  # the feedback task failed (ball off the plate, robot fallen) with ``fail_terminates``
    TIME_OUT = 4  # the step budget ran out (truncation, not a termination of the MDP)

    @property
    def label(self) -> str:
        """The reason's name in metrics.json (``termination``) and in ``Episode_Termination/<label>`` logs."""
        return _LABELS[self]


_LABELS = {TerminationReason.NONE: "none", TerminationReason.STOPPED: "robot_stopped",
           TerminationReason.DEVIATION: "deviation", TerminationReason.TASK_FAILED: "task_failed",
           TerminationReason.TIME_OUT: "time_out"}

#: The reasons an episode can end with, in priority order (and in this order in the episode log).
ENDINGS = tuple(r for r in TerminationReason if r is not TerminationReason.NONE)
#: Their labels.
TERMINATION_REASONS = tuple(r.label for r in ENDINGS)


def end_reached(s: Tensor, end_s: Tensor, to_end: Tensor | None, knot_gap: float,
                end_tolerance: float | None) -> Tensor:
    """(N,) bool: the covered arc length s (N,) reached the segment end end_s (N,) (to 1e-9), or, with an
    ``end_tolerance`` (weighted rad), the robot is within it of the end knot (distance ``to_end`` (N,)) with less
    than one knot gap (rad of arc length) left."""
    reached = s >= end_s - 1e-9
    if end_tolerance is not None:
        reached = reached | ((to_end <= end_tolerance) & (end_s - s < knot_gap))
    return reached


def robot_stopped(braking: Tensor, vel: Tensor, acc: Tensor, tol: float) -> Tensor:
    """(N,) bool: envs in braking mode (N,) whose joints (vel, acc (N, D)) are all below `tol` in |v| and |a|."""
    return braking & is_stopped(vel, acc, tol)


def deviation_exceeded(dev_max: Tensor, max_deviation: float | None) -> Tensor:
    """(N,) bool: the step's max deviation dev_max (N,) (weighted rad) exceeded `max_deviation` (None: never)."""
    if max_deviation is None:
        return torch.zeros_like(dev_max, dtype=torch.bool)
    return dev_max > max_deviation


def timed_out(episode_length: Tensor, budget: Tensor) -> Tensor:
    """(N,) bool: the episode used its step budget (both (N,) long)."""
    return episode_length >= budget


def termination_reason(stopped: Tensor, deviation: Tensor, task_failed: Tensor, time_out: Tensor) -> Tensor:
    """(N,) int8 :class:`TerminationReason` codes from the (N,) bool term masks; the first term in the order
    stopped, deviation, task_failed, time_out that holds wins; NONE (0) where none holds."""
    reason = time_out.to(torch.int8) * int(TerminationReason.TIME_OUT)
    reason.masked_fill_(task_failed, int(TerminationReason.TASK_FAILED))
    reason.masked_fill_(deviation, int(TerminationReason.DEVIATION))
    return reason.masked_fill_(stopped, int(TerminationReason.STOPPED))
