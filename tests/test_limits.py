"""Tests of pathrl.limits: agreement with klimits, hand-derived cases, integration, checker, braking.

Agreement with klimits 1.1.3 (``test_klimits_agreement``), per shipped robot on 100k random robot
states drawn near every limit (positions close to both limits with velocity towards them, velocities
and accelerations close to their limits, and uniform ones):

* Compared are states inside the limits for which klimits reports no violation and our range needs
  no conflict resolution (i.e. a limit-respecting continuation exists).
* On >= 90 % of them (in practice 93-99 %) both bounds agree to 1e-6 (physical units; the residual
  is klimits' own root-finding accuracy, <= 1e-8 seen).
* Where they differ, our range is always the narrower one. Two causes, both in our favour:
  1. klimits bugs near position limits (wrong branch/root, or its 1e-3 s tolerance in the "first
     phase"): its bound then lets the greedy braking overshoot the limit. Verified here with an
     independent step-by-step braking simulation.
  2. klimits plans braking that holds ``-acc`` through the step where the velocity reaches zero,
     although its own velocity rule may forbid that knot (undershooting ``-vel`` afterwards). We
     raise that knot (velocity-aware braking), which tightens the bound by a few 1e-3 (iiwa) to
     ~0.16 (ARMAR arms) rad/s^2; without it bang-bang policies violate the velocity limit.
"""

from __future__ import annotations

import klimits
import numpy as np
import pytest
import torch

from pathrl.limits import _braking as braking_kernels
from pathrl.limits import feasible
from pathrl.limits.braking import braking_acceleration, braking_steps_bound, braking_within, is_stopped
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits, acceleration_to_action, action_to_acceleration, valid_acceleration_range
from pathrl.limits.integrate import end_of_step, interpolate_step
from pathrl.robot.external import load_robot_by_name

ROBOTS = ("iiwa7", "armar6", "armar4", "armar4_legs")
DT = 0.1
AGREE = 1e-6  # rad/s^2 (or m/s^2)


def _limits(name: str) -> JointLimits:
    return JointLimits.from_robot(load_robot_by_name(name))


def _t(x) -> torch.Tensor:
    return torch.as_tensor(np.asarray(x, dtype=np.float64))


# ----------------------------------------------------------------------------------------------
# Independent reference: exact peak of "step ending with x, then greedy braking", step by step.
# ----------------------------------------------------------------------------------------------


def _greedy_peak_reference(p, v, a, x, pmax, amax, jmax, dt, steps=80):
    """Max position (numpy, elementwise) of: acceleration a -> x over one step, then knots
    max(k - jmax*dt, -amax). Per step the velocity is quadratic; its roots and the step ends are
    evaluated exactly. Returns peak - pmax."""
    p, v, a, x, pmax, amax, jmax = (np.array(t, dtype=np.float64) for t in (p, v, a, x, pmax, amax, jmax))
    top = p.copy()
    nxt = x
    for _ in range(steps):
        jerk = (nxt - a) / dt
        cand = [np.full_like(p, dt)]
        disc = a * a - 2.0 * jerk * v
        with np.errstate(divide="ignore", invalid="ignore"):
            sq = np.sqrt(np.maximum(disc, 0.0))
            for r in ((-a + sq) / jerk, (-a - sq) / jerk, -v / a):
                cand.append(np.where(np.isfinite(r) & (r > 0) & (r < dt), r, dt))
        for t in cand:
            top = np.maximum(top, p + v * t + a * t * t / 2 + jerk * t**3 / 6)
        p, v, a = p + v * dt + (a / 3 + nxt / 6) * dt * dt, v + (a + nxt) / 2 * dt, nxt
        nxt = np.maximum(a - jmax * dt, -amax)
    return top - pmax


# ----------------------------------------------------------------------------------------------
# klimits agreement
# ----------------------------------------------------------------------------------------------


def _klimits(lim: JointLimits):
    pos, vel, acc, jerk = (t.numpy() for t in (lim.pos, lim.vel, lim.acc, lim.jerk))
    return klimits.PosVelJerkLimitation(
        time_step=DT, pos_limits=pos, vel_limits=np.stack([-vel, vel], 1),
        acc_limits=np.stack([-acc, acc], 1), jerk_limits=np.stack([-jerk, jerk], 1),
        acceleration_after_max_vel_limit_factor=0.01, set_velocity_after_max_pos_to_zero=True,
        limit_velocity=True, limit_position=True, normalize_acc_range=False, num_threads=1)


