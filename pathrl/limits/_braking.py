"""Position bound from braking: the greedy braking peak and its root in the end acceleration ``x``.

All functions look at a joint from one side: the position limit ``pmax`` lies above, the velocity
limit is ``+-vmax``. The lower bound of a joint is the negated upper bound of the mirrored joint.
Within a step the acceleration is linear in time, so a trajectory is given by its accelerations at
the decision steps ("knots"); the step about to be taken ends with acceleration ``x``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

import torch
from torch import Tensor

from pathrl.limits._velocity import velocity_floor


@dataclass
class Side:
    """Flat (M,) float64 joint states and limits, seen from one side (limit above)."""

    p: Tensor  # position
    v: Tensor  # velocity
    a: Tensor  # acceleration at the current knot
    pmax: Tensor  # position limit (upper in these coordinates)
    amax: Tensor  # acceleration limit magnitude
    jmax: Tensor  # jerk limit magnitude
    vmax: Tensor  # velocity limit magnitude

    def take(self, idx: Tensor) -> Side:
        """The elements at ``idx``."""
        return Side(*(getattr(self, f.name)[idx] for f in fields(self)))


@dataclass
class Peak:
    """Highest position reached after the step by the greedy braking trajectory, and where."""

    value: Tensor  # peak position
    slope: Tensor  # d(value)/dx > 0
    time: Tensor  # time of the peak from the START of the step (s); dt if at the step end
    phase: Tensor  # 0 at the step end, 1 on the full-jerk ramp, 2 in the reduced-jerk step, 3 in the hold
    ramp: Tensor  # m: full-jerk knots after the step before the reduced-jerk knot onto -amax


def last_down_crossing(v: Tensor, a: Tensor, k: Tensor) -> Tensor:
    """Time ``w`` where ``v + a*w - k*w**2/2`` crosses zero downwards (nan if the roots are complex).

    That root has derivative ``-sqrt(a**2 + 2*k*v) <= 0``. It is evaluated without cancellation;
    ``k`` may have any sign, for ``k == 0`` the linear root results (``inf`` if ``a >= 0``).
    """
    disc = a * a + 2.0 * k * v
    s = torch.sqrt(disc.clamp_min(0.0))
    w = torch.where(a >= 0.0, (a + s) / k, 2.0 * v / (s - a))
    return torch.where(disc >= 0.0, w, float("nan"))


def in_step_bound(s: Side, dt: float) -> Tensor:
    """Largest ``x`` keeping the position at or below ``pmax`` strictly inside the step.

    Inside the step ``p(t)`` is a cubic whose local maximum touches ``pmax`` (with ``v = 0``) at a time
    ``tau`` solving ``a0*tau**2 + 4*v0*tau - 6*(pmax - p0) = 0``; then
    ``x = a0 - 2*dt*(v0 + a0*tau)/tau**2``. Both roots are tried, the smallest valid ``x`` wins;
    ``+inf`` where no interior maximum can reach the limit.
    """
    room = (s.pmax - s.p).clamp_min(0.0)
    disc = 4.0 * s.v * s.v + 6.0 * s.a * room
    root = torch.sqrt(disc.clamp_min(0.0))
    best = torch.full_like(s.p, float("inf"))
    for tau in (6.0 * room / (root + 2.0 * s.v), 6.0 * room / (2.0 * s.v - root)):
        x = s.a - 2.0 * dt * (s.v + s.a * tau) / tau**2
        turning = s.a + (x - s.a) * tau / dt < 0.0  # a local maximum, not a minimum
        valid = (disc >= 0.0) & (tau > 0.0) & (tau < dt) & turning & (x < best)
        best = torch.where(valid, x, best)
    return best


def greedy_peak(x: Tensor, s: Side, dt: float) -> Peak:
    """Highest position from the end of the step on, if the step ends with ``x`` and braking is greedy.

    Greedy braking: after the step the knots are ``max(x - jmax*dt*i, -amax)``, i = 1, 2, ...: full jerk
    down (phase R, m knots), one reduced-jerk step onto ``-amax`` (P), then ``-amax`` held (H). It is
    the pointwise lowest acceleration, hence velocity and position, of any continuation, so its peak is
    the lowest reachable one. The peak is convex and increasing in ``x``, slope at least ``dt**2/6``.
    """
    amax, jmax = s.amax, s.jmax
    p1 = s.p + s.v * dt + (s.a / 3.0 + x / 6.0) * dt * dt
    v1 = s.v + 0.5 * (s.a + x) * dt
    dp1, dv1 = dt * dt / 6.0, 0.5 * dt

    m = torch.floor((x + amax) / (jmax * dt)).clamp_min(0.0)
    tr = m * dt
    ur = last_down_crossing(v1, x, jmax)
    in_r = (ur >= 0.0) & (ur <= tr)
    ur = torch.where(in_r, ur, 0.0)
    f_r = p1 + v1 * ur + 0.5 * x * ur**2 - jmax * ur**3 / 6.0
    g_r = dp1 + dv1 * ur + 0.5 * ur**2
    a_r = x - jmax * tr
    v_r = v1 + x * tr - 0.5 * jmax * tr**2
    p_r = p1 + v1 * tr + 0.5 * x * tr**2 - jmax * tr**3 / 6.0
    dv_r = dv1 + tr
    dp_r = dp1 + dv1 * tr + 0.5 * tr**2

    k = (a_r + amax) / dt
    wp = last_down_crossing(v_r, a_r, k)
    in_p = (wp >= 0.0) & (wp <= dt) & ~in_r
    wp = torch.where(in_p, wp, 0.0)
    f_p = p_r + v_r * wp + 0.5 * a_r * wp**2 - k * wp**3 / 6.0
    g_p = dp_r + dv_r * wp + 0.5 * wp**2 - wp**3 / (6.0 * dt)

    v_h = v_r + 0.5 * (a_r - amax) * dt
    p_h = p_r + v_r * dt + (a_r / 3.0 - amax / 6.0) * dt * dt
    in_h = (v_h > 0.0) & ~in_r & ~in_p
    vh = v_h.clamp_min(0.0)
    f_h = p_h + vh**2 / (2.0 * amax)
    g_h = dp_r + dv_r * dt + dt * dt / 3.0 + vh * (dv_r + 0.5 * dt) / amax

    value = torch.where(in_r, f_r, torch.where(in_p, f_p, torch.where(in_h, f_h, p1)))
    slope = torch.where(in_r, g_r, torch.where(in_p, g_p, torch.where(in_h, g_h, dp1)))
    time = dt + torch.where(in_r, ur, torch.where(in_p, tr + wp, torch.where(in_h, tr + dt + vh / amax, 0.0)))
    phase = torch.where(in_r, 1, torch.where(in_p, 2, torch.where(in_h, 3, 0)))
    low = value < p1  # velocity negative right after the step: the step end is the highest point
    return Peak(torch.where(low, p1, value), torch.where(low, dp1, slope), torch.where(low, dt, time),
                torch.where(low, 0, phase), m)


def greedy_state(x: Tensor, s: Side, dt: float, t: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Position, velocity and acceleration of the greedy braking trajectory at knot time ``t >= dt``."""
    amax, jmax = s.amax, s.jmax
    p1 = s.p + s.v * dt + (s.a / 3.0 + x / 6.0) * dt * dt
    v1 = s.v + 0.5 * (s.a + x) * dt
    m = torch.floor((x + amax) / (jmax * dt)).clamp_min(0.0)
    u = (t - dt).clamp_min(0.0)
    ur = torch.minimum(u, m * dt)
    a_r = x - jmax * ur
    v_r = v1 + x * ur - 0.5 * jmax * ur**2
    p_r = p1 + v1 * ur + 0.5 * x * ur**2 - jmax * ur**3 / 6.0
    v_h = v_r + 0.5 * (a_r - amax) * dt
    p_h = p_r + v_r * dt + (a_r / 3.0 - amax / 6.0) * dt * dt
    w = (u - (m + 1.0) * dt).clamp_min(0.0)
    hold = u >= (m + 1.0) * dt - 1e-12
    return (torch.where(hold, p_h + v_h * w - 0.5 * amax * w**2, p_r),
            torch.where(hold, v_h - amax * w, v_r), torch.where(hold, -amax, a_r))


