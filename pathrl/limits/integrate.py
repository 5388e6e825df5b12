"""Setpoints within a decision step: acceleration interpolated linearly (constant jerk).

With ``a(t) = a0 + (a1 - a0) * t / dt`` on ``[0, dt]``:
``v(t) = v0 + a0*t + (a1 - a0)*t**2/(2*dt)`` and ``p(t) = p0 + v0*t + a0*t**2/2 + (a1 - a0)*t**3/(6*dt)``.
The default control rate of 240 Hz gives 24 setpoints per 0.1 s decision step.
"""

from __future__ import annotations

import torch
from torch import Tensor

from pathrl.limits.kernels import kernel

__all__ = ["CONTROL_RATE_HZ", "DEFAULT_SUBSTEPS", "end_of_step", "interpolate_step"]


CONTROL_RATE_HZ = 240
DEFAULT_SUBSTEPS = 24  # control setpoints per 0.1 s decision step at 240 Hz


@kernel
def interpolate_step(p0: Tensor, v0: Tensor, a0: Tensor, a1: Tensor, dt: float,
                     n_sub: int = DEFAULT_SUBSTEPS) -> tuple[Tensor, Tensor, Tensor]:
    """Setpoints at ``t = dt*k/n_sub``, k = 1..n_sub.

    Args:
        p0, v0, a0: (..., D) state at the start of the step; a1: (..., D) acceleration at its end.
        dt: step length (s); n_sub: number of setpoints.

    Returns:
        ``(p, v, a)``, each (..., n_sub, D).
    """
    t = torch.arange(1, n_sub + 1, dtype=p0.dtype, device=p0.device) * (dt / n_sub)
    t = t.unsqueeze(-1)  # (n_sub, 1), broadcast against (..., 1, D)
    p0, v0, a0, da = (x.unsqueeze(-2) for x in (p0, v0, a0, a1 - a0))
    jerk = da / dt
    a = a0 + jerk * t
    v = v0 + a0 * t + 0.5 * jerk * t**2
    p = p0 + v0 * t + 0.5 * a0 * t**2 + jerk * t**3 / 6.0
    return p, v, a


@kernel
def end_of_step(p0: Tensor, v0: Tensor, a0: Tensor, a1: Tensor, dt: float) -> tuple[Tensor, Tensor]:
    """Position and velocity at the end of the step; all (..., D)."""
    p1 = p0 + v0 * dt + (a0 / 3.0 + a1 / 6.0) * dt * dt
    v1 = v0 + 0.5 * (a0 + a1) * dt
    return p1, v1