def _near_limit_states(lim: JointLimits, n: int, rng: np.random.Generator):
    """(n, D) states concentrated near the limits: positions near/at both limits with velocity towards
    them, velocities and accelerations near their limits, combinations, plus uniform ones."""
    lo, hi = lim.pos[:, 0].numpy(), lim.pos[:, 1].numpy()
    vel, acc = lim.vel.numpy(), lim.acc.numpy()
    shape = (n, len(vel))
    span = hi - lo
    upper = rng.uniform(size=shape) < 0.5
    gap = np.where(rng.uniform(size=shape) < 0.5, rng.exponential(0.02, shape), rng.uniform(0, 0.3, shape)) * span
    gap = np.where(rng.uniform(size=shape) < 0.05, 0.0, gap)  # exactly at the limit
    p = np.where(upper, hi - gap, lo + gap)
    p = np.where(rng.uniform(size=shape) < 0.25, rng.uniform(lo, hi, shape), p)
    towards = np.where(upper, 1.0, -1.0)
    v = np.where(rng.uniform(size=shape) < 0.5, towards * vel * (1 - rng.exponential(0.05, shape)),
                 vel * rng.uniform(-1, 1, shape))
    a = np.where(rng.uniform(size=shape) < 0.3, np.sign(rng.uniform(-1, 1, shape)) * acc
                 * (1 - rng.exponential(0.05, shape)), acc * rng.uniform(-1, 1, shape))
    return p, np.clip(v, -vel, vel), np.clip(a, -acc, acc)


def _compare(robot: str, n: int, seed: int):
    """klimits and our ranges on n random robot states; returns states, ranges, comparison mask."""
    lim = _limits(robot)
    kl = _klimits(lim)
    p, v, a = _near_limit_states(lim, n, np.random.default_rng(seed))
    ref = np.empty((n, lim.dof, 2))
    code = np.empty((n, lim.dof))
    for i in range(n):
        ref[i], code[i] = kl.calculate_valid_acceleration_range(p[i], v[i], a[i])
    lo, hi, overlap = feasible._valid_range(_t(p), _t(v), _t(a), lim, DT, stop_at_knot=True)
    inside = (p >= lim.pos[:, 0].numpy()) & (p <= lim.pos[:, 1].numpy())
    ok = (code == 0) & overlap.numpy() & inside
    return lim, (p, v, a), ref, lo.numpy(), hi.numpy(), ok


@pytest.mark.parametrize("robot", ROBOTS)
def test_klimits_agreement(robot: str) -> None:
    """See the module docstring for what is compared and asserted."""
    lim, (p, v, a), ref, lo, hi, ok = _compare(robot, 100_000, seed=7)
    assert ok.sum() > 0.5 * ok.size
    same = ok & (np.abs(lo - ref[..., 0]) <= AGREE) & (np.abs(hi - ref[..., 1]) <= AGREE)
    assert same.sum() >= 0.9 * ok.sum()

    acc, jerk = lim.acc.numpy(), lim.jerk.numpy()
    for side, mine, theirs in ((1, hi, ref[..., 1]), (-1, lo, ref[..., 0])):
        rows, cols = np.nonzero(ok & (np.abs(mine - theirs) > AGREE))
        pmax = np.where(side > 0, lim.pos[cols, 1].numpy(), -lim.pos[cols, 0].numpy())
        args = (side * p[rows, cols], side * v[rows, cols], side * a[rows, cols])
        common = (pmax, acc[cols], jerk[cols], DT)
        overshoot_theirs = _greedy_peak_reference(*args, side * theirs[rows, cols], *common)
        overshoot_mine = _greedy_peak_reference(*args, side * mine[rows, cols], *common)
        assert (overshoot_mine <= 1e-9).all(), "every bound of ours where klimits differs is safe"
        gap = side * (theirs - mine)[rows, cols]  # > 0: ours narrower
        wider, klimits_unsafe = gap < 0, overshoot_theirs > 1e-9
        assert (-gap[wider] <= 0.01 * acc[cols][wider]).all()  # klimits' root finding, rare
        tightened = ~wider & ~klimits_unsafe
        assert (gap[tightened] <= 0.02 * acc[cols][tightened]).all()


