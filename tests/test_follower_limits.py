"""The limit guarantee at every door: paths outside the position range are refused or clipped (the whole spline, not
only the knots), the follower's reset and path change are atomic, and every setpoint of an accepted path is inside
every limit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pathrl.dataset.io import DatasetError, load_pathset, save_dataset
from pathrl.deploy import Follower, FollowerError
from pathrl.envs.rewards import build_reward_terms
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits
from pathrl.limits.integrate import interpolate_step
from pathrl.models import model_dir
from pathrl.paths.inside import PathOutsideError, clip_spline_into, keep_inside, spline_excess, table_excess
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.pathset import build_pathset
from pathrl.paths.quick import quick_knots
from pathrl.paths.segments import full_segments, sample_segments

ROOT = Path(__file__).resolve().parents[1]
MODEL = model_dir("iiwa7_random")


@pytest.fixture(scope="module")
def refuse():
    return Follower.load(MODEL)


@pytest.fixture(scope="module")
def clip():
    return Follower.load(MODEL, out_of_limits="clip")


def _limits(follower: Follower) -> tuple[np.ndarray, np.ndarray]:
    lim = follower.robot.pos_limits[follower.robot.path_index]
    return lim[:, 0], lim[:, 1]


def _follow(follower: Follower, decisions: int = 400) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Setpoints (T, D) until the follower is done, the start state first."""
    q, v, a = (torch.as_tensor(x).unsqueeze(0) for x in follower.state)
    ps, vs, accs = [q], [v], [a]
    for _ in range(decisions):
        _decide_into(follower, ps, vs, accs)
        if follower.done:
            break
    return torch.cat(ps), torch.cat(vs), torch.cat(accs)


def _decide_into(follower: Follower, ps: list, vs: list, accs: list) -> None:
    """One decision; its setpoints appended to the position, velocity and acceleration lists."""
    sp = follower.decide()
    ps.append(torch.as_tensor(sp.position))
    vs.append(torch.as_tensor(sp.velocity))
    accs.append(torch.as_tensor(sp.acceleration))


def _violations(follower: Follower, p, v, a) -> dict[str, int]:
    counts = limit_violations(p, v, a, JointLimits.from_robot(follower.robot), 1.0 / follower.env_cfg.control_rate)
    return {k: int(c) for k, c in counts.items()}


# ---------------------------------------------------------------------------------------------- the spline


def test_a_spline_through_inside_knots_can_leave_the_range_and_clipping_brings_it_back():
    """Two knots at y = 1 with a turn between them: the natural spline bulges above y = 1 (hand-checkable: its
    samples between the knots exceed 1); clipping moves the two knots down until no sample does, and leaves the
    first and last knots, far from the bulge, where they were."""
    knots = np.array([[0.0, 0.0], [1.0, 1.0], [1.3, 1.0], [2.3, 0.0], [3.3, 0.0]])
    lo, hi = np.array([-5.0, -1.0]), np.array([5.0, 1.0])
    below, above = spline_excess(knots, lo, hi, 0.01)
    assert below.max() == 0.0 and above[1] > 0.01 and above[0] == 0.0
    inside = clip_spline_into(knots, lo, hi, 0.01)
    below, above = spline_excess(inside, lo, hi, 0.01)
    assert below.max() == 0.0 and above.max() == 0.0
    assert np.array_equal(inside[0], knots[0]) and np.array_equal(inside[-1], knots[-1])
    assert (inside[1:3, 1] < 1.0).all() and (inside[1:3, 1] > 0.8).all()  # moved down, not flattened


def test_table_excess_ignores_the_padding_past_the_path_end():
    """A path that ends exactly at the limit: the table's padding row extrapolates past the end knot, which no
    position lookup reaches; only real samples count."""
    paths = build_pathset([np.array([[0.0, 0.0], [0.4, 0.3], [1.0, 1.0]])], ["p"], table_step=0.07)
    box = lambda *x: torch.tensor(x, dtype=torch.float64)  # noqa: E731
    ex = table_excess(paths, box(-1.0, -1.0), box(1.0, 1.0))
    assert float(ex[0]) <= 1e-12
    ex = table_excess(paths, box(-1.0, -1.0), box(0.9, 1.0))
    assert float(ex[0]) == pytest.approx(0.1, abs=1e-9)  # the end knot at x = 1.0