def velocity_aware_peak(x: Tensor, s: Side, dt: float, peak: Peak, settle: float) -> Tensor:
    """Peak when the knot that ends the step containing the greedy peak obeys the velocity floor.

    Greedy braking holds ``-amax`` through the step in which the velocity reaches zero. If the
    velocity rule (``v >= -vmax``, klimits' refinement included) then demands a higher knot, the
    greedy plan cannot be executed and a bound based on it steers into a dead end. The knot is raised
    to that floor and the peak recomputed (it can only grow).
    """
    start = dt + torch.floor((peak.time - dt) / dt - 1e-12).clamp_min(0.0) * dt
    ps, vs, a_s = greedy_state(x, s, dt, start)
    greedy_end = torch.maximum(a_s - s.jmax * dt, -s.amax)
    end = torch.maximum(greedy_end, velocity_floor(vs, a_s, s.vmax, s.amax, s.jmax, dt, settle))
    w = last_down_crossing(vs, a_s, -(end - a_s) / dt)
    inside = (w >= 0.0) & (w <= dt)
    w = torch.where(inside, w, dt)  # no crossing in the step: the step end bounds it from below
    value = ps + vs * w + 0.5 * a_s * w**2 + (end - a_s) * w**3 / (6.0 * dt)
    raised = (end > greedy_end) & (peak.phase > 0)
    return torch.where(raised, torch.maximum(value, peak.value), peak.value)


