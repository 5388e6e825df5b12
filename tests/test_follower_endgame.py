"""The follower in a real control loop: setpoints at any whole-number rate, the path ends on its last knot at rest
(a jerk-limited final approach inside every limit), the fast path table equals the dataset pipeline's, measured
states are compared (never jumped to), prepared paths."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from pathrl.dataset.io import load_dataset
from pathrl.deploy import Follower, FollowerError
from pathrl.deploy.follower import SETTLE_TOLERANCE
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits
from pathrl.models import model_dir
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.pathset import build_pathset
from pathrl.paths.quick import quick_knots, quick_pathset

ROOT = Path(__file__).resolve().parents[1]
MODEL = model_dir("iiwa7_random")


@pytest.fixture(scope="module")
def follower():
    return Follower.load(MODEL)


@pytest.fixture(scope="module")
def test_knots(follower):
    return load_dataset(ROOT / "datasets" / "iiwa7" / "random", follower.robot).splits["test"].knots


def follow(follower: Follower, rate: float, decisions: int = 400) -> tuple[torch.Tensor, ...]:
    """Setpoints (T, D) at `rate` until done, the start state first."""
    ps, vs, accs = ([torch.as_tensor(x)[None]] for x in follower.state)
    for _ in range(decisions):
        sp = follower.decide(rate_hz=rate)
        assert sp.position.shape == (round(rate * 0.1), follower.robot.dof)
        for lst, x in zip((ps, vs, accs), (sp.position, sp.velocity, sp.acceleration), strict=True):
            lst.append(torch.as_tensor(x))
        if follower.done:
            break
    return torch.cat(ps), torch.cat(vs), torch.cat(accs)


@pytest.mark.parametrize("rate", [100, 500])
@pytest.mark.parametrize("path", [3, 49])  # 49: the policy comes to rest 0.06 rad short and never reaches the end
def test_a_path_ends_at_rest_on_its_last_knot_inside_every_limit(follower, test_knots, rate, path):
    follower.reset(test_knots[path])
    p, v, a = follow(follower, rate)
    assert follower.done
    assert follower.final_error <= SETTLE_TOLERANCE
    assert np.abs(follower.state[0] - test_knots[path][-1]).max() <= SETTLE_TOLERANCE
    assert np.abs(follower.state[1]).max() == 0.0 and np.abs(follower.state[2]).max() == 0.0
    counts = limit_violations(p, v, a, JointLimits.from_robot(follower.robot), 1.0 / rate)
    assert int(counts["total"]) == 0, {k: int(c) for k, c in counts.items()}


def test_rates_and_ticks(follower, test_knots):
    with pytest.raises(FollowerError, match="whole number"):
        follower.decide(rate_hz=333)
    with pytest.raises(FollowerError, match="whole number"):
        Follower.load(MODEL, control_rate=5)
    follower.reset(test_knots[4])
    ticks = list(follower.ticks(rate_hz=100))
    assert follower.done and all(t.position.shape == (1, 7) for t in ticks)
    assert np.allclose(ticks[-1].position[0], test_knots[4][-1], atol=SETTLE_TOLERANCE)


def test_the_same_decisions_at_two_rates_give_the_same_trajectory(test_knots):
    """The env's acceleration is linear within a decision: 500 Hz setpoints are the 100 Hz ones and those between."""
    a, b = Follower.load(MODEL, control_rate=100), Follower.load(MODEL, control_rate=500)
    a.reset(test_knots[5])
    b.reset(test_knots[5])
    for _ in range(30):
        sa, sb = a.decide(), b.decide()
        assert np.allclose(sa.position, sb.position[4::5], atol=1e-12)
        assert np.allclose(sa.acceleration, sb.acceleration[4::5], atol=1e-9)


def test_measured_state_is_compared_never_jumped_to(test_knots):
    f = Follower.load(MODEL, measured_tolerance=0.02)
    f.reset(test_knots[0])
    f.decide()
    q = f.state[0]
    f.decide(q_measured=q + 0.01)
    assert f.measured_error == pytest.approx(0.01)
    before = [x.copy() for x in f.state]
    with pytest.raises(FollowerError, match="measured position is 0.0300 rad"):
        f.decide(q_measured=f.state[0] + 0.03)
    assert all(np.array_equal(x, y) for x, y in zip(before, f.state, strict=True))  # refused: nothing advanced
    w = Follower.load(MODEL, measured_tolerance=0.02, on_measured="warn")
    w.reset(test_knots[0])
    w.decide()
    with pytest.warns(RuntimeWarning, match="goes on"):
        sp = w.decide(q_measured=w.state[0] + 0.5)
    assert np.abs(sp.position[0] - (w.state[0] + 0.5)).max() > 0.4  # the commanded trajectory did not jump
    with pytest.raises(FollowerError, match="on_measured"):
        Follower.load(MODEL, on_measured="ignore")


def test_a_prepared_path_replaces_like_its_knots(follower, test_knots):
    follower.reset(test_knots[6])
    for _ in range(10):
        follower.decide()
    new = np.vstack([follower.state[0], test_knots[7]])
    prepared = follower.prepare(new)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gap = follower.replace_path(prepared)
    assert gap < 1e-9
    assert torch.equal(follower.env.paths.table, follower.prepare(new).paths.table)
    other = Follower.load(model_dir("armar6_random"))
    with pytest.raises(FollowerError, match="another robot"):
        other.reset(prepared)


@pytest.mark.parametrize("strategy", [KnotStrategy("curvature", 0.3, 0.1, 9), KnotStrategy("distance", 0.3, 0.1, 5)])
def test_the_fast_table_is_the_dataset_pipelines(test_knots, strategy):
    for k in test_knots[:5]:
        ref = build_pathset([strategy.apply(k)], ["p"])
        new = quick_pathset(quick_knots(strategy, k))
        for x, y in ((ref.knots, new.knots), (ref.knot_s, new.knot_s), (ref.table, new.table),
                     (ref.length, new.length)):
            assert x.shape == y.shape
            assert float((x - y).abs().max()) < 1e-9
    line = np.linspace(np.zeros(7), np.ones(7), 2)
    assert torch.equal(build_pathset([line], ["p"]).table, quick_pathset(line).table)