# ----------------------------------------------------------------------------------------------
# Hand-derived cases
# ----------------------------------------------------------------------------------------------


def _one(pos=(-10.0, 10.0), vel=2.0, acc=15.0, jerk=300.0) -> JointLimits:
    return JointLimits.from_arrays([pos], [vel], [acc], [jerk])


def _range(lim: JointLimits, p: float, v: float, a: float) -> tuple[float, float]:
    lo, hi = valid_acceleration_range(_t([[p]]), _t([[v]]), _t([[a]]), lim, DT)
    return float(lo), float(hi)


def test_rest_far_from_limits_gives_full_acceleration_range() -> None:
    # iiwa7: from rest, a step to +acc and the full-jerk ramp back peaks at about
    # acc*dt/2 + acc**2/(2*jerk) <= 1.5 rad/s < vel for every joint, and the joint is far from its
    # position limits, so the full acceleration range is valid (jerk*dt = 2*acc is not binding).
    lim = _limits("iiwa7")
    mid = lim.pos.mean(dim=1).expand(3, -1)
    zero = torch.zeros_like(mid)
    lo, hi = valid_acceleration_range(mid, zero, zero, lim, DT)
    assert torch.equal(lo, -lim.acc.expand(3, -1)) and torch.equal(hi, lim.acc.expand(3, -1))


def test_jerk_limits_the_range() -> None:
    lim = _one(jerk=50.0)  # jerk*dt = 5
    assert _range(lim, 0.0, 0.0, 3.0) == pytest.approx((-2.0, 8.0), abs=1e-12)


def test_at_max_velocity_no_further_acceleration() -> None:
    lo, hi = _range(_one(), 0.0, 2.0, 0.0)
    assert (lo, hi) == (-15.0, 0.0)


def test_velocity_reached_within_the_step() -> None:
    # v0 + a0*dt/2 >= vmax: a must cross zero inside the step when v = vmax (TrueAdapt eq. 12):
    # a1 = a0*(1 - a0*dt/(2*(vmax - v0))) = 0.5*(1 - 0.025/0.01) = -0.75.
    _, hi = _range(_one(), 0.0, 1.99, 0.5)
    assert hi == pytest.approx(-0.75, abs=1e-12)


def test_velocity_ramp_settles_exactly_at_the_limit() -> None:
    # From rest with a small velocity limit the bound is the settling ramp: a1, then the knot
    # -0.01*acc one step later; the velocity peak of that plan is exactly vmax.
    lim = _one(vel=0.1)
    _, x = _range(lim, 0.0, 0.0, 0.0)
    a_pin = -0.01 * 15.0
    v1 = 0.5 * x * DT
    v_peak = v1 + x * x * DT / (2.0 * (x - a_pin))  # zero crossing of a inside the next step
    assert v_peak == pytest.approx(0.1, abs=1e-12)
    assert 0.0 < x < 15.0


def test_at_rest_on_the_position_limit() -> None:
    lo, hi = _range(_one(pos=(-1.0, 1.0)), 1.0, 0.0, 0.0)
    assert lo == -15.0 and hi == pytest.approx(0.0, abs=1e-6) and hi <= 0.0


def test_position_bound_brakes_exactly_to_the_limit() -> None:
    # At full speed towards the limit, the upper bound is the largest end acceleration after which
    # full braking (greedy: -acc at the next knot, held) still stops at the limit: peak == limit.
    lim = _one(pos=(-1.0, 1.0))
    p, v, a = 0.6, 2.0, 0.0
    lo, hi, _ = feasible._valid_range(_t([[p]]), _t([[v]]), _t([[a]]), lim, DT, stop_at_knot=False)
    gap = _greedy_peak_reference([p], [v], [a], [float(hi)], [1.0], [15.0], [300.0], DT)
    assert abs(gap[0]) < 1e-9
    assert -15.0 < float(hi) < 0.0 and float(lo) == -15.0


