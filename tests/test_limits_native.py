"""The native valid-range code (``pathrl/native/valid_range.c``) equals the torch reference and falls back safely.

Compared on states near every limit (the klimits test's sampler: positions near both limits with velocity
towards them, velocities and accelerations near theirs) and on states of rollouts that drive the joints
into their limits (the property test's action patterns). Agreement: 1e-9 of the acceleration limit (the
same tolerance as compiled vs eager torch); NaN/inf where and only where the torch code has them.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import torch
from test_limits import _near_limit_states
from test_limits_property import _SHIPPED, DT, ROBOTS, _actions

from pathrl import native
from pathrl.limits import feasible
from pathrl.limits.backend import LimitBackend, current
from pathrl.limits.feasible import action_to_acceleration
from pathrl.limits.integrate import end_of_step

TOL = 1e-9  # relative to the acceleration limit


def _agree(p, v, a, lim, stop_at_knot: bool) -> int:
    """Asserts native == torch on these states; returns the number of compared elements."""
    lo_t, hi_t, _ = feasible._valid_range_torch(p, v, a, lim, DT, stop_at_knot)
    lo_n, hi_n, _ = native.valid_range(p, v, a, lim.pos, lim.vel, lim.acc, lim.jerk,
                                       feasible._reach_radius(lim, DT), DT, stop_at_knot)
    for ref, got in ((lo_t, lo_n), (hi_t, hi_n)):
        assert torch.equal(ref.isfinite(), got.isfinite())
        fin = ref.isfinite()
        err = ((ref - got).abs() / lim.acc).where(fin, torch.zeros_like(ref))
        assert float(err.max()) < TOL, float(err.max())
    return lo_t.numel()


def test_native_code_is_built_here() -> None:
    """CI has a C compiler: the default path must be the native one (a silent fallback would hide a break)."""
    assert native.available()
    assert current().native  # the process default


@pytest.mark.parametrize("stop_at_knot", [True, False])
@pytest.mark.parametrize("robot", ROBOTS)
def test_native_equals_torch_near_limits(robot: str, stop_at_knot: bool) -> None:
    lim = _SHIPPED[ROBOTS.index(robot)]
    p, v, a = (torch.as_tensor(x) for x in _near_limit_states(lim, 20_000, np.random.default_rng(11)))
    assert _agree(p, v, a, lim, stop_at_knot) == 20_000 * lim.dof


@pytest.mark.parametrize("robot", ROBOTS)
def test_native_equals_torch_along_rollouts(robot: str) -> None:
    """States of limit-seeking rollouts (each driven by the torch ranges, so both see the same states)."""
    lim = _SHIPPED[ROBOTS.index(robot)]
    g = torch.Generator().manual_seed(5)
    n, steps = 96, 100
    p = lim.pos[:, 0] + (lim.pos[:, 1] - lim.pos[:, 0]) * torch.rand(n, lim.dof, generator=g, dtype=torch.float64)
    v, a, held = torch.zeros_like(p), torch.zeros_like(p), torch.zeros_like(p)
    compared = 0
    for k in range(steps):
        compared += _agree(p, v, a, lim, stop_at_knot=True)
        lo, hi, _ = feasible._valid_range_torch(p, v, a, lim, DT, True)
        a1 = action_to_acceleration(_actions(k, held, g), lo, hi)
        (p, v), a = end_of_step(p, v, a, a1, DT), a1
    assert compared == steps * n * lim.dof


def test_threads_split_rows_without_changing_results() -> None:
    lim = _SHIPPED[0]
    p, v, a = (torch.as_tensor(x) for x in _near_limit_states(lim, 4096, np.random.default_rng(2)))
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        assert native.threads() == 1
        one = feasible._valid_range(p, v, a, lim, DT, True)
        torch.set_num_threads(2)  # followed by default
        assert native.threads() == 2
        two = feasible._valid_range(p, v, a, lim, DT, True)
        torch.set_num_threads(1)
        native.set_threads(3)  # or set on its own
        assert native.threads() == 3
        three = feasible._valid_range(p, v, a, lim, DT, True)
    finally:
        torch.set_num_threads(before)
        native.set_threads(None)
    assert all(torch.equal(x, y) and torch.equal(x, z) for x, y, z in zip(one, two, three, strict=True))
    with pytest.raises(ValueError, match=">= 1"):
        native.set_threads(0)


def test_inputs_it_cannot_take_use_the_torch_code() -> None:
    lim = _SHIPPED[0]
    p = torch.zeros(3, lim.dof, dtype=torch.float64)
    assert native.applies(p, lim.pos)
    assert not native.applies(p.float(), lim.pos)
    assert not native.applies(p.long(), lim.pos)  # never read as doubles
    assert not native.applies(p.clone().requires_grad_(), lim.pos)
    assert native.applies(p, longs=(torch.zeros(3, dtype=torch.long),))
    assert not native.applies(p, longs=(torch.zeros(3, dtype=torch.int32),))
    with LimitBackend(native=False).active():
        lo, hi = feasible.valid_acceleration_range(p, p, p, lim, DT)  # the torch code
    lo_n, hi_n = feasible.valid_acceleration_range(p, p, p, lim, DT)
    assert torch.allclose(lo, lo_n, rtol=0, atol=1e-12) and torch.allclose(hi, hi_n, rtol=0, atol=1e-12)


def _probe(env: dict) -> subprocess.CompletedProcess:
    code = ("import warnings, torch; warnings.simplefilter('always')\n"
            "from pathrl import native\n"
            "from pathrl.limits import feasible\n"
            "from pathrl.limits.feasible import JointLimits\n"
            "from pathrl.robot.external import load_robot_by_name\n"
            "lim = JointLimits.from_robot(load_robot_by_name('iiwa7'))\n"
            "p = torch.zeros(2, 7, dtype=torch.float64)\n"
            "lo, hi = feasible.valid_acceleration_range(p, p, p, lim, 0.1)\n"
            "print('native' if native.available() else 'torch', float(hi[0, 0]))\n")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={**os.environ, **env},
                          timeout=120)


def test_switch_off_and_missing_compiler_fall_back_to_torch(tmp_path) -> None:
    off = _probe({"PATHRL_NATIVE": "0"})
    assert off.returncode == 0, off.stderr
    assert off.stdout.split()[0] == "torch" and "unavailable" not in off.stderr
    broken = _probe({"PATHRL_CACHE_DIR": str(tmp_path / "cache"), "CC": "false"})
    assert broken.returncode == 0, broken.stderr
    assert broken.stdout.split()[0] == "torch"
    assert "native code unavailable" in broken.stderr
    assert off.stdout.split()[1] == broken.stdout.split()[1]  # the same range either way
    built = _probe({"PATHRL_CACHE_DIR": str(tmp_path / "cache2")})
    assert built.returncode == 0 and built.stdout.split() == ["native", off.stdout.split()[1]], built.stderr
    assert len(list((tmp_path / "cache2").glob("pathrl_native_*.so"))) == 1  # no temp files left


def test_native_env_step_equals_torch() -> None:
    """``advance.c`` equals :func:`pathrl.envs.tracking.advance` (eager): moving, resting and clamped envs."""
    from pathrl.envs.tracking import advance
    from pathrl.paths.pathset import build_pathset

    rng = np.random.default_rng(0)
    paths = build_pathset([np.cumsum(rng.uniform(-0.1, 0.1, (10, 3)), axis=0) for _ in range(4)], list("abcd"))
    g = torch.Generator().manual_seed(5)
    n = 257
    pos, vel, acc, a1 = (torch.randn(n, 4, generator=g, dtype=torch.float64) * 0.1 for _ in range(4))
    vel[:8], acc[:8], a1[:8] = 0.0, 0.0, 0.0  # at rest: the deviation is a plain mean
    path = torch.randint(4, (n,), generator=g)
    s = torch.rand(n, generator=g, dtype=torch.float64) * paths.length[path]
    end_s = torch.minimum(s + 0.3 * torch.rand(n, generator=g, dtype=torch.float64), paths.length[path])
    args = (pos, vel, acc, a1, torch.tensor([0, 2, 3]), s, end_s, path, paths.table, paths.length,
            torch.tensor([1.0, 2.0, 0.5], dtype=torch.float64))
    assert native.applies(*args[:4], *args[5:7], *args[8:], longs=(args[4], args[7]))
    ref = advance(*args, 0.1, 8, paths.table_step)
    got = native.advance(*args, 0.1, 8, paths.table_step)
    assert bool((got[2][:8] == 0).all()) and bool((got[2][8:] > 0).all())
    for r, c in zip(ref, got, strict=True):
        torch.testing.assert_close(c, r, rtol=1e-12, atol=1e-14)
    with pytest.raises(ValueError, match="unsupported sizes"):
        native.advance(*args, 0.1, 100, paths.table_step)


def test_float32_limits_use_the_torch_code() -> None:
    """Limits built by hand in float32 must not be read as doubles by the native code."""
    lim = _SHIPPED[0]
    lim32 = feasible.JointLimits(*(t.float() for t in (lim.pos, lim.vel, lim.acc, lim.jerk)))
    p = torch.zeros(2, lim.dof, dtype=torch.float64)
    assert not native.applies(p, p, p, lim32.pos, lim32.vel, lim32.acc, lim32.jerk)
    lo, hi = feasible.valid_acceleration_range(p, p, p, lim32, DT)  # torch code, no garbage
    assert bool((hi > 0).all()) and bool((lo < 0).all()) and bool((hi <= lim.acc.float() + 1e-4).all())


def test_env_with_more_substeps_than_the_native_step_takes_uses_torch(tiny_dataset) -> None:
    """substeps > 64 is a valid config: the env steps with the torch kernel instead of failing."""
    from pathrl.dataset.io import load_pathset
    from pathrl.envs.rewards import build_reward_terms
    from pathrl.envs.tracking import PathTrackingEnv
    from pathrl.envs.tracking_cfg import TrackingEnvCfg
    from pathrl.paths.knots import KnotStrategy
    from pathrl.robot.external import load_robot_by_name

    robot = load_robot_by_name("iiwa7")
    paths = load_pathset(tiny_dataset, "train", KnotStrategy("distance", 0.3), robot=robot)
    terms = build_reward_terms({"path_length": {"weight": 1.0}})
    assert not native.advance_supports(7, 80, 100)
    moved = []
    for substeps in (64, 80):
        env = PathTrackingEnv(TrackingEnvCfg(num_envs=4, seed=0, substeps=substeps), robot, paths, terms)
        env.step(torch.full((4, 7), 0.5))
        moved.append(env.last_step["moved"])
    torch.testing.assert_close(moved[1], moved[0], rtol=1e-3, atol=1e-9)  # finer polyline, same motion