PeakFn = Callable[[Tensor, Side, float], tuple[Tensor, Tensor]]


def descend(fn: PeakFn, x: Tensor, s: Side, dt: float, tol: float = 1e-13, max_iter: int = 60) -> Tensor:
    """Newton's method for ``fn(x).value == pmax``, starting right of the root; (M,) -> (M,).

    For a convex increasing peak the iterates decrease monotonically onto the root. Iterations stop
    at ``|peak - pmax| <= tol`` (m); converged elements drop out.
    """
    out = x.clone()
    idx = torch.arange(x.numel(), device=x.device)
    cur, sub = x.clone(), s
    for _ in range(max_iter):
        value, slope = fn(cur, sub, dt)
        r = value - sub.pmax
        todo = r.abs() > tol
        cur = cur - torch.where(todo, r / slope, 0.0)
        out[idx] = cur
        if not bool(todo.any()):
            break
        keep = todo.nonzero().squeeze(-1)
        idx, cur, sub = idx[keep], cur[keep], sub.take(keep)
    return out


def greedy_bound(s: Side, dt: float, probe: Tensor, settle: float) -> tuple[Tensor, Tensor, Peak]:
    """Position bounds after the step: klimits' greedy root and the velocity-aware (safe) one.

    Elements whose greedy peak at ``probe`` stays below ``pmax`` get ``+inf`` (the bound is higher than
    anything the caller cares about). Returns ``(greedy, safe, peak at greedy)``.
    """
    peak = greedy_peak(probe, s, dt)
    greedy = torch.full_like(probe, float("inf"))
    safe = greedy.clone()
    idx = (peak.value > s.pmax).nonzero().squeeze(-1)
    if idx.numel() == 0:
        return greedy, safe, peak
    sub = s.take(idx)
    root = descend(_greedy_fn, probe[idx], sub, dt)
    at_root = greedy_peak(root, sub, dt)
    fixed = root.clone()
    lifted = velocity_aware_peak(root, sub, dt, at_root, settle) > sub.pmax + 1e-13
    jdx = lifted.nonzero().squeeze(-1)
    if jdx.numel():
        fixed[jdx] = descend(_aware_fn(settle), root[jdx], sub.take(jdx), dt)
    greedy[idx], safe[idx] = root, fixed
    for f in fields(peak):
        getattr(peak, f.name)[idx] = getattr(at_root, f.name).to(getattr(peak, f.name).dtype)
    return greedy, safe, peak


def _greedy_fn(x: Tensor, s: Side, dt: float) -> tuple[Tensor, Tensor]:
    peak = greedy_peak(x, s, dt)
    return peak.value, peak.slope


def _aware_fn(settle: float) -> PeakFn:
    def fn(x: Tensor, s: Side, dt: float) -> tuple[Tensor, Tensor]:
        peak = greedy_peak(x, s, dt)
        return velocity_aware_peak(x, s, dt, peak, settle), peak.slope

    return fn


def reach_top(p0: Tensor, v0: Tensor, a0: Tensor, amax: Tensor, jmax: Tensor, dt: float,
              x_probe: Tensor) -> Tensor:
    """Upper bound on the greedy braking peak for every end acceleration ``x <= x_probe`` (cheap).

    Uses a profile lying above the greedy one: ``max(a0, x)`` during the step, ``x`` during the next,
    then the continuous full-jerk ramp from ``x`` onto ``-amax`` and ``-amax`` held.
    """
    s1 = torch.maximum(a0, x_probe)
    v1 = v0 + s1 * dt
    p1 = p0 + v0 * dt + 0.5 * s1 * dt * dt
    v2 = v1 + x_probe * dt
    p2 = p1 + v1 * dt + 0.5 * x_probe * dt * dt
    tr = (x_probe + amax).clamp_min(0.0) / jmax
    u = last_down_crossing(v2, x_probe, jmax)
    in_ramp = (u >= 0.0) & (u <= tr)
    u = torch.where(in_ramp, u, tr)
    v_r = v2 + x_probe * u - 0.5 * jmax * u * u
    reach = p2 + v2 * u + 0.5 * x_probe * u * u - jmax * u**3 / 6.0
    reach = reach + torch.where(in_ramp, 0.0, v_r.clamp_min(0.0) ** 2 / (2.0 * amax))
    step_top = p0 + v0.clamp_min(0.0) * dt + 0.5 * s1.clamp_min(0.0) * dt * dt
    return torch.maximum(torch.maximum(reach, torch.maximum(p1, p2)), step_top)