def test_stop_at_knot_refinement_is_never_wider() -> None:
    lim = _limits("iiwa7")
    p, v, a = _near_limit_states(lim, 2000, np.random.default_rng(3))
    lo, hi = valid_acceleration_range(_t(p), _t(v), _t(a), lim, DT)
    lo_g, hi_g, _ = feasible._valid_range(_t(p), _t(v), _t(a), lim, DT, stop_at_knot=False)
    ok = feasible._valid_range(_t(p), _t(v), _t(a), lim, DT, stop_at_knot=True)[2]
    assert (lo[ok] >= lo_g[ok] - 1e-12).all() and (hi[ok] <= hi_g[ok] + 1e-12).all()


def test_pruning_does_not_change_results(monkeypatch: pytest.MonkeyPatch) -> None:
    lim = _limits("armar4_legs")
    p, v, a = _near_limit_states(lim, 3000, np.random.default_rng(5))
    expected = valid_acceleration_range(_t(p), _t(v), _t(a), lim, DT)
    no_prune = lambda p0, *args: torch.full_like(p0, float("inf"))  # noqa: E731
    monkeypatch.setattr(feasible, "reach_top", no_prune)
    unpruned = valid_acceleration_range(_t(p), _t(v), _t(a), lim, DT)
    assert torch.equal(expected[0], unpruned[0]) and torch.equal(expected[1], unpruned[1])


def test_range_is_ordered_and_clipped() -> None:
    lim = _limits("armar6")
    rng = np.random.default_rng(11)
    lo_l, hi_l = lim.pos[:, 0].numpy(), lim.pos[:, 1].numpy()
    shape = (5000, lim.dof)
    p = rng.uniform(lo_l - 0.1, hi_l + 0.1, shape)  # also outside the limits
    v = rng.uniform(-2, 2, shape) * lim.vel.numpy()
    a = rng.uniform(-1.5, 1.5, shape) * lim.acc.numpy()
    lo, hi = valid_acceleration_range(_t(p), _t(v), _t(a), lim, DT)
    assert torch.isfinite(lo).all() and torch.isfinite(hi).all() and (lo <= hi).all()
    assert (lo >= -lim.acc).all() and (hi <= lim.acc).all()


def test_in_step_bound_matches_its_definition() -> None:
    # The position touches the limit inside the step with zero velocity (tangency).
    # a0*tau**2 + 4*v0*tau - 6*(pmax - p0) = 0 -> tau = 0.0550510, x = -14.529 (hand-computed).
    s = braking_kernels.Side(*(_t([x]) for x in (0.99, 0.3, -2.0, 1.0, 15.0, 300.0, 2.0)))
    x = float(braking_kernels.in_step_bound(s, DT))
    assert x == pytest.approx(-2.0 - 2 * DT * (0.3 - 2.0 * 0.0550510257) / 0.0550510257**2, rel=1e-8)
    t = np.linspace(0, DT, 200_001)
    pos = 0.99 + 0.3 * t - 1.0 * t**2 + (x + 2.0) * t**3 / (6 * DT)
    assert pos.max() == pytest.approx(1.0, abs=1e-12)


def test_action_to_acceleration() -> None:
    lo, hi = _t([[-2.0, 1.0]]), _t([[4.0, 3.0]])
    assert torch.equal(action_to_acceleration(_t([[-1.0, 1.0]]), lo, hi), _t([[-2.0, 3.0]]))
    assert torch.equal(action_to_acceleration(_t([[0.0, 5.0]]), lo, hi), _t([[1.0, 3.0]]))


