"""The model-based ball controller (waiter's tray + ball feedback), the open-loop sensor, controller model dirs."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from pathrl.baselines.ball_feedback import (
    TrayController,
    TrayControllerCfg,
    linear_action,
    make_controller,
    quintic,
    quintic_coefficients,
    tray_normal,
)
from pathrl.dataset.io import load_pathset
from pathrl.envs.feedback import GRAVITY, ROLL_FACTOR, AnalyticBall, FrozenSensor
from pathrl.envs.rewards import build_reward_terms
from pathrl.envs.tracking import PathTrackingEnv, TrackingEnvCfg
from pathrl.eval.rollout import rollout
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits, action_to_acceleration
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.segments import full_segments
from pathrl.robot.model import load_robot_by_name

ROOT = Path(__file__).resolve().parents[1]
DATASET = ROOT / "datasets" / "iiwa7" / "ball_balancing"
REWARD = {"path_length": {"weight": 4.0}, "deviation_max": {"weight": 0.9}, "deviation_mean": {"weight": 0.9},
          "ball_centre": {"weight": 1.0}}


@pytest.fixture(scope="module")
def iiwa():
    return load_robot_by_name("iiwa7")


def ball_env(robot, n: int, seed: int = 0, frozen: bool = False) -> PathTrackingEnv:
    paths = load_pathset(DATASET, "test", KnotStrategy("distance", 0.3, 0.1, 5), robot)
    cfg = TrackingEnvCfg(num_envs=n, seed=seed, segments="full", episode_budget_s=6.0, scale_budget=False,
                         n_state=5, end_obs=True, end_tolerance=0.05, autoreset=False, fail_terminates=False)
    ball = AnalyticBall(robot, n, seed=seed)
    return PathTrackingEnv(cfg, robot, paths, build_reward_terms(REWARD), FrozenSensor(ball) if frozen else ball)


def in_plane_force(normal: torch.Tensor, a_plate: torch.Tensor) -> torch.Tensor:
    """In-plane part (N, 3) of g - a_plate on a plate with this normal."""
    f = torch.tensor([0.0, 0.0, -GRAVITY], dtype=torch.float64) - a_plate
    return f - (f * normal).sum(-1, keepdim=True) * normal


def test_tray_normal_by_hand():
    a = torch.tensor([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, -1.0, 0.5]], dtype=torch.float64)
    n = tray_normal(a, torch.zeros_like(a))
    assert n[0].tolist() == pytest.approx([0.0, 0.0, 1.0])  # at rest: level
    # accelerating at 2 m/s^2 along x: tilted into the motion by atan(2 / g)
    assert math.atan2(float(n[1, 0]), float(n[1, 2])) == pytest.approx(math.atan2(2.0, GRAVITY))
    assert in_plane_force(n, a).abs().max() < 1e-12  # nothing drives the ball
    # a commanded ball acceleration u (in the plane): 5/7 of the in-plane specific force equals u (to first order
    # in the tilt: 0.3 m/s^2 tilts the plate by 2.5 deg, the in-plane part is then 0.2 % short)
    u = torch.tensor([[0.3, 0.0, 0.0]], dtype=torch.float64)
    n_u = tray_normal(torch.zeros(1, 3, dtype=torch.float64), u)
    assert (ROLL_FACTOR * in_plane_force(n_u, torch.zeros(1, 3, dtype=torch.float64)))[0, 0] == pytest.approx(
        0.3, rel=3e-3)


def test_quintic_meets_its_boundary_conditions():
    p0, v0, a0, p1, tau = (torch.tensor([x], dtype=torch.float64) for x in (0.5, 0.4, -0.2, 2.0, 1.5))
    c = quintic_coefficients(p0, v0, a0, p1, tau)
    start, end = quintic(c, torch.zeros(1, dtype=torch.float64)), quintic(c, tau)
    assert [float(x) for x in start] == pytest.approx([0.5, 0.4, -0.2])
    assert [float(x) for x in end] == pytest.approx([2.0, 0.0, 0.0], abs=1e-12)


def test_linear_action_inverts_the_env_mapping():
    a_min = torch.tensor([[-2.0, 0.5, -1.0]], dtype=torch.float64)
    a_max = torch.tensor([[1.0, 3.0, -0.5]], dtype=torch.float64)
    acc = torch.tensor([[0.3, 0.5, -0.7]], dtype=torch.float64)
    assert torch.allclose(action_to_acceleration(linear_action(acc, a_min, a_max), a_min, a_max), acc)
    assert linear_action(torch.tensor([[9.0, -9.0, 0.0]], dtype=torch.float64), a_min, a_max).tolist() == [
        [1.0, -1.0, 1.0]]


def test_a_centred_ball_at_rest_gets_no_correction(iiwa):
    env = ball_env(iiwa, 2)
    env.start_segments(torch.arange(2), full_segments(env.paths, torch.tensor([0, 1])))
    ctl = TrayController(env)
    ctl._replan()
    at_rest = torch.zeros(2, 4, dtype=torch.float64)
    assert ctl.ball_acceleration(at_rest).abs().max() == 0.0
    # a ball off centre is pushed back toward the centre
    off = torch.tensor([[0.5, 0.0, 0.5, 0.0]], dtype=torch.float64).expand(2, 4)
    assert bool((ctl.ball_acceleration(off)[:, 0] < 0).all())
    ctl_still = TrayController(env, TrayControllerCfg(min_duration=1e6))  # a time law that has not started
    ctl_still._replan()
    env.episode_length_buf[:] = -1  # the target instant is then the start: plate at rest, level
    q_d, v_d, _ = ctl_still.target(at_rest)
    assert torch.allclose(q_d, env.pos, atol=1e-6)
    assert v_d.abs().max() < 1e-6


def test_controller_keeps_every_limit_and_most_balls(iiwa):
    """20 whole test paths, analytic ball: no limit violation at 240 Hz, every path reaches its end, and the
    ball stays on far more often than on a plate carried level (measured on these paths: 2 of 20 lost with
    feedback; the tracking-only policy of Table VII loses every ball)."""
    env = ball_env(iiwa, 20)
    plan = full_segments(env.paths, torch.arange(20))
    recs = rollout(env, TrayController(env), plan)
    lim = JointLimits.from_robot(iiwa)
    assert sum(int(limit_violations(r.setpoints, r.setpoint_vel, r.setpoint_acc, lim, r.extra["control_dt"])["total"])
               for r in recs) == 0
    lost = sum(r.extra["task"]["ball_on_plate"] < 0.5 for r in recs)
    assert lost <= 3
    assert sum(r.finish_step >= 0 for r in recs) >= 18


def test_frozen_sensor_keeps_its_first_reading_while_the_ball_moves(iiwa):
    env = ball_env(iiwa, 4, frozen=True)
    env.start_segments(torch.arange(4), full_segments(env.paths, torch.arange(4)))
    first = env.feedback.observe().clone()
    ctl = TrayController(env)
    for _ in range(15):
        env.step(ctl(env.get_observations()))
    assert torch.equal(env.feedback.observe(), first)
    assert not torch.allclose(env.feedback.inner.xy / env.feedback.inner.half, first[:, 2:4])  # the ball rolled


def test_make_controller_rejects_bad_specs(iiwa):
    env = ball_env(iiwa, 1)
    with pytest.raises(ValueError, match="unknown name 'lqr'"):
        make_controller({"name": "lqr"}, env)
    with pytest.raises(ValueError, match=r"unknown keys \['kpp'\]"):
        make_controller({"name": "tray", "kpp": 1.0}, env)
    with pytest.raises(ValueError, match="must be numbers"):
        make_controller({"name": "tray", "kp": "high"}, env)
    assert make_controller({"name": "tray", "kp": 2}, env).cfg.kp == 2


def test_the_shipped_controller_evaluates_like_a_policy(tmp_path):
    from pathrl.cli.evaluate import main

    out = tmp_path / "eval"
    assert main(["run_dir=models/iiwa7_ball_tray_controller", f"dataset.path={DATASET}", "segments=full",
                 "episodes=4", "backend=analytic", f"out={out}", "record=false"]) == 0
    import json

    m = json.loads((out / "metrics.json").read_text())
    assert m["checkpoint"] is None and m["task"]["open_loop"] is False and "ball_fell_pct" in m
    assert main(["run_dir=models/iiwa7_ball_tray_controller", f"dataset.path={DATASET}", "segments=full",
                 "episodes=4", "backend=analytic", f"out={out}", "record=false", "open_loop=true"]) == 0
    assert json.loads((out / "metrics.json").read_text())["task"]["open_loop"] is True


def test_open_loop_without_a_task_is_one_line_error(capsys):
    from pathrl.cli.evaluate import main

    assert main(["run_dir=models/iiwa7_random", "episodes=2", "open_loop=true",
                 f"dataset.path={ROOT / 'datasets' / 'iiwa7' / 'random'}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no feedback task" in err[0]