def test_keep_inside_refuses_or_clips_only_the_offending_paths():
    lo, hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    ok = np.array([[0.0, 0.0], [0.5, 0.2], [0.2, 0.6]])
    out = np.array([[0.0, 0.0], [1.003, 0.5], [0.5, 0.9]])  # 3 mrad outside at a knot
    knots = [ok, out]
    paths = build_pathset(knots, ["ok", "out"])
    with pytest.raises(PathOutsideError, match=r"1 of 2 paths leave the position range \(by up to"):
        keep_inside(paths, knots, lo, hi, clip=False)
    clipped = keep_inside(paths, knots, lo, hi, clip=True)
    assert torch.equal(clipped.knots[0, :3], paths.knots[0, :3])  # the inside path as it was
    assert float(table_excess(clipped, torch.as_tensor(lo), torch.as_tensor(hi)).max()) == 0.0


# ---------------------------------------------------------------------------------------------- the follower


def test_a_path_starting_outside_the_range_is_refused_and_changes_nothing(refuse):
    lo, hi = _limits(refuse)
    inside = np.linspace(0.5 * lo, 0.5 * hi, 4)
    refuse.reset(inside)
    refuse.decide()
    before = [x.copy() for x in refuse.state]
    outside = inside.copy()
    outside[0, 0] = hi[0] + 0.5  # the first knot 0.5 rad past joint 1's upper limit
    with pytest.raises(FollowerError, match="position range by up to 500 mrad"):
        refuse.reset(outside)
    with pytest.raises(FollowerError, match="position range"):
        refuse.replace_path(outside)
    assert all(np.array_equal(a, b) for a, b in zip(before, refuse.state, strict=True))
    assert torch.equal(refuse.env.paths.knots[0, 0], torch.as_tensor(quick_knots(refuse.knots, inside)[0]))


def test_a_path_starting_outside_the_range_is_clipped_and_followed_inside_every_limit(clip):
    lo, hi = _limits(clip)
    knots = np.linspace(0.5 * lo, 0.5 * hi, 4)
    knots[0, 0] = hi[0] + 0.5
    knots[1, 1] = lo[1] - 0.2
    clip.reset(knots)
    p, v, a = _follow(clip)
    assert clip.done
    assert _violations(clip, p, v, a)["total"] == 0


def _model_copy(dest: Path, summary: str | None) -> Path:
    """models/tracking/iiwa7_random at `dest`, its summary.json replaced by the text `summary` (None: removed)."""
    dest.mkdir()
    for name in ("config.yaml", "model.pt"):
        (dest / name).write_bytes((MODEL / name).read_bytes())
    if summary is not None:
        (dest / "summary.json").write_text(summary)
    return dest


def test_measured_state_and_bad_inputs_are_follower_errors_and_change_nothing(refuse, tmp_path):
    """Every bad input is a one-line FollowerError (before: TypeError, ValueError or OverflowError for some, and a
    NaN length scale loaded), and a refused call changes neither the path nor the commanded state."""
    lo, hi = _limits(refuse)
    good = np.linspace(0.3 * lo, 0.3 * hi, 3)
    refuse.reset(good)
    refuse.decide()
    paths, state = refuse.env.paths, [x.copy() for x in refuse.state]
    q = good[0].copy()
    q[2] = np.nan
    zigzag = np.where(np.arange(400)[:, None] % 2, 0.3 * lo, 0.3 * hi)  # inside the range, > 1000 rad long
    cases = [
        (lambda: refuse.reset(good, q=q), "q must be finite"),
        (lambda: refuse.reset(good, q=good[0][:3]), r"q must have shape \(7,\)"),
        (lambda: refuse.reset(good, q="abc"), "q must"),
        (lambda: refuse.decide(q_measured=np.r_[state[0][:6], np.nan]), "q must be finite"),
        (lambda: refuse.decide(q_measured=state[0][:6]), r"q must have shape \(7,\)"),
        (lambda: refuse.decide(rate_hz="fast"), "control rate must be a number"),
        (lambda: refuse.reset([["a", "b"]]), "array of numbers"),
        (lambda: refuse.reset(good.astype(complex)), "array of numbers"),
        (lambda: refuse.reset(np.zeros((2, 7))), "path knots"),  # a path of length 0
        (lambda: refuse.reset(good * 1e300), "beyond 100 rad"),  # was an OverflowError
        (lambda: refuse.reset(good * 400), "beyond 100 rad"),  # degrees or mm: seconds of tabulation before
        (lambda: refuse.replace_path(zigzag), "at most 1000 rad"),
        (lambda: refuse.replace_path(np.full((3, 7), np.inf)), "finite"),
        (lambda: Follower.load(MODEL, out_of_limits="ignore"), "out_of_limits must be one of"),
        (lambda: Follower.load(MODEL, measured_tolerance="abc"), "measured_tolerance must be a number > 0"),
        (lambda: Follower.load(MODEL, control_rate="abc"), "control rate must be a number"),
        (lambda: Follower.load(None), "model_dir must be a path"),
        (lambda: Follower.load(_model_copy(tmp_path / "nosum", None)), "summary.json is missing"),
        (lambda: Follower.load(_model_copy(tmp_path / "nangap", '{"knot_gap_norm": NaN}')), "must be a number > 0"),
    ]
    for call, message in cases:
        with pytest.raises(FollowerError, match=message):
            call()
        assert refuse.env.paths is paths
        assert all(np.array_equal(a, b) for a, b in zip(state, refuse.state, strict=True))


