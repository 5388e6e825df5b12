"""Path changes during training (pathrl.envs.path_changes, pathrl.paths.branch): the batched branch is the evaluation's
branch, its tables are build_pathset's, off changes nothing, each episode changes at most once at its switch time,
and changes keep every limit (hypothesis)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pathrl.cli.common import compose, to_container
from pathrl.dataset.io import load_dataset
from pathrl.envs.path_change_cfg import PathChangeCfg
from pathrl.envs.path_changes import PathChanges, with_path_changes
from pathrl.envs.registry import EnvRequest, make_env
from pathrl.eval.path_change import branch
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits
from pathrl.limits.integrate import interpolate_step
from pathrl.paths.branch import BranchShape, BranchStart, branch_knots, dedupe_padded, tabulate_batch
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.pathset import build_pathset
from pathrl.paths.spline import dedupe_knots
from pathrl.robot.model import load_robot
from pathrl.schema import TrainAppCfg

ROOT = Path(__file__).resolve().parents[1]
DATASET = ROOT / "datasets" / "iiwa7" / "random"


def _cfg(overrides: list[str]) -> dict:
    return to_container(compose("train", overrides, TrainAppCfg))


@pytest.fixture(scope="module")
def cfg() -> dict:
    return _cfg(["+experiment=iiwa7_random_path_change"])


@pytest.fixture(scope="module")
def setup(cfg):
    """(robot, a bank of 6 test paths with the experiment's knots)."""
    robot = load_robot(cfg["robot"])
    knots = load_dataset(DATASET, robot).splits["test"].knots[:6]
    strategy = KnotStrategy.from_cfg(cfg["knots"])
    return robot, build_pathset([strategy.apply(k) for k in knots], [str(i) for i in range(6)])


def _random_paths(rng: np.random.Generator, n: int, m: int) -> list[np.ndarray]:
    return [np.cumsum(rng.normal(0.0, 0.3, (int(rng.integers(2, 30)), m)), axis=0) for _ in range(n)]


@pytest.mark.parametrize("seed", range(4))
def test_batched_branch_equals_the_evaluations_branch(seed):
    """branch_knots row by row equals pathrl.eval.path_change.branch on the path's knots (to 1e-12), with and
    without the lead knot, and with no knot left."""
    rng = np.random.default_rng(seed)
    b, m = 8, 7
    ps = build_pathset(_random_paths(rng, b, m), [str(i) for i in range(b)])
    lim = np.stack([np.full(m, -2.0), np.full(m, 2.0)], axis=1)
    s_now = torch.as_tensor(rng.uniform(0.0, 1.05, b)) * ps.length
    q, v = torch.as_tensor(rng.normal(0, 1, (b, m))), torch.as_tensor(rng.normal(0, 1, (b, m)))
    v[0] = 0.0
    offset, ramp = torch.as_tensor(rng.normal(0, 0.4, (b, m))), torch.as_tensor(rng.uniform(0.2, 1.5, b))
    got, count = branch_knots(ps.knots, ps.knot_s, ps.num_knots - 1, BranchStart(s_now, q, v),
                              BranchShape(offset, ramp, torch.as_tensor(lim)))
    for i in range(b):
        knots = ps.knots[i, : int(ps.num_knots[i])].numpy()
        start = BranchStart(float(s_now[i]), q[i].numpy(), v[i].numpy())
        ref = branch(knots, start, BranchShape(offset[i].numpy(), float(ramp[i]), lim))
        n = int(count[i])
        assert ref.shape == (n, m)
        np.testing.assert_allclose(got[i, :n].numpy(), ref, rtol=0, atol=1e-12)
        assert bool((got[i, n:] == got[i, n - 1]).all())  # padded with its last knot


def test_dedupe_padded_equals_dedupe_knots():
    rng = np.random.default_rng(5)
    rows = [rng.normal(size=(k, 3)) for k in (2, 5, 9)]
    rows[1][2] = rows[1][1]
    rows[2][[1, 2, 6]] = rows[2][[0, 1, 5]]
    knots = torch.stack([torch.as_tensor(np.vstack([r, np.repeat(r[-1:], 9 - len(r), 0)])) for r in rows])
    got, count = dedupe_padded(knots, torch.tensor([2, 5, 9]))
    for i, r in enumerate(rows):
        ref = dedupe_knots(r)
        assert int(count[i]) == len(ref)
        np.testing.assert_array_equal(got[i, : len(ref)].numpy(), ref)
        assert bool((got[i, len(ref):] == got[i, len(ref) - 1]).all())


def test_batched_tables_equal_build_pathset():
    """tabulate_batch with build_pathset's arc-length spacing gives its tables (1e-9); training's coarser spacing with
    Richardson extrapolation stays within 5e-4 rad of them."""
    rng = np.random.default_rng(1)
    paths = _random_paths(rng, 7, 7) + [np.array([[0.0] * 7, [0.5] * 7])]
    ps = build_pathset(paths, [str(i) for i in range(len(paths))])
    width = ps.table.shape[1] + 5
    exact = tabulate_batch(ps.knots, ps.num_knots, ps.table_step, width, chunk=3)
    np.testing.assert_allclose(exact["length"].numpy(), ps.length.numpy(), rtol=0, atol=1e-9)
    np.testing.assert_allclose(exact["knot_s"].numpy(), ps.knot_s.numpy(), rtol=0, atol=1e-9)
    np.testing.assert_allclose(exact["table"][:, : ps.table.shape[1]].numpy(), ps.table.numpy(), rtol=0, atol=1e-9)
    assert bool((exact["table"][:, ps.table.shape[1]:] - ps.table[:, -1:]).abs().max() < 1e-9)
    assert bool(exact["fits"].all())
    fast = tabulate_batch(ps.knots, ps.num_knots, ps.table_step, width, arc_step=0.01, extrapolate=True)
    assert float((fast["length"] - ps.length).abs().max()) < 5e-4
    inside = (torch.arange(ps.table.shape[1]) * ps.table_step < ps.length.unsqueeze(1) - 0.01).unsqueeze(2)
    assert float(((fast["table"][:, : ps.table.shape[1]] - ps.table) * inside).abs().max()) < 5e-4
    assert not bool(tabulate_batch(ps.knots, ps.num_knots, ps.table_step, 10)["fits"].any())


def test_off_is_the_env_itself_and_configs_compose(setup, cfg):
    robot, paths = setup
    plain = _cfg(["+experiment=iiwa7_random_length6"])
    assert plain["path_change"] is None  # the default: no key value, saved configs unchanged
    group = _cfg(["+experiment=iiwa7_random_length6", "path_change=train"])["path_change"]
    assert {**group, "offsets": [0.3], "ramps": [1.0]} == cfg["path_change"]  # the experiment keeps gentle changes
    assert cfg["path_change"]["enabled"] and cfg["init_from"] == "models/tracking/iiwa7_random_length6"
    assert cfg["iterations"] == 200
    env = make_env(plain, EnvRequest(num_envs=2, seed=0, paths=paths, robot=robot))
    assert with_path_changes(plain, env) is env
    assert with_path_changes({**plain, "path_change": {"enabled": False}}, env) is env
    assert env.sample_paths is None
    with pytest.raises(ValueError, match="path_change.fraction"):
        with_path_changes({**plain, "path_change": {"enabled": True, "fraction": 2.0}}, env)
    with pytest.raises(ValueError, match="unknown keys"):
        PathChangeCfg.from_run({"path_change": {"enabled": True, "switch": [1, 2]}})


def _wrapped(cfg, setup, n: int, seed: int, **pc) -> PathChanges:
    robot, paths = setup
    env = make_env(cfg, EnvRequest(num_envs=n, seed=seed, paths=paths, robot=robot), max_deviation=None)
    return PathChanges(env, PathChangeCfg(enabled=True, **pc))


def test_each_episode_changes_at_most_once_at_its_switch_time(cfg, setup):
    w = _wrapped(cfg, setup, 16, 0, fraction=0.75, switch_range=[0.3, 1.5], slots=6)
    env, base = w.env, w.base
    calls: list[tuple[torch.Tensor, torch.Tensor]] = []
    replace = env.replace_path

    def spy(ids, path, s, end_knot=None):
        calls.append((ids.clone(), env.episode_length_buf[ids].clone()))
        replace(ids, path, s, end_knot)

    env.replace_path = spy
    per_episode = torch.zeros(16, dtype=torch.long)
    gen = torch.Generator().manual_seed(0)
    total = 0
    for _ in range(60):
        switch, pending = w.switch_step.clone(), w.pending.clone()
        calls.clear()
        _, _, dones, extras = w.step(torch.rand(16, env.num_actions, generator=gen) * 2 - 1)
        per_episode[dones] = 0
        for ids, steps in calls:
            assert bool(pending[ids].all()) and torch.equal(steps, switch[ids])
            per_episode[ids] += 1
            total += len(ids)
        assert int(per_episode.max()) <= 1
        assert int(extras["log"]["PathChange/changes_per_step"]) == sum(len(i) for i, _ in calls)
        on_branch = env.seg_path >= base
        assert torch.equal(on_branch, w.changed)  # a changed episode tracks its branch until it ends
        assert len(torch.unique(env.seg_path[on_branch])) == int(on_branch.sum()) <= 6  # one slot each
        assert bool((env.seg_path[dones] < base).all())  # new episodes start on the dataset's paths
    assert total >= 8


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**31 - 1), offset=st.floats(0.0, 1.0), ramp=st.floats(0.05, 1.5),
       scale=st.floats(0.2, 1.0))
