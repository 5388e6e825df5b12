"""Braking at the end of the path: bring every joint to standstill as fast as the limits allow."""

from __future__ import annotations

import torch
from torch import Tensor

from pathrl.limits.feasible import JointLimits, valid_acceleration_range


def is_stopped(v: Tensor, a: Tensor, tol: float = 0.01) -> Tensor:
    """(N,) True where every joint has |v| < tol and |a| < tol."""
    return ((v.abs() < tol) & (a.abs() < tol)).all(dim=-1)


def braking_acceleration(p: Tensor, v: Tensor, a: Tensor, limits: JointLimits, dt: float,
                         tol: float = 0.01) -> Tensor:
    """End-of-step acceleration (N, D) of a deadbeat braking law clipped into the valid range.

    The acceleration that makes the velocity exactly zero once the acceleration has ramped back to
    zero in the following step, v0 + a0 dt / 2 + a1 dt = 0, clipped into [a_min, a_max]: far from
    standstill the clip makes it decelerate at the acceleration/jerk limits; close to it, it lands on
    v = a = 0 without overshoot. Joints already at rest (|v|, |a| < tol) get 0 (if valid).
    """
    lo, hi = valid_acceleration_range(p, v, a, limits, dt)
    return braking_within(v, a, lo, hi, dt, tol)


def braking_within(v: Tensor, a: Tensor, lo: Tensor, hi: Tensor, dt: float, tol: float = 0.01) -> Tensor:
    """The braking law of :func:`braking_acceleration` for an already computed valid range [lo, hi]."""
    target = -(v + a * (dt / 2.0)) / dt
    rest = (v.abs() < tol) & (a.abs() < tol)
    target = torch.where(rest, torch.zeros_like(target), target)
    return torch.minimum(torch.maximum(target, lo), hi)