def test_a_non_finite_action_is_refused_before_it_moves_the_robot(monkeypatch):
    follower = Follower.load(MODEL)
    lo, hi = _limits(follower)
    follower.reset(np.linspace(0.3 * lo, 0.3 * hi, 3))
    follower.decide()
    state = [x.copy() for x in follower.state]
    real = follower.policy
    monkeypatch.setattr(follower, "policy", lambda obs: real(obs) * float("nan"))
    with pytest.raises(FollowerError, match="non-finite action"):
        follower.decide()
    assert all(np.array_equal(a, b) for a, b in zip(state, follower.state, strict=True))
    follower.stop()  # braking does not use the policy's action
    for _ in range(40):
        assert np.isfinite(follower.decide().position).all()
    assert follower.done


@pytest.mark.parametrize("action", ["stop", "replace_path"])
def test_a_stop_or_path_change_during_the_final_approach_stays_inside_every_limit(action):
    """A path ending on a joint's upper limit: the final approach (Ruckig, time-optimal) nears the limit faster than
    the env's laws could stop from. A stop or path change in its first decisions handed the robot to them and left
    the range (the follower fuzz found it); now a stop lets the approach end (at rest on the last knot) and a path
    change during it is refused without a change (once done, at rest on the last knot, it is taken again)."""
    follower = Follower.load(MODEL)
    lo, hi = _limits(follower)
    mid, refused = 0.5 * (lo + hi), 0
    for joint, run_up, wait in [(2, 0.3, 2), (2, 0.6, 0), (3, 0.3, 0), (5, 0.3, 0), (5, 0.6, 0), (6, 0.6, 0)]:
        knots = np.array([mid, mid])
        knots[:, joint] = hi[joint] - run_up, hi[joint]
        follower.reset(knots)
        q, v, a = (torch.as_tensor(x).unsqueeze(0) for x in follower.state)
        ps, vs, accs, at = [q], [v], [a], None
        for t in range(300):
            at = t if at is None and follower.final_approach_s > 0 else at
            if at is not None and t == at + wait:
                if action == "stop":
                    follower.stop()
                else:
                    before = [x.copy() for x in follower.state]
                    try:
                        follower.replace_path(np.vstack([follower.state[0], mid + 0.1]))
                    except FollowerError as exc:
                        assert "final approach" in str(exc)
                        assert all(np.array_equal(x, y) for x, y in zip(before, follower.state, strict=True))
                        refused += 1
            _decide_into(follower, ps, vs, accs)
            if follower.done:
                break
        assert follower.done and at is not None
        counts = _violations(follower, torch.cat(ps), torch.cat(vs), torch.cat(accs))
        assert counts["total"] == 0, (joint, run_up, counts)
        assert follower.replace_path(np.vstack([follower.state[0], mid])) < 1e-9  # at rest at the end: taken again
    assert action == "stop" or refused > 0


def _adversarial_paths(lo: np.ndarray, hi: np.ndarray):
    """Paths of 2-6 knots anywhere in the range widened by a quarter on each side, some starting outside, some
    hugging a limit (the spline overshoots between knots placed on it)."""
    width = hi - lo
    knot = st.lists(st.floats(-0.25, 1.25), min_size=len(lo), max_size=len(lo)).map(lambda f: lo + np.array(f) * width)
    hug = st.integers(0, len(lo) - 1)
    return st.tuples(st.lists(knot, min_size=2, max_size=6), st.one_of(st.none(), hug))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_every_setpoint_of_an_accepted_path_is_inside_every_limit(refuse, clip, data):
    """Property: for any path the follower accepts (refused ones raise a FollowerError), every 240 Hz setpoint of
    its whole run is inside the position, velocity, acceleration and jerk limits; with clipping every path is
    accepted."""
    lo, hi = _limits(clip)
    knots, hug = data.draw(_adversarial_paths(lo, hi))
    knots = np.array(knots)
    if hug is not None:
        knots[1:-1, hug] = hi[hug]  # every inner knot on the upper limit of one joint
    if float(np.linalg.norm(np.diff(knots, axis=0), axis=1).sum()) < 1e-3:
        return
    for follower in (refuse, clip):
        try:
            follower.reset(knots)
        except FollowerError as exc:
            msg = str(exc)  # clipping can leave one point (every knot outside on the same side): refused too
            assert (follower is refuse and "position range" in msg) or "fewer than two distinct" in msg, msg
            continue
        p, v, a = _follow(follower, decisions=150)
        assert _violations(follower, p, v, a)["total"] == 0