def test_action_to_acceleration_held_joints() -> None:
    # joint 0: range [-2, 4] contains 0; joint 1: [1, 3] does not (0 -> 1, the nearest admissible value)
    lo, hi = _t([[-2.0, 1.0]]), _t([[4.0, 3.0]])
    hold = torch.tensor([True, True])
    assert torch.equal(action_to_acceleration(_t([[0.0, 0.0]]), lo, hi, hold), _t([[0.0, 1.0]]))
    assert torch.equal(action_to_acceleration(_t([[-1.0, -1.0]]), lo, hi, hold), _t([[-2.0, 1.0]]))
    assert torch.equal(action_to_acceleration(_t([[1.0, 0.5]]), lo, hi, hold), _t([[4.0, 2.0]]))
    assert torch.equal(action_to_acceleration(_t([[-0.5, -3.0]]), lo, hi, hold), _t([[-1.0, 1.0]]))
    # only the held joint changes: joint 1 keeps the linear mapping
    mixed = action_to_acceleration(_t([[0.0, 0.0]]), lo, hi, torch.tensor([True, False]))
    assert torch.equal(mixed, _t([[0.0, 2.0]]))
    # acceleration_to_action inverts the centred mapping (and clips what lies outside the range)
    act = _t([[-1.0, -0.3, 0.0, 0.4, 1.0]])
    lo5, hi5 = _t([[-2.0, -2.0, 1.0, -3.0, 0.5]]), _t([[4.0, -1.0, 3.0, 1.0, 2.0]])
    back = acceleration_to_action(action_to_acceleration(act, lo5, hi5, torch.ones(5, dtype=torch.bool)), lo5, hi5)
    torch.testing.assert_close(back[:, [0, 1, 3, 4]], act[:, [0, 1, 3, 4]])
    assert float(back[0, 2]) == 0.0  # 0 is not admissible there: its nearest value c = 1 is action 0
    assert torch.equal(acceleration_to_action(_t([[9.0, -9.0]]), lo, hi), _t([[1.0, -1.0]]))


def test_joint_limits_validation_and_device() -> None:
    lim = _limits("iiwa7")
    assert lim.dof == 7 and lim.pos.dtype == torch.float64 and lim.to("cpu").vel.device.type == "cpu"
    with pytest.raises(ValueError):
        JointLimits.from_arrays([[1.0, 0.0]], [1.0], [1.0], [1.0])
    with pytest.raises(ValueError):
        JointLimits.from_arrays([[0.0, 1.0]], [1.0], [0.0], [1.0])


# ----------------------------------------------------------------------------------------------
# Integration and the limit checker
# ----------------------------------------------------------------------------------------------


def test_interpolate_step_formulas_and_end_of_step() -> None:
    g = torch.Generator().manual_seed(0)
    p0, v0, a0, a1 = (torch.randn(5, 3, generator=g, dtype=torch.float64) for _ in range(4))
    p, v, a = interpolate_step(p0, v0, a0, a1, DT, 24)
    assert p.shape == v.shape == a.shape == (5, 24, 3)
    t = DT * 7 / 24
    k = 6  # t = dt*7/24
    assert torch.allclose(a[:, k], a0 + (a1 - a0) * t / DT, atol=1e-14)
    assert torch.allclose(v[:, k], v0 + a0 * t + (a1 - a0) * t**2 / (2 * DT), atol=1e-14)
    assert torch.allclose(p[:, k], p0 + v0 * t + a0 * t**2 / 2 + (a1 - a0) * t**3 / (6 * DT), atol=1e-14)
    p1, v1 = end_of_step(p0, v0, a0, a1, DT)
    assert torch.allclose(p1, p[:, -1], atol=1e-14) and torch.allclose(v1, v[:, -1], atol=1e-14)
    assert torch.allclose(a[:, -1], a1, atol=1e-14)


def test_limit_violations_counts_each_kind() -> None:
    lim = JointLimits.from_arrays([[-1.0, 1.0]], [2.0], [10.0], [100.0])
    dt = 0.01
    a = torch.zeros(1, 6, 1, dtype=torch.float64)
    a[0, 3, 0] = 10.5  # acceleration violation and two jerk violations (1050 per s^3)
    p = torch.zeros_like(a)
    p[0, 0, 0] = 1.0 + 1e-7  # within tolerance? 1e-6 * width 2 = 2e-6 -> yes
    p[0, 1, 0] = -1.01  # violation
    v = torch.zeros_like(a)
    v[0, 2, 0] = -2.1
    out = limit_violations(p, v, a, lim, dt)
    assert {k: int(x) for k, x in out.items()} == {"position": 1, "velocity": 1, "acceleration": 1,
                                                   "jerk": 2, "total": 5}
    single = limit_violations(p[0], v[0], a[0], lim, dt)
    assert single["total"].shape == () and int(single["total"]) == 5


