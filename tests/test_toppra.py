"""TOPP-RA baseline: analytic straight line, limit compliance on curved paths, plan determinism, CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pathrl.baselines.toppra import MARGIN, PathLimits, ToppraSettings, solve_plan, solve_segment
from pathrl.paths.pathset import build_pathset
from pathrl.paths.segments import evaluation_plan
from pathrl.paths.spline import arc_length_table, fit_spline, knot_arc_lengths
from pathrl.robot.external import load_robot_by_name

VEL = np.array([1.0, 2.0, 1.5])
ACC = np.array([4.0, 3.0, 10.0])
LIMITS = PathLimits(VEL, ACC)


def line_time(length: float, v: float, a: float) -> float:
    """Minimum rest-to-rest time along a line with path speed <= v and path acceleration <= a."""
    if length >= v * v / a:  # trapezoid
        return length / v + v / a
    return 2.0 * math.sqrt(length / a)  # triangle


def line_knots(a: np.ndarray, b: np.ndarray, n: int = 6) -> np.ndarray:
    u = np.r_[0.0, np.sort(np.random.default_rng(0).uniform(0.05, 0.95, n - 2)), 1.0]  # uneven spacing
    return a + (b - a) * u[:, None]


@pytest.mark.parametrize("scale", [0.2, 3.0])  # triangular and trapezoidal profiles
def test_straight_line_matches_analytic_minimum_time(scale):
    a, b = np.zeros(3), scale * np.array([1.0, -0.5, 0.8])
    knots = line_knots(a, b)
    length = float(np.linalg.norm(b - a))
    d = np.abs(b - a) / length
    v, acc = float(np.min(VEL / d)), float(np.min(ACC / d))  # the binding joint's limits along the line
    expect = line_time(length, v, acc)
    res = solve_segment(knots, 0.0, length, LIMITS)
    assert res.status == "ok"
    assert res.duration_s == pytest.approx(expect, rel=1e-2)
    assert res.duration_s >= expect * (1 - 1e-6)  # never faster than the optimum
    # only the small safety margin is lost
    assert res.duration_s <= expect * (1 + 2 * MARGIN)
    # a sub-segment of the line
    res2 = solve_segment(knots, 0.25 * length, 0.75 * length, LIMITS)
    assert res2.duration_s == pytest.approx(line_time(0.5 * length, v, acc), rel=1e-2)
    np.testing.assert_allclose(res2.q[0], a + 0.25 * (b - a), atol=1e-6)
    np.testing.assert_allclose(res2.q[-1], a + 0.75 * (b - a), atol=1e-6)


def curved_knots(n: int = 40) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n)
    return np.c_[np.sin(t), 0.6 * np.sin(2 * t + 0.3), 0.4 * np.cos(3 * t)] * 1.2


def test_curved_path_respects_limits():
    knots = curved_knots()
    _, length = knot_arc_lengths(knots)
    pos = np.array([[-2.0, 2.0]] * 3)
    limits = PathLimits(VEL, ACC, pos, jerk=20 * ACC)
    res = solve_segment(knots, 0.1 * length, 0.9 * length, limits, ToppraSettings(control_rate=240.0))
    assert res.status == "ok", res.summary()
    assert res.violations == {"position": 0, "velocity": 0, "acceleration": 0}
    assert res.max_vel_ratio <= 1.0 + 1e-9 and res.max_acc_ratio <= 1.0 + 1e-9
    assert res.max_vel_ratio > 0.95 or res.max_acc_ratio > 0.95  # time optimal: some limit is reached
    assert res.max_joint_dev_rad < 1e-9
    # samples at the control rate, rest to rest, on the path at both ends
    n = res.q.shape[0]
    assert n == math.ceil(res.duration_s * 240.0 - 1e-9) + 1
    np.testing.assert_allclose(res.qd[[0, -1]], 0.0, atol=1e-9)
    spline = fit_spline(knots)
    u, s = arc_length_table(spline, knots)
    np.testing.assert_allclose(res.q[0], spline(np.interp(0.1 * length, s, u)), atol=1e-9)
    np.testing.assert_allclose(res.q[-1], spline(np.interp(0.9 * length, s, u)), atol=1e-9)
    # every sample lies on the geometric path (distance to a dense sampling of the spline)
    dense = spline(np.linspace(0, 1, 20001))
    dist = np.min(np.linalg.norm(res.q[::15, None, :] - dense[None], axis=2), axis=1)
    assert dist.max() < 2e-3
    # consistent finite differences (the samples are one trajectory)
    fd = np.diff(res.q, axis=0) * 240.0
    np.testing.assert_allclose(fd, 0.5 * (res.qd[1:] + res.qd[:-1]), atol=0.02)
    # TOPP-RA has no jerk limit: the jerk is reported, and exceeding it is not a violation
    assert np.isfinite(res.max_jerk) and res.max_jerk_ratio > 1 and res.jerk_violations > 0


def test_duration_close_to_default_toppra():
    """The limit-honouring trajectory is at most marginally slower than toppra's default output."""
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    knots = curved_knots()
    _, length = knot_arc_lengths(knots)
    res = solve_segment(knots, 0.0, length, LIMITS)
    spline = fit_spline(knots)
    from pathrl.baselines.toppra import SegmentPath, as_toppra_path

    inst = algo.TOPPRA(
        [constraint.JointVelocityConstraint(VEL), constraint.JointAccelerationConstraint(ACC)],
        as_toppra_path(SegmentPath(spline, 0.0, 1.0)),
        solver_wrapper="seidel",
    )
    default = inst.compute_trajectory(0, 0).duration
    assert res.duration_s == pytest.approx(default, rel=0.01)


