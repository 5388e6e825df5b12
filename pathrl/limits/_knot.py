"""klimits' "stop at a decision step" refinement of the position bound.

klimits (``set_velocity_after_max_pos_to_zero=True``) asks the braking trajectory to reach ``v = 0``
exactly on a knot at the position limit, instead of touching the limit between knots. Each candidate
profile is linear in two unknowns, the end acceleration ``x`` and one free jerk ``j``, so ``v = 0`` and
``p = pmax`` at the stop knot are a 2x2 linear system; its coefficients are closed-form sums over the
knots. Candidate profiles are tried in klimits' order (it depends on where the greedy peak lies).
"""

from __future__ import annotations

import torch
from torch import Tensor

from pathrl.limits._braking import Peak, Side, hold_root, pick
from pathrl.limits.kernels import kernel


def knot_stop_bound(s: Side, dt: float, peak: Peak) -> Tensor:
    """Largest ``x`` whose braking ends with ``v = 0`` on a knot exactly at ``pmax``; (M,).

    Profile (knot indices from 1 = end of the coming step): ``x``, the greedy structure of the peak
    (``peak.ramp`` full-jerk knots, then ``-amax``) up to a turning knot, one step with a free jerk,
    then full jerk up to the stop knot ``K = ceil(t/dt)`` (``t`` = greedy peak time, or klimits' hold
    hypothesis when the peak lies in the reduced-jerk step). Returns ``+inf`` where no candidate is
    admissible or the peak is reached within the coming step.
    """
    out = torch.full_like(s.p, float("inf"))
    use = ((peak.time > dt + 1e-8) & (peak.phase > 0)).nonzero().squeeze(-1)
    if use.numel() == 0:
        return out
    s, m, phase, time = s.take(use), pick(peak.ramp, use), pick(peak.phase, use), pick(peak.time, use)
    time = torch.where(phase == 2, _hold_hypothesis_time(s, dt, m), time)
    stop = torch.ceil(time / dt).clamp_min(2.0)
    lowest = (stop - torch.floor(s.amax / (s.jmax * dt)) - 1.0).clamp_min(1.0)
    fewer = (m - 1.0).clamp_min(0.0)
    plans = (  # (ramp structure, first turning knot, last turning knot, applies) in klimits' order
        (fewer, stop - 1.0, m + 1.0, (phase == 2) & (m >= 1.0)),  # P: structure one knot shorter
        (m, stop - 1.0, m + 2.0, phase == 3),  # H: turn after the hold has started
        (fewer, stop - 1.0, m + 1.0, (phase == 3) & (m >= 1.0)),  # H: structure one knot shorter
        (m, torch.minimum(stop - 1.0, torch.where(phase == 1, stop, m + 1.0)), lowest, phase > 0),  # ramp
    )
    best = torch.full_like(s.p, float("nan"))
    for ramp, first, last, applies in plans:
        last = torch.maximum(last, lowest)
        for back in range(int((first - last).max().item()) + 1):
            best = _try_plan(best, applies, s, dt, stop, first - back, ramp, last)
    out[use] = torch.where(best.isnan(), float("inf"), best)
    return out


@kernel
def _try_plan(best: Tensor, applies: Tensor, s: Side, dt: float, stop: Tensor, turn: Tensor, ramp: Tensor,
              last: Tensor) -> Tensor:
    """``best`` with :func:`_solve`'s ``x`` filled in where no earlier profile was admissible and this one
    applies (turning knot not below ``last``); evaluated on all elements, kept where it counts."""
    x = _solve(s, dt, stop, turn, ramp)
    return torch.where(applies & best.isnan() & (turn >= last), x, best)


@kernel
def _solve(s: Side, dt: float, stop: Tensor, turn: Tensor, ramp: Tensor) -> Tensor:
    """``x`` of one stop-at-a-knot profile (nan where inadmissible); all (M,), indices as floats.

    Knots: 1: ``x``; 2..turn: ``x - J*dt*(k-1)`` while ``k <= ramp + 1``, else ``-A``; turn+1: knot
    ``turn`` plus ``j*dt``; then ``+J*dt`` per knot up to ``stop``. Velocity and position at knot
    ``stop`` are affine in ``(x, j)``: ``v = cv + av*x + bv*j``, ``p = cp + ap*x + bp*j``.
    """
    big_t, jm, am = dt, s.jmax, s.amax
    n_r = (torch.minimum(turn, ramp + 1.0) - 1.0).clamp_min(0.0)  # ramp knots among 2..turn
    n_h = turn - 1.0 - n_r  # hold knots among 2..turn
    on_ramp = (turn <= ramp + 1.0).to(s.p.dtype)
    turn_const = torch.where(turn <= ramp + 1.0, -jm * big_t * (turn - 1.0), -am)  # knot `turn` = on_ramp*x + c
    up = stop - turn  # knots turn+1..stop
    s1, s2 = n_r * (n_r + 1.0) / 2.0, n_r * (n_r + 1.0) * (2.0 * n_r + 1.0) / 6.0
    hold_sum = (2.0 + n_r + turn) * n_h / 2.0  # sum of hold knot indices
    up_v, up_p = big_t * (up - 0.5), big_t**2 * ((up - 1.0) * up / 2.0 + 1.0 / 6.0)  # weights of knot turn+1
    up_vc, up_pc = jm * big_t**2 * (up - 1.0) ** 2 / 2.0, jm * big_t**3 * (up - 1.0) ** 3 / 6.0
    av = big_t * (1.0 + n_r) + on_ramp * up_v
    ap = big_t**2 * ((stop - 1.0) * (1.0 + n_r) - s1) + on_ramp * up_p
    bv, bp = big_t * up_v, big_t * up_p
    cv = (s.v + 0.5 * big_t * s.a - jm * big_t**2 * s1 - am * big_t * n_h + turn_const * up_v + up_vc)
    cp = (s.p + s.v * stop * big_t + big_t**2 * s.a * (1.0 / 3.0 + 0.5 * (stop - 1.0))
          + jm * big_t**3 * (s2 - (stop - 1.0) * s1) - am * big_t**2 * (n_h * stop - hold_sum)
          + turn_const * up_p + up_pc)
    det = av * bp - bv * ap
    rhs = s.pmax - cp
    x = (-cv * bp - bv * rhs) / det
    j = (av * rhs + cv * ap) / det
    a_turn = on_ramp * x + turn_const
    a_ramp = x - jm * big_t * ramp  # last full-jerk knot of the structure
    tol = 1e-6
    ok = (j.abs() <= jm + 1e-4) & (a_turn > -am - tol) & (a_turn + j * big_t > -am - tol)
    ok &= (a_ramp > -am - tol) & ((turn <= ramp + 1.0) | (a_ramp + am <= jm * big_t * (1.0 + 1e-6)))
    ok &= (x > s.a - jm * big_t - tol) & (turn >= 1.0) & (turn < stop) & (det != 0.0)
    return torch.where(ok, x, float("nan"))


def _hold_hypothesis_time(s: Side, dt: float, ramp: Tensor) -> Tensor:
    """Peak time (from the step start) if the greedy peak were in the hold, ramp structure fixed.

    klimits picks the stop knot from this time also when the actual peak lies in the reduced-jerk step.
    """
    _, v_h = hold_root(s, dt, ramp)
    return 2.0 * dt + ramp * dt + v_h / s.amax
