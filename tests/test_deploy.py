"""The deployable follower (pathrl.deploy): same step as the env, path changes and stops within every limit."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pathrl.dataset.io import load_dataset
from pathrl.deploy import Follower, FollowerError
from pathrl.envs.rewards import build_reward_terms
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits
from pathrl.models import model_dir
from pathrl.paths.quick import quick_knots, quick_pathsets
from pathrl.paths.segments import full_segments

ROOT = Path(__file__).resolve().parents[1]
MODEL = model_dir("iiwa7_random")
DATASET = ROOT / "datasets" / "iiwa7" / "random"


@pytest.fixture(scope="module")
def follower():
    return Follower.load(MODEL)


@pytest.fixture(scope="module")
def test_knots(follower):
    return load_dataset(DATASET, follower.robot).splits["test"].knots


def run(follower: Follower, decisions: int) -> tuple[torch.Tensor, ...]:
    """Setpoints (T, D) of `decisions` decisions, with the start state first."""
    q, v, a = (torch.as_tensor(x).unsqueeze(0) for x in follower.state)
    ps, vs, accs = [q], [v], [a]
    for _ in range(decisions):
        sp = follower.decide()
        ps.append(torch.as_tensor(sp.position))
        vs.append(torch.as_tensor(sp.velocity))
        accs.append(torch.as_tensor(sp.acceleration))
    return torch.cat(ps), torch.cat(vs), torch.cat(accs)


def test_follower_steps_exactly_like_the_batched_env(follower, test_knots):
    """The same actions give bit-identical states in the follower and in row 1 of a 3-env batch; the policy's own
    decisions agree to float32 rounding."""
    follower.reset(test_knots[1])
    paths = quick_pathsets([quick_knots(follower.knots, k) for k in test_knots[:3]], ["a", "b", "c"])
    env = PathTrackingEnv(replace(follower.env_cfg, num_envs=3), follower.robot, paths,
                          build_reward_terms(follower.cfg["reward"]["terms"]))
    env.start_segments(torch.arange(3), full_segments(paths, torch.arange(3)))
    gen = torch.Generator().manual_seed(0)
    for _ in range(40):
        with torch.inference_mode():
            own = follower.policy(follower.env.get_observations())
            batch = follower.policy(env.get_observations())
        assert torch.allclose(own[0], batch[1], atol=1e-5)
        actions = torch.rand(3, follower.robot.dof, generator=gen) * 2 - 1
        actions[1] = own[0]
        follower.env.step(own)
        env.step(actions)
        assert torch.equal(follower.env.pos[0], env.pos[1])
        assert torch.equal(follower.env.vel[0], env.vel[1])
        assert torch.equal(follower.env.s[0], env.s[1])


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(first=st.integers(0, 199), second=st.integers(0, 199), switch=st.integers(1, 60),
       stop_after=st.one_of(st.none(), st.integers(1, 30)))
def test_path_changes_and_stops_keep_every_limit(follower, test_knots, first, second, switch, stop_after):
    """A path change at any decision (to a path that runs from the robot to another test path; refused, changing
    nothing, where its spline leaves the position range), and an optional stop after it: every setpoint within
    the position, velocity, acceleration and jerk limits; a stop ends at rest."""
    follower.reset(test_knots[first])
    p1, v1, a1 = run(follower, switch)
    q = follower.state[0]
    try:
        gap = follower.replace_path(np.vstack([q, test_knots[second]]))
        assert gap < 1e-9  # the new path starts at the robot
    except FollowerError as exc:  # a spline outside the range, or during the final approach
        assert "position range" in str(exc) or "final approach" in str(exc)
        assert np.array_equal(follower.state[0], q)  # the old path goes on
    p2, v2, a2 = run(follower, 30 if stop_after is None else stop_after)
    parts = [(p1, v1, a1), (p2[1:], v2[1:], a2[1:])]
    if stop_after is not None:
        follower.stop()
        p3, v3, a3 = run(follower, 40)
        parts.append((p3[1:], v3[1:], a3[1:]))
        assert follower.done
    p, v, a = (torch.cat(x) for x in zip(*parts, strict=True))
    lim = JointLimits.from_robot(follower.robot)
    counts = limit_violations(p, v, a, lim, 1.0 / follower.env_cfg.control_rate)
    assert int(counts["total"]) == 0, {k: int(c) for k, c in counts.items()}


def test_a_whole_path_ends_at_rest_at_its_end(follower, test_knots):
    follower.reset(test_knots[2], q=test_knots[2][0])
    for _ in range(200):
        follower.decide()
        if follower.done:
            break
    assert follower.done
    assert follower.path_left < 0.3  # the env's end test: arc length reached or within 0.05 rad of the end knot
    assert np.linalg.norm(follower.state[0] - follower.env.end_q[0].numpy()) < 0.3


def test_bad_inputs_are_one_line_errors(follower, test_knots, tmp_path):
    fresh = Follower.load(MODEL)
    with pytest.raises(FollowerError, match="reset"):
        fresh.decide()
    with pytest.raises(FollowerError, match=r"\(K >= 2, 7\)"):
        follower.reset(np.zeros((5, 6)))
    with pytest.raises(FollowerError, match="finite"):
        follower.reset(np.full((3, 7), np.nan))
    with pytest.raises(FollowerError, match="from the path's first knot"):
        follower.reset(test_knots[0], q=test_knots[0][0] + 0.2)
    with pytest.raises(FollowerError, match="not a pathrl run"):
        Follower.load(tmp_path)
    with pytest.raises(FollowerError, match="controller"):
        Follower.load(model_dir("iiwa7_ball_tray_controller"))


def test_export_round_trip_matches_pytorch(tmp_path):
    """TorchScript and ONNX exports of a shipped actor (normaliser included) equal the PyTorch actor to 1e-5 on 1000
    observations the policy visits; the files load on their own; bad requests are one-line errors."""
    import json

    import onnxruntime

    from pathrl.cli.export import main

    out = tmp_path / "export"
    assert main([f"run_dir={MODEL}", f"out={out}", f"dataset.path={DATASET}"]) == 0
    report = json.loads((out / "export.json").read_text())
    assert report["observations"] == 1000
    assert report["max_abs_diff_torchscript"] <= 1e-5 and report["max_abs_diff_onnx"] <= 1e-5
    obs = torch.randn(3, report["obs_dim"])
    with torch.inference_mode():
        jit = torch.jit.load(str(out / "actor.pt"))(obs)
    onnx = onnxruntime.InferenceSession(str(out / "actor.onnx")).run(None, {"obs": obs.numpy()})[0]
    assert jit.shape == (3, 7) and np.allclose(jit.numpy(), onnx, atol=1e-5)
    assert main([f"run_dir={model_dir('iiwa7_ball_tray_controller')}", f"out={tmp_path / 'x'}"]) == 2
    assert main([f"run_dir={MODEL}", "observations=0"]) == 2
    assert main(["model=foo"]) == 2


def test_a_distilled_student_with_float32_mixed_precision_layers_exports(tmp_path):
    """The Table I student (pathrl's mixed-precision MLP with float32 hidden layers, a subclass TorchScript cannot
    script) is exported as rsl-rl's stock MLP with the same weights."""
    import json

    from pathrl.cli.export import main

    out = tmp_path / "export"
    assert main([f"run_dir={model_dir('iiwa7_random_track_distill')}", f"out={out}", f"dataset.path={DATASET}",
                 "observations=200"]) == 0
    report = json.loads((out / "export.json").read_text())
    assert report["hidden_dtype"] == "float32" and report["max_abs_diff_trained_dtype"] == 0.0
    assert report["max_abs_diff_torchscript"] <= 1e-5 and report["max_abs_diff_onnx"] <= 1e-5