def test_path_changes_keep_every_limit(cfg, setup, seed, offset, ramp, scale):
    """A batch stepping with random actions through random path changes: every control-rate setpoint within the
    position, velocity, acceleration and jerk limits (each env checked up to its first episode end)."""
    w = _wrapped(cfg, setup, 12, seed % 1000, fraction=1.0, switch_range=[0.1, 0.8], offsets=[offset],
                 ramps=[ramp], slots=12)
    env = w.env
    gen = torch.Generator().manual_seed(seed)
    alive = torch.ones(12, dtype=torch.bool)
    p, v, a = [env.pos.clone().unsqueeze(1)], [env.vel.clone().unsqueeze(1)], [env.acc.clone().unsqueeze(1)]
    changes = 0
    for _ in range(25):
        p0, v0, a0 = env.pos.clone(), env.vel.clone(), env.acc.clone()
        _, _, dones, extras = w.step(scale * (torch.rand(12, env.num_actions, generator=gen) * 2 - 1))
        changes += int(extras["log"]["PathChange/changes_per_step"])
        qc, vc, ac = interpolate_step(p0, v0, a0, env.acc, env.cfg.dt, env.control_steps)
        keep = (alive & ~dones).view(-1, 1, 1)  # an env reset in this step: its end state is the next episode's
        for out, new in ((p, qc), (v, vc), (a, ac)):  # ended envs hold their last setpoint
            out.append(torch.where(keep, new, out[-1][:, -1:].expand_as(new)))
        alive &= ~dones
    assert changes > 0
    counts = limit_violations(torch.cat(p, 1), torch.cat(v, 1), torch.cat(a, 1), JointLimits.from_robot(env.robot),
                              1.0 / env.cfg.control_rate)
    assert int(counts["total"].sum()) == 0, {k: int(c.sum()) for k, c in counts.items()}


def test_a_restored_snapshot_continues_exactly(cfg, setup):
    """The runner's checkpoint state (pathrl.envs.state.snapshot of the wrapper) holds the branches: a fresh wrapper
    restored from it steps exactly as the original (its branch tables are rebuilt from the stored knots)."""
    from pathrl.envs.state import restore, snapshot, unwrapped

    first = _wrapped(cfg, setup, 8, 3, fraction=1.0, switch_range=[0.2, 0.6], slots=8)
    gen = torch.Generator().manual_seed(1)
    actions = [torch.rand(8, first.num_actions, generator=gen) * 2 - 1 for _ in range(20)]
    for act in actions[:8]:
        first.step(act)
    assert bool(first.changed.any())
    state = snapshot(unwrapped(first))
    second = _wrapped(cfg, setup, 8, 99, fraction=1.0, switch_range=[0.2, 0.6], slots=8)
    restore(unwrapped(second), state)
    for act in actions[8:]:
        o1, r1, d1, _ = first.step(act)
        o2, r2, d2, _ = second.step(act)
        assert torch.equal(o1["policy"], o2["policy"]) and torch.equal(r1, r2) and torch.equal(d1, d2)