def test_empty_segment():
    res = solve_segment(curved_knots(), 1.0, 1.0, LIMITS)
    assert res.status == "empty" and res.duration_s == 0.0


def synthetic_paths(m: int = 7, p: int = 3):
    rng = np.random.default_rng(1)
    out = []
    for i in range(p):
        t = np.linspace(0, 1, 12 + 3 * i)[:, None]
        out.append(0.4 * np.sin(2 * np.pi * (t * rng.uniform(0.3, 1.0, m) + rng.uniform(0, 1, m))))
    return build_pathset(out, [f"path_{i:03d}" for i in range(p)])


@pytest.fixture(scope="module")
def iiwa():
    return load_robot_by_name("iiwa7")


@pytest.mark.parametrize("protocol,episodes", [("full", 3), ("paper", 5)])
def test_solve_plan_deterministic(iiwa, protocol, episodes):
    paths = synthetic_paths()
    plan = evaluation_plan(paths, episodes, protocol, seed=3)
    a = solve_plan(paths, plan, iiwa, workers=1, progress=False)
    b = solve_plan(paths, plan, iiwa, workers=1, progress=False, chunk_size=1)
    assert len(a) == episodes
    assert [r.duration_s for r in a] == [r.duration_s for r in b]
    assert all(r.status == "ok" and r.num_violations == 0 for r in a)
    # each episode equals solving its segment alone
    i = episodes - 1
    p = int(plan.path[i])
    k = paths.knots[p, : int(paths.num_knots[p])].numpy()
    limits = PathLimits(iiwa.vel_limits, iiwa.acc_limits, iiwa.pos_limits)
    one = solve_segment(k, float(plan.start_s[i]), float(plan.end_s[i]), limits)
    assert one.duration_s == a[i].duration_s


def test_solve_plan_two_workers_same_order(iiwa):
    paths = synthetic_paths()
    plan = evaluation_plan(paths, 6, "paper", seed=0)
    drop = ToppraSettings(keep_trajectory=False)
    a = solve_plan(paths, plan, iiwa, drop, workers=1, progress=False)
    b = solve_plan(paths, plan, iiwa, drop, workers=2, progress=False, chunk_size=1)
    assert [r.duration_s for r in a] == [r.duration_s for r in b]
    assert a[0].q.shape == (0, 7)


