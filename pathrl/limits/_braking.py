"""Position bound from braking: the greedy braking peak and its root in the end acceleration ``x``.

All functions look at a joint from one side: the position limit ``pmax`` lies above, the velocity
limit is ``+-vmax``. The lower bound of a joint is the negated upper bound of the mirrored joint.
Within a step the acceleration is linear in time, so a trajectory is given by its accelerations at
the decision steps ("knots"); the step about to be taken ends with acceleration ``x``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, fields

import torch
from torch import Tensor

from pathrl.limits._velocity import velocity_floor
from pathrl.limits.kernels import kernel


def pick(t: Tensor, idx: Tensor) -> Tensor:
    """``t[idx]`` for a flat tensor and long indices: ``index_select``, whose dispatch costs a third of
    advanced indexing (3 vs 9 us here); the subsets of the limit code are small, so this adds up."""
    return t.index_select(0, idx)


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
        """The elements at ``idx`` (long indices)."""
        return Side(*(pick(getattr(self, f.name), idx) for f in fields(self)))


@dataclass
class Peak:
    """Highest position reached after the step by the greedy braking trajectory, and where."""

    value: Tensor  # peak position
    slope: Tensor  # d(value)/dx > 0
    time: Tensor  # time of the peak from the START of the step (s); dt if at the step end
    phase: Tensor  # 0 at the step end, 1 on the full-jerk ramp, 2 in the reduced-jerk step, 3 in the hold
    ramp: Tensor  # m: full-jerk knots after the step before the reduced-jerk knot onto -amax


@kernel
def last_down_crossing(v: Tensor, a: Tensor, k: Tensor) -> Tensor:
    """Time ``w`` where ``v + a*w - k*w**2/2`` crosses zero downwards (nan if the roots are complex).

    That root has derivative ``-sqrt(a**2 + 2*k*v) <= 0``. It is evaluated without cancellation;
    ``k`` may have any sign, for ``k == 0`` the linear root results (``inf`` if ``a >= 0``).
    """
    disc = a * a + 2.0 * k * v
    s = torch.sqrt(disc.clamp_min(0.0))
    w = torch.where(a >= 0.0, (a + s) / k, 2.0 * v / (s - a))
    return torch.where(disc >= 0.0, w, float("nan"))


@kernel
def in_step_bound(s: Side, dt: float) -> Tensor:
    """Largest ``x`` keeping the position at or below ``pmax`` strictly inside the step.

    Inside the step ``p(t)`` is a cubic whose local maximum touches ``pmax`` (with ``v = 0``) at a time
    ``tau`` solving ``a0*tau**2 + 4*v0*tau - 6*(pmax - p0) = 0``; then
    ``x = a0 - 2*dt*(v0 + a0*tau)/tau**2``. Both roots are tried (computed without cancellation, also
    for ``p0 == pmax``), the smallest valid ``x`` wins; ``+inf`` where no interior maximum can reach
    the limit.
    """
    room = (s.pmax - s.p).clamp_min(0.0)
    disc = 4.0 * s.v * s.v + 6.0 * s.a * room
    q = -(2.0 * s.v + torch.where(s.v >= 0.0, 1.0, -1.0) * torch.sqrt(disc.clamp_min(0.0)))
    best = torch.full_like(s.p, float("inf"))
    for tau in (q / s.a, -6.0 * room / q):
        x = s.a - 2.0 * dt * (s.v + s.a * tau) / tau**2
        turning = s.a + (x - s.a) * tau / dt < 0.0  # a local maximum, not a minimum
        valid = (disc >= 0.0) & (tau > 0.0) & (tau < dt) & turning & (x < best)
        best = torch.where(valid, x, best)
    # At the limit and moving out of it: no acceleration helps (the tangency time shrinks to 0).
    return torch.where((room == 0.0) & (s.v > 1e-9), -float("inf"), best)


@kernel
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


@kernel
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


@kernel
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
    at ``|peak - pmax| <= tol`` (m). Converged elements are re-evaluated at the same point and stay put,
    so the subset is iterated as a whole (one fused kernel call per UNROLL iterations) until fewer than
    half of its elements are left, which are then taken out and iterated alone. ``max_iter`` is rounded
    down to a multiple of UNROLL.
    """
    out = x.clone()
    idx = torch.arange(x.numel(), device=x.device)
    cur, sub = x.clone(), s
    for _ in range(max_iter // UNROLL):
        cur, todo = _newton_steps(fn, cur, sub, dt, tol)
        left = int(todo.sum())
        if left == 0:
            break
        if 2 * left < todo.numel():  # few left: iterate only those from now on
            out.index_copy_(0, idx, cur)
            keep = todo.nonzero().squeeze(-1)
            idx, cur, sub = pick(idx, keep), pick(cur, keep), sub.take(keep)
    return out.index_copy_(0, idx, cur)


#: Iterations of the root loops per compiled call (:func:`descend`, :func:`bracket_below`). An element whose
#: iteration has ended is carried through the rest of a block unchanged, so results do not depend on it;
#: fewer calls save their dispatch (the loops often run on a few dozen elements).
UNROLL = 4


@kernel
def _newton_steps(fn: PeakFn, x: Tensor, s: Side, dt: float, tol: float) -> tuple[Tensor, Tensor]:
    """UNROLL Newton steps; returns the iterate and whether the last step still moved it."""
    todo = torch.ones_like(x, dtype=torch.bool)
    for _ in range(UNROLL):
        value, slope = fn(x, s, dt)
        r = value - s.pmax
        todo = r.abs() > tol
        x = x - torch.where(todo, r / slope, 0.0)
    return x, todo


@kernel
def hold_root(s: Side, dt: float, ramp: Tensor) -> tuple[Tensor, Tensor]:
    """Root ``x`` if the greedy peak lay in the hold phase with ``ramp`` full-jerk knots; and ``v_h``.

    With the ramp structure fixed, position and velocity where ``-amax`` starts to be held are affine
    in ``x``, so ``p_h + v_h**2/(2*amax) = pmax`` is a quadratic (larger root). Consistent (the actual
    root) where ``v_h > 0`` and ``x`` has that ramp structure. Returns ``(x, v_h(x))``.
    """
    tr = ramp * dt

    def hold_state(x: float) -> tuple[Tensor, Tensor]:
        v1 = s.v + 0.5 * (s.a + x) * dt
        p1 = s.p + s.v * dt + (s.a / 3.0 + x / 6.0) * dt * dt
        a_r = x - s.jmax * tr
        v_r = v1 + x * tr - 0.5 * s.jmax * tr**2
        p_r = p1 + v1 * tr + 0.5 * x * tr**2 - s.jmax * tr**3 / 6.0
        return p_r + v_r * dt + (a_r / 3.0 - s.amax / 6.0) * dt * dt, v_r + 0.5 * (a_r - s.amax) * dt

    (pz, vz), (po, vo) = hold_state(0.0), hold_state(1.0)
    dp, dv = po - pz, vo - vz
    qa, qb, qc = dv**2 / (2.0 * s.amax), dp + vz * dv / s.amax, pz + vz**2 / (2.0 * s.amax) - s.pmax
    x = (-qb + torch.sqrt((qb * qb - 4.0 * qa * qc).clamp_min(0.0))) / (2.0 * qa)
    return x, vz + dv * x


def bracket_below(fn: PeakFn, hi: Tensor, s: Side, dt: float, xtol: float = 1e-7,
                  max_iter: int = 16) -> Tensor:
    """Largest ``x <= hi`` found with ``fn(x).value <= pmax`` for a peak that may jump; (M,) -> (M,).

    ``fn(hi)`` must exceed ``pmax``. Steps down (doubling) until the peak is below the limit, then
    shrinks the bracket by regula falsi (Illinois variant) with a bisection fallback; returns the safe
    end once the bracket is narrower than ``xtol * (1 + |x|)`` (physical units of ``x``) or after
    ``max_iter`` shrinking steps (the rare elements where the peak jumps then get a slightly lower,
    still safe bound). Closed brackets are carried along unchanged (one fused kernel per UNROLL steps)
    until fewer than half are open; those are then taken out. ``max_iter`` is rounded down to a multiple
    of UNROLL.
    """
    value, slope = fn(hi, s, dt)
    r_hi = value - s.pmax
    step = r_hi / slope
    lo = hi - step
    r_lo = fn(lo, s, dt)[0] - s.pmax
    for _ in range(max_iter // UNROLL):
        if not bool((r_lo > 0.0).any()):
            break
        lo, hi, r_lo, r_hi, step = _widen(fn, lo, hi, r_lo, r_hi, step, s, dt)
    keep_hi = torch.zeros_like(lo, dtype=torch.bool)  # Illinois: which end was kept last time
    keep_lo = torch.zeros_like(keep_hi)
    out = lo.clone()
    idx = torch.arange(lo.numel(), device=lo.device)
    for _ in range(max_iter // UNROLL):
        open_ = (hi - lo) > xtol * (1.0 + lo.abs())
        left = int(open_.sum())
        if left == 0:
            break
        if 2 * left < open_.numel():  # few brackets open: shrink only those from now on
            out.index_copy_(0, idx, lo)
            sel = open_.nonzero().squeeze(-1)
            s = s.take(sel)
            idx, lo, hi, r_lo, r_hi, keep_hi, keep_lo = (
                pick(t, sel) for t in (idx, lo, hi, r_lo, r_hi, keep_hi, keep_lo))
        lo, hi, r_lo, r_hi, keep_hi, keep_lo = _illinois(fn, lo, hi, r_lo, r_hi, keep_hi, keep_lo, s, dt, xtol)
    return out.index_copy_(0, idx, lo)


@kernel
def _widen(fn: PeakFn, lo: Tensor, hi: Tensor, r_lo: Tensor, r_hi: Tensor, step: Tensor, s: Side,
           dt: float) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """UNROLL doubling steps down of :func:`bracket_below` for the elements still above the limit."""
    for _ in range(UNROLL):
        bad = r_lo > 0.0
        step = torch.where(bad, 2.0 * step, step)
        hi, r_hi = torch.where(bad, lo, hi), torch.where(bad, r_lo, r_hi)
        lo = torch.where(bad, hi - step, lo)
        r_lo = torch.where(bad, fn(lo, s, dt)[0] - s.pmax, r_lo)
    return lo, hi, r_lo, r_hi, step


@kernel
def _illinois(fn: PeakFn, lo: Tensor, hi: Tensor, r_lo: Tensor, r_hi: Tensor, keep_hi: Tensor, keep_lo: Tensor,
              s: Side, dt: float, xtol: float) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor]:
    """UNROLL regula-falsi (Illinois) steps of :func:`bracket_below` on the brackets still open."""
    for _ in range(UNROLL):
        open_ = (hi - lo) > xtol * (1.0 + lo.abs())
        w_hi = torch.where(keep_hi, 0.5, 1.0) * r_hi
        w_lo = torch.where(keep_lo, 0.5, 1.0) * r_lo
        x = hi - w_hi * (hi - lo) / (w_hi - w_lo)
        x = torch.where((x > lo) & (x < hi), x, 0.5 * (lo + hi))
        r = fn(x, s, dt)[0] - s.pmax
        up = open_ & (r > 0.0)
        down = open_ & ~up
        lo, hi = torch.where(down, x, lo), torch.where(up, x, hi)
        r_lo, r_hi = torch.where(down, r, r_lo), torch.where(up, r, r_hi)
        keep_hi, keep_lo = torch.where(open_, ~up, keep_hi), torch.where(open_, up, keep_lo)
    return lo, hi, r_lo, r_hi, keep_hi, keep_lo


def greedy_root(s: Side, dt: float, probe: Tensor, tol: float = 1e-13) -> Tensor:
    """Root of ``greedy_peak(x) = pmax`` below ``probe`` (where the peak at ``probe`` exceeds ``pmax``).

    Closed form where the peak lies in the hold phase (one quadratic per ramp structure, accepted when
    consistent); otherwise Newton's method, started from the hold candidate of the shortest structure
    (for a convex function Newton converges from either side of the root).
    """
    root = probe.clone()
    done = torch.zeros_like(probe, dtype=torch.bool)
    start = probe.clone()
    most = int(torch.floor((probe + s.amax) / (s.jmax * dt)).clamp_min(0.0).max().item())
    for m in range(most + 1):
        root, done, start = _hold_candidate(s, dt, probe, float(m), root, done, start)
    todo = (~done).nonzero().squeeze(-1)
    if todo.numel():
        root[todo] = descend(_greedy_fn, pick(start, todo), s.take(todo), dt, tol)
    return root


@kernel
def _hold_candidate(s: Side, dt: float, probe: Tensor, m: float, root: Tensor, done: Tensor, start: Tensor
                    ) -> tuple[Tensor, Tensor, Tensor]:
    """One ramp structure ``m`` of :func:`greedy_root`: its hold-phase root where consistent and not found
    before; for ``m == 0`` also Newton's start."""
    x, v_h = hold_root(s, dt, torch.full_like(probe, m))
    fits = (v_h > 0.0) & (torch.floor((x + s.amax) / (s.jmax * dt)).clamp_min(0.0) == m) & (x <= probe)
    found = ~done & fits
    if m == 0.0:
        start = torch.where(x.isfinite() & (x < probe), x, probe)
    return torch.where(found, x, root), done | found, start


def greedy_bound(s: Side, dt: float, probe: Tensor, settle: float,
                 aware: Tensor) -> tuple[Tensor, Tensor, Tensor, Peak]:
    """Position bounds after the step: klimits' greedy root and the velocity-aware (safe) one.

    Only elements whose greedy peak at ``probe`` exceeds ``pmax`` are solved (``idx``); the others do not
    constrain anything the caller cares about. ``aware`` marks elements whose velocity floor can exceed
    ``-amax`` (only those can need the velocity-aware correction). Returns ``(idx, greedy, safe, peak)``,
    the last three for ``idx`` only (peak at the greedy root).
    """
    idx = (greedy_peak(probe, s, dt).value > s.pmax).nonzero().squeeze(-1)
    sub = s.take(idx)
    if idx.numel() == 0:
        empty = pick(probe, idx)
        return idx, empty, empty, greedy_peak(empty, sub, dt)
    root = greedy_root(sub, dt, pick(probe, idx))
    peak = greedy_peak(root, sub, dt)
    safe = root.clone()
    check = pick(aware, idx).nonzero().squeeze(-1)
    if check.numel():
        sc = sub.take(check)
        lifted = velocity_aware_peak(pick(root, check), sc, dt, _take_peak(peak, check), settle) > sc.pmax + 1e-13
        jdx = check[lifted]
        if jdx.numel():
            safe[jdx] = bracket_below(_aware_fn(settle), pick(root, jdx), sub.take(jdx), dt)
    return idx, root, safe, peak


def _take_peak(peak: Peak, idx: Tensor) -> Peak:
    return Peak(*(pick(getattr(peak, f.name), idx) for f in fields(peak)))


@kernel
def _greedy_fn(x: Tensor, s: Side, dt: float) -> tuple[Tensor, Tensor]:
    peak = greedy_peak(x, s, dt)
    return peak.value, peak.slope


@kernel
def _aware_value(x: Tensor, s: Side, dt: float, settle: float) -> tuple[Tensor, Tensor]:
    peak = greedy_peak(x, s, dt)
    return velocity_aware_peak(x, s, dt, peak, settle), peak.slope


@functools.cache
def _aware_fn(settle: float) -> PeakFn:
    """The velocity-aware peak as a PeakFn (one object per ``settle``: compiled steps specialize on it)."""
    def fn(x: Tensor, s: Side, dt: float) -> tuple[Tensor, Tensor]:
        return _aware_value(x, s, dt, settle)

    return fn


@kernel
def _ramp_reach(v: Tensor, a: Tensor, amax: Tensor, jmax: Tensor) -> Tensor:
    """Largest displacement ahead for a continuous full-jerk ramp from ``a`` onto ``-amax``, then held."""
    tr = (a + amax).clamp_min(0.0) / jmax
    u = last_down_crossing(v, a, jmax)
    in_ramp = (u >= 0.0) & (u <= tr)
    u = torch.where(in_ramp, u, tr)
    v_r = v + a * u - 0.5 * jmax * u * u
    reach = v * u + 0.5 * a * u * u - jmax * u**3 / 6.0
    return (reach + torch.where(in_ramp, 0.0, v_r.clamp_min(0.0) ** 2 / (2.0 * amax))).clamp_min(0.0)


@kernel
def reach_top(p0: Tensor, v0: Tensor, a0: Tensor, amax: Tensor, jmax: Tensor, dt: float,
              x_probe: Tensor) -> Tensor:
    """Upper bound on the greedy braking peak for every end acceleration ``x <= x_probe`` (cheap).

    Exact for the step and the next one (knot ``max(x - jmax*dt, -amax)``); from there a profile
    lying above the greedy one: that knot held for one more step, then the continuous full-jerk
    ramp onto ``-amax`` and ``-amax`` held.
    """
    x = x_probe
    g2 = torch.maximum(x - jmax * dt, -amax)
    p1 = p0 + v0 * dt + (a0 / 3.0 + x / 6.0) * dt * dt
    v1 = v0 + 0.5 * (a0 + x) * dt
    p2 = p1 + v1 * dt + (x / 3.0 + g2 / 6.0) * dt * dt
    v2 = v1 + 0.5 * (x + g2) * dt
    top1 = p0 + v0.clamp_min(0.0) * dt + 0.5 * torch.maximum(a0, x).clamp_min(0.0) * dt * dt
    top2 = p1 + v1.clamp_min(0.0) * dt + 0.5 * x.clamp_min(0.0) * dt * dt
    p3 = p2 + v2 * dt + 0.5 * g2 * dt * dt
    v3 = v2 + g2 * dt
    stops = (g2 < 0.0) & (v2 > 0.0) & (v3 <= 0.0)  # velocity reaches zero while g2 is held
    top3 = torch.where(stops, p2 + v2 * v2 / (-2.0 * g2).clamp_min(1e-300), p3 + _ramp_reach(v3, g2, amax, jmax))
    top3 = torch.where((v2 <= 0.0) & (g2 <= 0.0), p2, top3)
    return torch.maximum(torch.maximum(top1, top2), torch.maximum(torch.maximum(p1, p2), top3))
