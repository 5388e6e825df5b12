"""Compiled limit kernels (``pathrl.limits.kernels``) give the eager results and stay safe.

These test the torch code of the valid range, so they run with ``LimitBackend(native=False)`` (the native code,
``pathrl.native``, is the default where it builds); ``tests/test_limits_native.py`` compares the two.

The first test compiles every kernel (minutes on a fresh 2-core machine; inductor's disk cache makes
later runs fast). States come from eager rollouts with the property test's action patterns, so they
cover the limits (position stops, velocity saturation, braking).
"""

from __future__ import annotations

import pytest
import torch
from test_limits_property import _SHIPPED, DT, ROBOTS, _actions, _rollout

from pathrl.limits.backend import LimitBackend, current
from pathrl.limits.braking import braking_acceleration
from pathrl.limits.feasible import action_to_acceleration, valid_acceleration_range
from pathrl.limits.integrate import end_of_step

EAGER, COMPILED = LimitBackend(native=False), LimitBackend(native=False, compiled=True)


@pytest.fixture(autouse=True)
def torch_limit_code():
    with EAGER.active():
        yield


@pytest.fixture
def compiled_kernels():
    with COMPILED.active():
        yield


def _both(fn, *args):
    with EAGER.active():
        eager = fn(*args)
    with COMPILED.active():
        return eager, fn(*args)


@pytest.mark.parametrize("robot", ROBOTS)
def test_compiled_range_equals_eager(robot: str, compiled_kernels) -> None:
    lim = _SHIPPED[ROBOTS.index(robot)]
    g = torch.Generator().manual_seed(3)
    n, d = 256, lim.dof
    p = lim.pos[:, 0] + (lim.pos[:, 1] - lim.pos[:, 0]) * torch.rand(n, d, generator=g, dtype=torch.float64)
    v, a, held = torch.zeros_like(p), torch.zeros_like(p), torch.zeros_like(p)
    worst, compared = 0.0, 0
    for k in range(120):
        (lo, hi), (lo_c, hi_c) = _both(valid_acceleration_range, p, v, a, lim, DT)
        worst = max(worst, float(((lo - lo_c).abs() / lim.acc).max()), float(((hi - hi_c).abs() / lim.acc).max()))
        compared += lo.numel()
        brake, brake_c = _both(braking_acceleration, p, v, a, lim, DT)
        worst = max(worst, float(((brake - brake_c).abs() / lim.acc).max()))
        a1 = action_to_acceleration(_actions(k, held, g), lo, hi)
        (p, v), a = end_of_step(p, v, a, a1, DT), a1
    assert compared == 120 * n * d
    assert worst < 1e-9, worst  # relative to the acceleration limit


@pytest.mark.parametrize("robot", ROBOTS)
def test_compiled_rollouts_never_violate_limits(robot: str, compiled_kernels) -> None:
    lim = _SHIPPED[ROBOTS.index(robot)]
    assert _rollout(lim, n=64, seed=29) > 0  # asserts zero violations inside


def test_active_backend_nests_and_restores_the_previous_one() -> None:
    assert current() == EAGER  # this module's fixture
    with COMPILED.active():
        assert current().compiled
        with EAGER.active():
            assert not current().compiled
        assert current().compiled
    assert current() == EAGER


def test_compiled_env_advance_equals_eager(compiled_kernels) -> None:
    """The env's fused step kernel (static shapes) gives the eager results, and recompiles for a new batch size."""
    import numpy as np

    from pathrl.envs.tracking import advance
    from pathrl.paths.pathset import build_pathset

    rng = np.random.default_rng(0)
    paths = build_pathset([np.cumsum(rng.uniform(-0.1, 0.1, (10, 3)), axis=0) for _ in range(4)], list("abcd"))
    g = torch.Generator().manual_seed(5)
    for n in (64, 37):
        pos, vel, acc, a1 = (torch.randn(n, 4, generator=g, dtype=torch.float64) * 0.1 for _ in range(4))
        path = torch.randint(4, (n,), generator=g)
        s = torch.rand(n, generator=g, dtype=torch.float64) * paths.length[path] * 0.5
        args = (pos, vel, acc, a1, torch.tensor([0, 2, 3]), s, s + 0.3, path, paths.table, paths.length,
                torch.tensor([1.0, 2.0, 0.5], dtype=torch.float64), 0.1, 8, paths.table_step)
        eager, compiled = _both(advance, *args)
        assert compiled[2].shape == (n,) and bool((compiled[2] > 0).all())
        for e, c in zip(eager, compiled, strict=True):
            torch.testing.assert_close(c, e, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("relative,end_obs", [(True, True), (False, False)])
def test_compiled_env_observation_equals_eager(compiled_kernels, relative: bool, end_obs: bool) -> None:
    """The env's observation kernel (static shapes) gives the eager state, window ends included."""
    import numpy as np

    from pathrl.envs.observations import observe_state
    from pathrl.paths.pathset import build_pathset

    rng = np.random.default_rng(1)
    paths = build_pathset([np.cumsum(rng.uniform(-0.1, 0.1, (8 + i, 3)), axis=0) for i in range(4)], list("abcd"))
    g = torch.Generator().manual_seed(3)
    n = 48
    pos, vel, acc = (torch.randn(n, 4, generator=g, dtype=torch.float64) * 0.3 for _ in range(3))
    path = torch.randint(4, (n,), generator=g)
    s = torch.rand(n, generator=g, dtype=torch.float64) * paths.length[path]
    end_knot = paths.num_knots[path] - 1 - torch.randint(3, (n,), generator=g)
    end_s = paths.knot_s[path, end_knot]
    lim = torch.tensor([[-1.0, 1.0]] * 4, dtype=torch.float64)
    ones = torch.ones(4, dtype=torch.float64)
    knot_i = paths.knot_index_at(path, s)
    args = (pos, vel, acc, lim, ones, 2.0 * ones, torch.tensor([0, 1, 3]), paths.knots, paths.knot_s, path, knot_i, s,
            end_knot, paths.position_at(path, end_s), end_s, 5, 1.2, 0.3, relative, end_obs)
    eager, compiled = _both(observe_state, *args)
    assert bool(eager[2].any()) and not bool(eager[2].all())  # some windows reach the end knot
    for e, c in zip(eager, compiled, strict=True):
        torch.testing.assert_close(c, e, rtol=1e-12, atol=1e-14)