# ---------------------------------------------------------------------------------------------- datasets and envs


def _third_party_like(tmp_path: Path, robot) -> Path:
    """A dataset whose knots leave the position range by up to 3.6 mrad, several of them on a limit (so that the
    spline between clipped knots overshoots), like an imported third-party path set."""
    rng = np.random.default_rng(0)
    lo, hi = robot.pos_limits[robot.path_index].T
    paths = []
    for i in range(12):
        k = lo + rng.uniform(0.1, 0.9, size=(6, len(lo))) * (hi - lo)
        j = i % len(lo)
        k[2:4, j] = hi[j] + rng.uniform(0.0, 3.6e-3, size=2)
        k[0, (j + 1) % len(lo)] = lo[(j + 1) % len(lo)] - 1e-3 * (i % 3)  # some starts outside too
        paths.append((f"p{i}", k))
    dest = tmp_path / "third_party"
    meta = {"robot": robot.name, "kind": "synthetic", "path_joints": list(robot.path_joints), "seed": 0}
    save_dataset(dest, {"test": paths}, meta)
    return dest


def test_a_clipped_path_set_starts_and_stays_inside_every_limit(refuse, tmp_path):
    """Clipping keeps the whole spline inside (not only the knots): every paper-protocol episode starts inside the
    range, and random actions through the valid range keep every setpoint inside every limit."""
    robot = refuse.robot
    src = _third_party_like(tmp_path, robot)
    strategy = KnotStrategy.from_cfg(refuse.cfg["knots"])
    with pytest.raises(DatasetError, match="out_of_limits=clip"):
        load_pathset(src, "test", strategy, robot=robot)
    paths = load_pathset(src, "test", strategy, robot=robot, out_of_limits="clip")
    lo, hi = (torch.as_tensor(x) for x in robot.pos_limits[robot.path_index].T)
    assert float(table_excess(paths, lo, hi).max()) == 0.0
    n = 256
    cfg = TrackingEnvCfg(num_envs=n, seed=0, max_deviation=None, episode_budget_s=1e9, autoreset=False)
    env = PathTrackingEnv(cfg, robot, paths, build_reward_terms({"path_length": {"weight": 1.0}}))
    gen = torch.Generator().manual_seed(1)
    env.start_segments(torch.arange(n), sample_segments(paths, torch.arange(n) % paths.num_paths, gen))
    assert bool(((env.pos >= lo) & (env.pos <= hi)).all())  # every episode starts inside
    _random_steps_inside(env, robot, gen, 40)


def _random_steps_inside(env: PathTrackingEnv, robot, gen: torch.Generator, steps: int) -> None:
    """`steps` env steps of random actions; every 240 Hz setpoint of every env inside every limit."""
    n, cfg, parts = env.num_envs, env.cfg, []
    for _ in range(steps):
        p0, v0, a0 = env.pos.clone(), env.vel.clone(), env.acc.clone()
        env.step(torch.rand(n, robot.dof, generator=gen, dtype=torch.float64) * 2 - 1)
        parts.append(interpolate_step(p0, v0, a0, env.acc, cfg.dt, env.control_steps))
    p, v, a = (torch.cat(x, dim=1) for x in zip(*parts, strict=True))
    counts = limit_violations(p, v, a, JointLimits.from_robot(robot), 1.0 / cfg.control_rate)
    assert int(counts["total"].sum()) == 0, {k: int(c.sum()) for k, c in counts.items()}


def _third_party_like_paths(lo: np.ndarray, hi: np.ndarray):
    """Paths of 3-6 knots inside the range with some knot entries up to 4 mrad past a limit (on either side), as in a
    released third-party path set."""
    m = len(lo)
    knot = st.lists(st.floats(0.0, 1.0), min_size=m, max_size=m).map(lambda f: lo + np.array(f) * (hi - lo))
    past = st.tuples(st.integers(0, 5), st.integers(0, m - 1), st.floats(-4e-3, 4e-3))  # (knot, joint, excess)
    return st.tuples(st.lists(knot, min_size=3, max_size=6), st.lists(past, max_size=4))