def test_limit_violations_accepts_infinite_limits() -> None:
    lim = JointLimits.from_arrays([[-np.inf, np.inf]], [1.0], [1.0], [np.inf])
    big = torch.full((4, 1), 1e9, dtype=torch.float64)
    out = limit_violations(big, big * 0, big * 0, lim, 0.01)
    assert int(out["total"]) == 0


# ----------------------------------------------------------------------------------------------
# Braking
# ----------------------------------------------------------------------------------------------


def _random_moving_states(lim: JointLimits, n: int, seed: int):
    """States reached by random actions from rest (hence inside the valid set)."""
    g = torch.Generator().manual_seed(seed)
    d = lim.dof
    p = lim.pos[:, 0] + (lim.pos[:, 1] - lim.pos[:, 0]) * torch.rand(n, d, generator=g, dtype=torch.float64)
    v, a = torch.zeros_like(p), torch.zeros_like(p)
    stop_at = torch.randint(1, 30, (n, 1), generator=g)
    for k in range(30):
        lo, hi = valid_acceleration_range(p, v, a, lim, DT)
        act = torch.sign(torch.rand(n, d, generator=g, dtype=torch.float64) - 0.5)
        act = torch.where(torch.rand(n, d, generator=g) < 0.5, act, 2 * torch.rand(n, d, generator=g) - 1)
        a1 = action_to_acceleration(act.to(p.dtype), lo, hi)
        p1, v1 = end_of_step(p, v, a, a1, DT)
        go = k < stop_at
        p, v, a = torch.where(go, p1, p), torch.where(go, v1, v), torch.where(go, a1, a)
    return p, v, a


@pytest.mark.parametrize("robot", ROBOTS)
def test_braking_stops_within_bound_without_violations(robot: str) -> None:
    lim = _limits(robot)
    p, v, a = _random_moving_states(lim, 200, seed=1)
    bound = braking_steps_bound(v, a, lim, DT)
    steps = torch.full((p.shape[0],), -1)
    samples = []
    for k in range(60):
        steps = torch.where((steps < 0) & is_stopped(v, a), k, steps)
        if bool((steps >= 0).all()):
            break
        a1 = braking_acceleration(p, v, a, lim, DT)
        samples.append(interpolate_step(p, v, a, a1, DT, 24))
        (p, v), a = end_of_step(p, v, a, a1, DT), a1
    assert (steps >= 0).all() and (steps <= bound).all()
    sp, sv, sa = (torch.cat(x, dim=1) for x in zip(*samples, strict=True))
    assert int(limit_violations(sp, sv, sa, lim, DT / 24, rtol=1e-9)["total"].sum()) == 0


def test_braking_law_details() -> None:
    lim = _one()
    zero = _t([[0.0]])
    lo, hi = _t([[-15.0]]), _t([[15.0]])
    # at rest: 0; below the stop tolerance: 0
    assert float(braking_within(zero, zero, lo, hi, DT, limits=lim)) == 0.0
    assert float(braking_within(_t([[0.005]]), _t([[-0.005]]), lo, hi, DT, limits=lim)) == 0.0
    # fast: full deceleration (clipped by the acceleration limit)
    assert float(braking_within(_t([[2.0]]), zero, lo, hi, DT, limits=lim)) == -15.0
    # deadbeat finish: v + a*dt/2 <= 0 -> a1 = -(v + a*dt/2)/dt, then 0 lands on v = a = 0
    v, a = _t([[0.05]]), _t([[-2.0]])
    a1 = braking_within(v, a, lo, hi, DT, limits=lim)
    assert float(a1) == pytest.approx(0.5, abs=1e-12)
    _, v1 = end_of_step(zero, v, a, a1, DT)
    _, v2 = end_of_step(zero, v1, a1, zero, DT)
    assert float(v2) == pytest.approx(0.0, abs=1e-15)
    # clipped into the valid range
    assert float(braking_within(_t([[2.0]]), zero, _t([[-3.0]]), hi, DT, limits=lim)) == -3.0
    assert bool(is_stopped(_t([[0.001, -0.009]]), _t([[0.0, 0.0099]]))) and not bool(
        is_stopped(_t([[0.001, 0.011]]), _t([[0.0, 0.0]])))
