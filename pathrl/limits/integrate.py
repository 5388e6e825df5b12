"""Setpoints within a decision step: acceleration linear in time from a0 to a1 (constant jerk).

With T the step and t in (0, T]:
    a(t) = a0 + (a1 - a0) t / T
    v(t) = v0 + a0 t + (a1 - a0) t^2 / (2 T)
    p(t) = p0 + v0 t + a0 t^2 / 2 + (a1 - a0) t^3 / (6 T)
"""

from __future__ import annotations

import torch
from torch import Tensor


def interpolate_step(p0: Tensor, v0: Tensor, a0: Tensor, a1: Tensor, dt: float, n_sub: int
                     ) -> tuple[Tensor, Tensor, Tensor]:
    """States at t = dt k / n_sub, k = 1..n_sub. Inputs (N, D); outputs (N, n_sub, D) each."""
    t = torch.arange(1, n_sub + 1, dtype=p0.dtype, device=p0.device).mul_(dt / n_sub).view(1, n_sub, 1)
    p0, v0, a0 = p0.unsqueeze(1), v0.unsqueeze(1), a0.unsqueeze(1)
    da = (a1.unsqueeze(1) - a0) / dt
    a = a0 + da * t
    v = v0 + a0 * t + da * t * t / 2.0
    p = p0 + v0 * t + a0 * t * t / 2.0 + da * t * t * t / 6.0
    return p, v, a


def end_of_step(p0: Tensor, v0: Tensor, a0: Tensor, a1: Tensor, dt: float) -> tuple[Tensor, Tensor]:
    """Position and velocity at the end of the step. (N, D) -> ((N, D), (N, D))."""
    p1 = p0 + v0 * dt + a0 * (dt * dt / 3.0) + a1 * (dt * dt / 6.0)
    v1 = v0 + (a0 + a1) * (dt / 2.0)
    return p1, v1
