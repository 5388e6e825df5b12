"""Braking: bring every joint to standstill as fast as the limits allow (end of path, episode end).

Per joint, in the direction of motion, the law picks the lowest end-of-step acceleration from which a
full-jerk ramp back to zero acceleration still ends exactly at zero velocity on a decision step (the
velocity rule of :mod:`pathrl.limits._velocity` with a velocity limit of 0), bounded by the jerk and
acceleration limits. Once the velocity reaches zero within the current step anyway, a deadbeat step
takes over: ``a1 = -(v + a*dt/2)/dt``, then 0, bring ``v = a = 0`` by the end of the next step. The
result is always clipped into the valid range, so braking never violates a limit. (The original work
ran a second klimits object with velocity limits [0, 0] for the same purpose.)
"""

from __future__ import annotations

import torch
from torch import Tensor

from pathrl.limits._velocity import velocity_floor
from pathrl.limits.feasible import JointLimits, valid_acceleration_range

__all__ = ["STOP_TOL", "braking_acceleration", "braking_steps_bound", "braking_within", "is_stopped"]


STOP_TOL = 0.01  # |v| (per s) and |a| (per s^2) below which a joint counts as stopped

def is_stopped(v: Tensor, a: Tensor, tol: float = STOP_TOL) -> Tensor:
    """(N,) True where every joint has ``|v| < tol`` and ``|a| < tol``; inputs (N, D)."""
    return ((v.abs() < tol) & (a.abs() < tol)).all(dim=-1)

def braking_acceleration(p: Tensor, v: Tensor, a: Tensor, limits: JointLimits, dt: float,
                         tol: float = STOP_TOL) -> Tensor:
    """End-of-step acceleration (N, D) of the braking law, inside the valid range; inputs (N, D)."""
    lo, hi = valid_acceleration_range(p, v, a, limits, dt)
    return braking_within(v, a, lo, hi, dt, tol, limits)

def braking_within(v: Tensor, a: Tensor, lo: Tensor, hi: Tensor, dt: float, tol: float = STOP_TOL,
                   limits: JointLimits | None = None) -> Tensor:
    """The braking law for an already computed valid range ``[lo, hi]``; all (N, D).

    Without ``limits`` only the deadbeat step is used (the jerk and acceleration limits then act only
    through the clip into ``[lo, hi]``, which can overshoot zero velocity when ``jerk*dt < 2*acc``).
    Joints at rest (``|v|, |a| < tol``) get 0, clipped into the range.
    """
    deadbeat = -(v + 0.5 * a * dt) / dt
    target = deadbeat
    if limits is not None:
        up = (v > 0.0) | ((v == 0.0) & (a > 0.0))
        sign = torch.where(up, 1.0, -1.0)
        vs, as_ = sign * v, sign * a  # moving upwards in these coordinates
        ramp = velocity_floor(vs, as_, torch.zeros_like(limits.vel), limits.acc, limits.jerk, dt, 0.0)
        ramp = torch.maximum(torch.maximum(ramp, as_ - limits.jerk * dt), -limits.acc)
        crosses = vs + 0.5 * as_ * dt <= 0.0  # zero velocity is reached within this step anyway
        target = torch.where(crosses, deadbeat, sign * ramp)
    rest = (v.abs() < tol) & (a.abs() < tol)
    target = torch.where(rest, 0.0, target)
    return torch.minimum(torch.maximum(target, lo), hi)

def braking_steps_bound(v: Tensor, a: Tensor, limits: JointLimits, dt: float) -> Tensor:
    """(N,) upper bound on the decision steps the law needs to stop every joint (for tests).

    Continuous time-optimal stop (ramp the acceleration to ``-acc``, hold, ramp back to 0, in the
    direction of motion) plus one step per phase switch and two for the deadbeat finish.
    """
    up = (v > 0.0) | ((v == 0.0) & (a > 0.0))
    sign = torch.where(up, 1.0, -1.0)
    vs, as_ = sign * v, sign * a
    amax, jmax = limits.acc, limits.jerk
    rise = as_.clamp_min(0.0) ** 2 / (2.0 * jmax)  # velocity still gained while a positive a decays
    t_stop = (as_ + amax).clamp_min(0.0) / jmax + (vs + rise).clamp_min(0.0) / amax + amax / jmax
    steps = torch.ceil(t_stop / dt) + 5.0
    return steps.amax(dim=-1).to(torch.int64).clamp_min(2)
