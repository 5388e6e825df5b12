"""Velocity-limit bounds on the next acceleration (one side, klimits-compatible).

"Upper" bounds: the velocity limit is ``+vmax``; the lower bound of a joint is the negated upper bound
of the mirrored joint ``(-v, -a)``. All tensors share one shape; ``dt`` is the decision step (s).
"""

from __future__ import annotations

import torch
from torch import Tensor

from pathrl.limits.kernels import kernel


@kernel
def velocity_bound(v0: Tensor, a0: Tensor, vmax: Tensor, amax: Tensor, jmax: Tensor, dt: float,
                   settle: float) -> Tensor:
    """Largest end-of-step acceleration that still allows ``v <= vmax`` (no emergency handling).

    Two regimes:
    * The velocity would reach ``vmax`` within this step even with end acceleration 0: the acceleration
      must cross zero inside the step exactly when ``v = vmax`` (TrueAdapt eq. 12).
    * Otherwise: after the step the acceleration is ramped down with the full jerk and must reach zero
      exactly at ``v = vmax`` (eq. 11). Because that zero rarely falls on a decision step, the last knot
      of the ramp is instead pinned to ``-settle * amax`` (slightly negative) and the earlier knots keep
      the full jerk, so the velocity settles just below the limit at a decision step (klimits'
      ``acceleration_after_max_vel_limit_factor``).
    """
    c = v0 + 0.5 * a0 * dt  # velocity at the end of the step if it ends with zero acceleration
    room = vmax - v0
    # klimits returns 0 for |room| < 1e-8; with a0 > 0 that overshoots by a0*dt/2, so there the exact
    # formula is kept (room <= 0 gives -inf, clipped to -amax by the caller).
    tiny = (a0.abs() < 1e-8) | ((room.abs() < 1e-8) & (a0 <= 0.0))
    safe_room = torch.where(a0 > 0.0, room.clamp_min(1e-300), torch.where(tiny, 1.0, room))
    in_step = torch.where(tiny, 0.0, a0 * (1.0 - 0.5 * a0 * dt / safe_room))

    gap = (vmax - c).clamp_min(0.0)
    tau = 0.5 * dt + torch.sqrt(0.25 * dt * dt + 2.0 * gap / jmax)  # time (from step start) of zero acc
    ramp = jmax * (tau - dt)
    q = tau / dt
    n = (torch.ceil(q) - 1.0).clamp_min(1.0)  # full-jerk knots before the pinned one
    a_pin = -settle * amax
    pinned = (torch.ceil(q) > q) & (ramp - jmax * dt * n < a_pin)
    w = vmax - c - jmax * dt * dt * n * (n - 1.0) / 2.0
    if settle > 0.0:
        b = dt * (n - 0.5) * a_pin + w
        s = torch.sqrt((b * b - 4.0 * n * dt * w * a_pin).clamp_min(0.0))
        # larger root of n*dt*y**2 - b*y + w*a_pin = 0, written without cancellation
        root = torch.where(b >= 0.0, (b + s) / (2.0 * n * dt), -2.0 * w * a_pin / (s - b))
    else:
        root = w / (n * dt)
    ramp = torch.where(pinned, root + jmax * dt * (n - 1.0), ramp)
    return torch.where(c >= vmax, in_step, ramp)


@kernel
def velocity_emergency(v0: Tensor, a0: Tensor, vmax: Tensor, amax: Tensor, dt: float) -> Tensor:
    """True where even the hardest ramp to ``-amax`` within one step overshoots ``vmax`` (klimits)."""
    overshoot = 0.5 * a0 * a0 * dt / (a0 + amax)
    return (a0 > 0.0) & (v0 - 1e-8 > vmax - overshoot)


@kernel
def velocity_floor(v: Tensor, a: Tensor, vmax: Tensor, amax: Tensor, jmax: Tensor, dt: float,
                   settle: float) -> Tensor:
    """Lowest next knot that the velocity rule admits at knot state ``(v, a)`` (limit ``v >= -vmax``)."""
    floor = -velocity_bound(-v, -a, vmax, amax, jmax, dt, settle)
    return torch.where(velocity_emergency(-v, -a, vmax, amax, dt), amax, floor)