def _env_setpoints_inside(robot, paths, gen: torch.Generator, steps: int = 25) -> None:
    """An env on `paths`: half the episodes on random segments (training), half on whole paths (evaluation); every
    episode starts inside the position range, and every 240 Hz setpoint of random actions is inside every limit."""
    n = 2 * paths.num_paths
    cfg = TrackingEnvCfg(num_envs=n, seed=0, max_deviation=None, episode_budget_s=1e9, autoreset=False)
    env = PathTrackingEnv(cfg, robot, paths, build_reward_terms({"path_length": {"weight": 1.0}}))
    ids = torch.arange(n) % paths.num_paths
    half = n // 2
    env.start_segments(torch.arange(half), sample_segments(paths, ids[:half], gen))
    env.start_segments(torch.arange(half, n), full_segments(paths, ids[half:]))
    lo, hi = (torch.as_tensor(x) for x in robot.pos_limits.T)
    assert bool(((env.pos >= lo - 1e-9) & (env.pos <= hi + 1e-9)).all())
    _random_steps_inside(env, robot, gen, steps)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_every_setpoint_of_a_path_bank_an_env_accepts_is_inside_every_limit(refuse, data):
    """Property: for any path bank an env accepts (one that leaves the position range is a ValueError), and for any
    bank clipped into the range as ``dataset.out_of_limits=clip`` does (the whole spline), every episode starts inside
    and every 240 Hz setpoint is inside every limit. Banks: adversarial paths (starting outside, hugging a limit) and
    third-party-like ones (knots up to 4 mrad outside)."""
    robot = refuse.robot
    lo, hi = _limits(refuse)
    knots_list = []
    for _ in range(3):
        if data.draw(st.booleans()):
            knots, hug = data.draw(_adversarial_paths(lo, hi))
            knots = np.array(knots)
            if hug is not None:
                knots[1:-1, hug] = hi[hug]
        else:
            knots, past = data.draw(_third_party_like_paths(lo, hi))
            knots = np.array(knots)
            for i, j, ex in past:
                knots[i % len(knots), j] = (hi[j] + ex) if ex > 0 else (lo[j] + ex)
        if float(np.linalg.norm(np.diff(knots, axis=0), axis=1).min()) < 1e-3:
            return  # a repeated knot: the pipeline deduplicates it; not what this property is about
        knots_list.append(knots)
    names = [f"p{i}" for i in range(len(knots_list))]
    paths = build_pathset(knots_list, names)
    gen = torch.Generator().manual_seed(data.draw(st.integers(0, 2**31 - 1)))
    try:
        _env_setpoints_inside(robot, paths, gen)
    except ValueError as exc:
        assert "position range" in str(exc), exc
    try:
        clipped = keep_inside(paths, knots_list, lo, hi, clip=True, tol=0.0)
    except ValueError as exc:  # every knot of a path clipped onto one point
        assert "distinct" in str(exc) or "cannot be clipped" in str(exc), exc
        return
    _env_setpoints_inside(robot, clipped, gen)


def test_an_env_refuses_a_path_bank_that_leaves_the_range(refuse):
    lo, hi = _limits(refuse)
    knots = np.linspace(0.5 * lo, 0.5 * hi, 4)
    knots[2, 3] = hi[3] + 0.01
    paths = build_pathset([knots], ["out"])
    with pytest.raises(ValueError, match=r"1 of 1 paths leave robot iiwa7's position range \(by up to"):
        PathTrackingEnv(refuse.env_cfg, refuse.robot, paths, build_reward_terms(refuse.cfg["reward"]["terms"]))


def test_the_follower_fuzz_finds_nothing_and_sees_a_follower_without_the_check(monkeypatch):
    """The bench's follower fuzz on a few trials: 0 violations, 0 crashes, every bad state refused. With the
    range check switched off (follower and env), the same trials start outside the range and the fuzz counts it."""
    from pathrl.deploy.fuzz import fuzz_follower

    res = fuzz_follower(MODEL, 8, seed=3, decisions=60)
    assert res.crashes == 0 and res.violations == 0 and res.bad_states_refused == res.trials == 8
    assert res.refused > 0 and res.setpoints_checked > 0
    no_check = lambda paths, lo, hi, chunk=256: torch.zeros(paths.num_paths, dtype=torch.float64)  # noqa: E731
    monkeypatch.setattr("pathrl.paths.inside.table_excess", no_check)
    monkeypatch.setattr("pathrl.envs.tracking.table_excess", no_check)
    broken = fuzz_follower(MODEL, 8, seed=3, decisions=60)
    assert broken.violations > 0