def test_settle_time_by_hand():
    from pathrl.eval.path_change import SwitchEpisode

    ep = lambda devs: SwitchEpisode(0, 1.0, 5.0, 3.0, True, devs)  # noqa: E731
    assert ep([0.1, 0.12, 0.1]).settle_s(0.15, 0.1) == 0.0  # never above the level
    assert ep([0.1, 0.3, 0.4, 0.2, 0.14, 0.1]).settle_s(0.15, 0.1) == pytest.approx(0.4)  # back 2 steps after the peak
    assert ep([0.1, 0.3, 0.4, 0.3]).settle_s(0.15, 0.1) == float("inf")


def test_settle_in_band_and_band_by_hand():
    from pathrl.eval.path_change import SwitchEpisode, peak_band, tracking_level

    ep = lambda devs: SwitchEpisode(0, 1.0, 5.0, 3.0, True, devs)  # noqa: E731
    assert ep([0.1, 0.2, 0.1]).settle_in_band_s(0.25, 0.1) == 0.0  # never outside the band
    assert ep([0.1, 0.3, 0.2, 0.1]).settle_in_band_s(0.25, 0.1) == pytest.approx(0.2)  # inside from step 2 on
    assert ep([0.3, 0.1, 0.1, 0.1, 0.26]).settle_in_band_s(0.25, 0.1) == pytest.approx(0.5)  # the last step counts
    unchanged = [np.array([0.1, 0.4]), np.array([0.2, 0.2, 0.1]), np.array([0.3])]
    assert peak_band(unchanged, 0.5) == pytest.approx(0.3)  # median of the per-path peaks 0.4, 0.2, 0.3
    assert tracking_level(unchanged, 0.5) == pytest.approx(0.2)  # median of all six steps


