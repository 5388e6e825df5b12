"""Why an episode ended: one :class:`TerminationReason` per env and step.

:class:`~pathrl.envs.tracking.PathTrackingEnv` (step 6 of its step order) and
:class:`~pathrl.envs.trueadapt.TrueAdaptEnv` evaluate the termination terms below once per step and store the
result as ``env.termination``, an (N,) ``int8`` tensor of reason codes (``NONE`` while the episode goes on).
Evaluation (:mod:`pathrl.eval.rollout`, :mod:`pathrl.eval.trueadapt`) and the envs' episode logs read that
tensor; nothing re-derives a reason from the individual flags.

When several terms hold in the same step the first reason in the env's endings wins. Path tracking
(:data:`ENDINGS`): ``STOPPED, DEVIATION, TASK_FAILED, TIME_OUT`` -- a stop is a success even if the step also
deviated, and a time-out counts only when nothing terminated. TrueAdapt (:data:`ADAPT_ENDINGS`): ``DEVIATION,
TASK_FAILED, TRAJECTORY_END`` -- reaching the trajectory's end counts only when nothing else ended the episode.
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import IntEnum

import torch
from torch import Tensor

from pathrl.limits.braking import is_stopped

__all__ = [
    "ADAPT_ENDINGS",
    "ENDINGS",
    "TERMINATION_REASONS",
    "TerminationReason",
    "deviation_exceeded",
    "end_reached",
    "first_reason",
    "robot_stopped",
    "task_failed",
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
    TRAJECTORY_END = 5  # TrueAdapt: the reference's last sample was reached (a termination, not a time-out)

    @property
    def label(self) -> str:
        """The reason's name in metrics.json (``termination``) and in ``Episode_Termination/<label>`` logs."""
        return _LABELS[self]


_LABELS = {TerminationReason.NONE: "none", TerminationReason.STOPPED: "robot_stopped",
           TerminationReason.DEVIATION: "deviation", TerminationReason.TASK_FAILED: "task_failed",
           TerminationReason.TIME_OUT: "time_out", TerminationReason.TRAJECTORY_END: "trajectory_end"}

#: The reasons an episode of the path-tracking env can end with, in priority order (and in this order in the
#: episode log).
ENDINGS = (TerminationReason.STOPPED, TerminationReason.DEVIATION, TerminationReason.TASK_FAILED,
           TerminationReason.TIME_OUT)
#: Their labels.
TERMINATION_REASONS = tuple(r.label for r in ENDINGS)
#: The reasons a TrueAdapt episode can end with, in priority order (and in this order in the episode log).
ADAPT_ENDINGS = (TerminationReason.DEVIATION, TerminationReason.TASK_FAILED, TerminationReason.TRAJECTORY_END)


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


def task_failed(failed: Tensor, fail_terminates: bool) -> Tensor:
    """(N,) bool: the feedback task failed in this step (failed (N,) bool) and a failure ends the episode."""
    return failed.clone() if fail_terminates else torch.zeros_like(failed)


def timed_out(episode_length: Tensor, budget: Tensor) -> Tensor:
    """(N,) bool: the episode used its step budget (both (N,) long); TrueAdapt: the reference's last sample
    (budget: the trajectory's steps) was reached."""
    return episode_length >= budget


def first_reason(terms: Sequence[tuple[TerminationReason, Tensor]]) -> Tensor:
    """(N,) int8 codes from (reason, (N,) bool mask) pairs in priority order: the first reason whose mask holds
    wins; NONE (0) where none holds."""
    reason = torch.zeros_like(terms[0][1], dtype=torch.int8)
    for code, mask in reversed(terms):
        reason.masked_fill_(mask, int(code))
    return reason


def termination_reason(stopped: Tensor, deviation: Tensor, task_failed: Tensor, time_out: Tensor) -> Tensor:
    """(N,) int8 :class:`TerminationReason` codes of the path-tracking env from the (N,) bool term masks; the
    first term in the order stopped, deviation, task_failed, time_out that holds wins; NONE (0) where none holds."""
    return first_reason(list(zip(ENDINGS, (stopped, deviation, task_failed, time_out), strict=True)))