# ------------------------------------------------------------------------------------------------ CLI


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory, iiwa):
    from pathrl.dataset.io import save_dataset

    paths = synthetic_paths(p=3)
    items = [(n, paths.knots[i, : int(paths.num_knots[i])].numpy()) for i, n in enumerate(paths.names)]
    dest = tmp_path_factory.mktemp("ds") / "tiny"
    meta = {"robot": "iiwa7", "kind": "random", "path_joints": list(iiwa.path_joints), "seed": 0}
    save_dataset(dest, {"train": items[:1], "test": items}, meta)
    return dest


def test_cli_smoke(tiny_dataset, tmp_path, capsys):
    from pathrl.cli.toppra import main

    out = tmp_path / "r.json"
    rc = main(
        [
            "robot=iiwa7",
            f"dataset.path={tiny_dataset}",
            "segments=paper",
            "episodes=4",
            "seed=1",
            "knots=distance_9",
            f"out={out}",
        ]
    )
    assert rc == 0, capsys.readouterr().err
    rep = json.loads(out.read_text())
    for key in (
        "robot",
        "dataset",
        "split",
        "segments",
        "seed",
        "episodes",
        "toppra_duration_s",
        "toppra_max_joint_dev_rad",
        "solve_time_s",
        "limit_violations",
        "max_jerk",
        "per_path",
    ):
        assert key in rep
    assert rep["episodes"] == 4 and len(rep["per_path"]) == 4 and rep["limit_violations"] == 0
    assert [e["name"] for e in rep["per_path"]] == ["path_000", "path_001", "path_002", "path_000"]
    assert rep["toppra_duration_s"] == pytest.approx(np.mean([e["duration_s"] for e in rep["per_path"]]))
    # default output location and full protocol: one episode per path
    assert main(["robot=iiwa7", f"dataset.path={tiny_dataset}", "segments=full"]) == 0
    rep = json.loads((tiny_dataset / "toppra_test_full.json").read_text())
    assert rep["episodes"] == 3 and all(e["start_s"] == 0.0 for e in rep["per_path"])


@pytest.mark.parametrize(
    "args",
    [
        ["dataset.path={missing}"],
        ["dataset.path={ds}", "split=nope"],
        ["dataset.path={ds}", "episodes=0"],
        ["dataset.path={ds}", "segments=bogus"],
        ["dataset.path={ds}", "workers=0"],
    ],
)
def test_cli_bad_input(tiny_dataset, tmp_path, capsys, args):
    from pathrl.cli.toppra import main

    out = tmp_path / "r.json"
    argv = ["robot=iiwa7", f"out={out}"] + [
        a.format(missing=tmp_path / "nope", ds=tiny_dataset) for a in args
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "\n" not in err
    assert not out.exists()


def test_ruckig_tracked_straight_line_against_its_analytic_time():
    """A straight 3 rad line of one joint (limits 1 rad/s, 2 rad/s^2, 20 rad/s^3): TOPP-RA takes D/v + v/a = 3.5 s;
    no jerk-limited motion is faster than D/v + v/a + a/j = 3.6 s; the Ruckig-tracked plan keeps every limit, jerk
    included, stays on the line (to the plan's 240 Hz sample spacing) and takes at most 0.1 s more (measured:
    3.64 s)."""
    from pathrl.baselines.ruckig_track import ruckig_tracked

    v, a, j, d = 1.0, 2.0, 20.0, 3.0
    lim = PathLimits(np.array([v, v]), np.array([a, a]), np.array([[-10.0, 10.0], [-10.0, 10.0]]), np.array([j, j]))
    knots = np.array([[0.0, 0.0], [d, 0.0]])
    res = solve_segment(knots, 0.0, d, lim, ToppraSettings(control_rate=240.0))
    assert res.duration_s == pytest.approx(d / v + v / a, abs=0.01)
    tr = ruckig_tracked(res, lim, 240.0)
    assert d / v + v / a + a / j - 1e-9 <= tr["duration_s"] <= d / v + v / a + a / j + 0.1
    assert sum(tr["violations"].values()) == 0
    assert tr["max_dev_rad"] < v / 240.0