def test_settle_against_the_control_by_hand():
    from pathrl.eval.path_change import excess_vs_control, settle_vs_control

    control = np.array([0.1, 0.1, 0.1, 0.1, 0.3, 0.1, 0.1, 0.1])  # the path's own turn at step 4
    assert settle_vs_control(control, control, 0.15, 0.1) == 0.0  # the control against itself
    turn_later = np.array([0.1, 0.1, 0.1, 0.1, 0.1, 0.3, 0.1, 0.1])  # the same turn one step later: within the slack
    assert settle_vs_control(turn_later, control, 0.15, 0.1) == 0.0
    assert settle_vs_control(turn_later, control, 0.15, 0.1, slack_s=0.0) == pytest.approx(0.6)  # steps 0-5 count
    change = np.array([0.2, 0.4, 0.2, 0.12, 0.35, 0.1, 0.1, 0.1])  # the change's excursion, then the turn (0.35 > 0.3)
    assert settle_vs_control(change, control, 0.15, 0.1) == pytest.approx(0.5)
    assert settle_vs_control(change, control, 0.15, 0.1, window_s=0.3) == pytest.approx(0.2)
    assert excess_vs_control(change, control, 0.15, 0.1, from_s=0.3) == pytest.approx(0.05)  # 0.35 - 0.3 at step 4
    assert excess_vs_control(change, control, 0.15, 0.1, from_s=0.5) == 0.0


def test_branch_starts_at_the_robot_in_its_direction_and_ends_offset():
    from pathrl.eval.path_change import branch
    from pathrl.paths.branch import BranchShape, BranchStart

    knots = np.stack([np.linspace(0.0, 4.0, 9), np.zeros(9)], axis=1)  # a straight line, knots 0.5 rad apart
    lim = np.array([[-5.0, 5.0], [-0.7, 0.7]])
    start = BranchStart(1.0, np.array([1.0, 0.01]), np.array([2.0, 0.0]))
    out = branch(knots, start, BranchShape(np.array([0.0, 1.0]), 1.0, lim))
    assert out[0].tolist() == [1.0, 0.01] and out[1].tolist() == pytest.approx([1.2, 0.01])
    assert out[2, 0] == 1.5 and out[2, 1] == pytest.approx(0.5 * 0.5 * (3 - 2 * 0.5))  # smoothstep at half the ramp
    assert out[-1].tolist() == pytest.approx([4.0, 0.68])  # the whole offset (1 rad), 0.02 inside the limit


def test_path_changes_keep_every_limit_and_reach_the_end(follower, test_knots):
    from pathrl.eval.path_change import path_change_episodes, toppra_replan

    eps = path_change_episodes(follower, test_knots, 3, seed=1)
    assert all(e.violations == 0 and e.reached_end for e in eps)
    assert all(1.0 <= e.switch_s <= 4.0 + 1e-9 for e in eps)
    rows = toppra_replan(follower, test_knots, 3, seed=1)
    assert [r["switch_s"] for r in rows] == pytest.approx([e.switch_s for e in eps])  # the same changes
    assert all(r["status"] == "ok" and r["violations"] == 0 for r in rows)


def test_the_path_change_benchmark_runs_end_to_end(tmp_path):
    """`python -m pathrl.eval.path_change` (a `make reproduce-tables` step) on 3 test paths: every variant measured,
    0 limit violations of the learned follower (its branches clipped into the range, never refused)."""
    import json

    from pathrl.eval.path_change import main

    out = tmp_path / "pc.json"
    main(["models/tracking/iiwa7_random", "datasets/iiwa7/random", str(out), "--episodes", "3"])
    res = json.loads(out.read_text())
    assert list(res["variants"]) == ["none", "gentle", "sharp"]
    for v in res["variants"].values():
        assert v["episodes"] == 3 and v["limit_violations"] == 0 and v["reached_end_pct"] == 100.0
