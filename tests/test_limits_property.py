"""Property tests: following the valid acceleration range never violates a limit.

Trajectories start at rest at random positions and take random actions in [-1, 1] for 200 (random
joints: 150) decision steps; each step is integrated at 240 Hz (24 setpoints) and every setpoint is
checked with :func:`pathrl.limits.check.limit_violations` at ``rtol = 1e-7`` (relative to the
velocity, acceleration and jerk limit, and to the width of the position range). Exact arithmetic would
give no excess at all; the worst seen is ~1e-8 (jerk), where a forced range ``[x, x]`` at the position
boundary and the jerk bound differ by rounding and are averaged (klimits' rule). Action patterns: uniform,
bang-bang, held extremes that switch now and then, and long alternating blocks of +-1 (the last three drive
the joints into their limits again and again).

Joints are the shipped robots' joints and, via hypothesis, robot-like random joints: limits of shipped
joints scaled by 0.5..1.5 with jerk = (15..40) * acc (the shipped ratio is 20). Outside that domain
(much smaller jerk/acc ratios, or position ranges shorter than the braking distances) the two limits of
a joint and its velocity limit can interact in ways neither klimits nor this module plan for.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pathrl.limits.braking import braking_acceleration, braking_steps_bound, is_stopped
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits, action_to_acceleration, valid_acceleration_range
from pathrl.limits.integrate import end_of_step, interpolate_step
from pathrl.robot.external import load_robot_by_name

DT, SUB, STEPS, RTOL = 0.1, 24, 200, 1e-7
ROBOTS = ("iiwa7", "armar6", "armar4", "armar4_legs")
_SHIPPED = [JointLimits.from_robot(load_robot_by_name(name)) for name in ROBOTS]
_POOL = [torch.cat([getattr(lim, f) for lim in _SHIPPED]) for f in ("pos", "vel", "acc", "jerk")]


def _actions(k: int, held: torch.Tensor, g: torch.Generator) -> torch.Tensor:
    """Actions at step k; env i uses pattern i % 4 (uniform, bang-bang, held extremes, +-1 blocks)."""
    r = 2.0 * torch.rand(held.shape, generator=g, dtype=torch.float64) - 1.0
    flip = (torch.rand(held.shape, generator=g) < 0.1) | (held == 0)
    held.copy_(torch.where(flip, torch.sign(r), held))
    block = torch.full_like(r, 1.0 if (k // 20) % 2 else -1.0)
    mode = (torch.arange(r.shape[0]) % 4).unsqueeze(1)
    return torch.where(mode == 0, r, torch.where(mode == 1, torch.sign(r), torch.where(mode == 2, held, block)))


def _rollout(lim: JointLimits, n: int, seed: int, steps: int = STEPS) -> int:
    """Runs n envs from rest; asserts no violation; returns the number of checked (sample, joint) pairs."""
    g = torch.Generator().manual_seed(seed)
    d = lim.dof
    p = lim.pos[:, 0] + (lim.pos[:, 1] - lim.pos[:, 0]) * torch.rand(n, d, generator=g, dtype=torch.float64)
    v, a = torch.zeros_like(p), torch.zeros_like(p)
    held = torch.zeros_like(p)
    chunks = [(p.unsqueeze(1), v.unsqueeze(1), a.unsqueeze(1))]  # the start, so the first jerk is checked
    checked = 0
    for k in range(steps):
        lo, hi = valid_acceleration_range(p, v, a, lim, DT)
        a1 = action_to_acceleration(_actions(k, held, g), lo, hi)
        chunks.append(interpolate_step(p, v, a, a1, DT, SUB))
        (p, v), a = end_of_step(p, v, a, a1, DT), a1
        if len(chunks) > 50 or k == steps - 1:
            sp, sv, sa = (torch.cat(x, dim=1) for x in zip(*chunks, strict=True))
            out = limit_violations(sp, sv, sa, lim, DT / SUB, rtol=RTOL)
            assert int(out["total"].sum()) == 0, {key: int(val.sum()) for key, val in out.items()}
            checked += sp[:, 1:].numel()
            chunks = [tuple(x[:, -1:] for x in chunks[-1])]  # keep the last knot for the jerk across chunks
    return checked


@pytest.mark.parametrize("robot", ROBOTS)
def test_shipped_robots_never_violate_limits(robot: str) -> None:
    assert _rollout(_SHIPPED[ROBOTS.index(robot)], n=64, seed=17) == 64 * STEPS * SUB * _SHIPPED[
        ROBOTS.index(robot)].dof


@st.composite
def robot_like_limits(draw) -> JointLimits:
    """1-6 joints: shipped joints with limits scaled by 0.5..1.5 and jerk = (15..40) * acc."""
    d = draw(st.integers(1, 6))
    pick = draw(st.lists(st.integers(0, len(_POOL[1]) - 1), min_size=d, max_size=d))
    scale = np.array(draw(st.lists(st.floats(0.5, 1.5), min_size=3 * d, max_size=3 * d))).reshape(3, d)
    ratio = np.array(draw(st.lists(st.floats(15.0, 40.0), min_size=d, max_size=d)))
    pos, vel, acc = (t[pick].numpy() for t in _POOL[:3])
    mid, half = pos.mean(1), 0.5 * (pos[:, 1] - pos[:, 0]) * scale[0]
    acc = acc * scale[2]
    return JointLimits.from_arrays(np.stack([mid - half, mid + half], 1), vel * scale[1], acc, acc * ratio)


@settings(max_examples=10, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(lim=robot_like_limits(), seed=st.integers(0, 2**31 - 1))
def test_random_robot_like_joints_never_violate_limits(lim: JointLimits, seed: int) -> None:
    assert _rollout(lim, n=16, seed=seed, steps=150) > 0


@settings(max_examples=8, deadline=None, derandomize=True)
@given(lim=robot_like_limits(), seed=st.integers(0, 2**31 - 1))
def test_braking_from_reachable_states(lim: JointLimits, seed: int) -> None:
    """Random actions for a random number of steps, then braking: stops in time, no violations."""
    g = torch.Generator().manual_seed(seed)
    n, d = 32, lim.dof
    p = lim.pos[:, 0] + (lim.pos[:, 1] - lim.pos[:, 0]) * torch.rand(n, d, generator=g, dtype=torch.float64)
    v, a = torch.zeros_like(p), torch.zeros_like(p)
    held = torch.zeros_like(p)
    for k in range(int(torch.randint(1, 25, (1,), generator=g))):
        lo, hi = valid_acceleration_range(p, v, a, lim, DT)
        a1 = action_to_acceleration(_actions(k, held, g), lo, hi)
        (p, v), a = end_of_step(p, v, a, a1, DT), a1
    bound = braking_steps_bound(v, a, lim, DT)
    chunks = []
    for _ in range(int(bound.max()) + 1):
        if bool(is_stopped(v, a).all()):
            break
        a1 = braking_acceleration(p, v, a, lim, DT)
        chunks.append(interpolate_step(p, v, a, a1, DT, SUB))
        (p, v), a = end_of_step(p, v, a, a1, DT), a1
    assert bool(is_stopped(v, a).all())
    if chunks:
        sp, sv, sa = (torch.cat(x, dim=1) for x in zip(*chunks, strict=True))
        assert int(limit_violations(sp, sv, sa, lim, DT / SUB, rtol=RTOL)["total"].sum()) == 0
