"""The model-based tracker of each path's time-optimal law (pathrl.baselines.law_tracker): the teacher of the
distilled tracking rows."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from pathrl.baselines.law_tracker import LawTracker, LawTrackerCfg
from pathrl.baselines.toppra import ToppraSettings, solve_plan
from pathrl.dataset.io import load_pathset
from pathrl.envs.rewards import build_reward_terms
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.eval.metrics import matched_samples, sample_deviations
from pathrl.eval.rollout import rollout
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.segments import full_segments, sample_segments
from pathrl.robot.external import load_robot_by_name
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.runs import make_controller

ROOT = Path(__file__).resolve().parents[1]
DATASET = ROOT / "datasets" / "iiwa7" / "ball_balancing"
REWARD = {"path_length": {"weight": 1.0}, "deviation_max": {"weight": 0.9}, "deviation_mean": {"weight": 0.9}}


def _env(n: int, segments: str = "full") -> PathTrackingEnv:
    robot = load_robot_by_name("iiwa7")
    paths = load_pathset(DATASET, "test", KnotStrategy("distance", 0.3, 0.1, 5), robot)
    cfg = TrackingEnvCfg(num_envs=n, seed=0, segments=segments, episode_budget_s=6.0, scale_budget=False, n_state=5,
                         autoreset=False)
    return PathTrackingEnv(cfg, robot, paths, build_reward_terms(REWARD))


def test_the_tracker_follows_whole_paths_within_a_few_millimetres_and_every_limit():
    """12 whole test paths at the full limits: every path finished, no limit violated at 240 Hz, mean Cartesian
    deviation below 0.5 cm (measured on the 200 test paths: 0.21 cm), at most 1.3x each path's TOPP-RA time
    (measured: 1.17x on the mean)."""
    env = _env(12)
    ctl = LawTracker(env, LawTrackerCfg(limit_margin=1.0, smooth_s=0.2, track_omega=15.0))
    ids = torch.arange(12)
    recs = rollout(env, ctl, full_segments(env.paths, ids))
    lim = JointLimits.from_robot(env.robot)
    assert all(r.reached_end for r in recs)
    assert sum(int(limit_violations(r.setpoints, r.setpoint_vel, r.setpoint_acc, lim, r.extra["control_dt"])["total"])
               for r in recs) == 0
    pi = torch.as_tensor(env.robot.path_index)
    sp = [r.setpoints for r in recs]
    devs = sample_deviations(sp, matched_samples(sp, pi, env.paths, [r.path for r in recs],
                                                 [r.start_s for r in recs], [r.end_s for r in recs]),
                             pi, ForwardKinematics(env.robot))
    assert np.mean([d["cart_pos_dev_mean_cm"] for d in devs]) < 0.5
    topp = solve_plan(env.paths, full_segments(env.paths, ids), env.robot, ToppraSettings(keep_trajectory=False),
                      progress=False)
    assert np.mean([r.duration_s for r in recs]) < 1.3 * np.mean([t.duration_s for t in topp])


def test_a_slower_law_takes_longer():
    """Half the limits make every law, and the tracked episodes, longer."""
    env = _env(4)
    fast, slow = LawTracker(env, LawTrackerCfg(limit_margin=1.0)), LawTracker(env, LawTrackerCfg(limit_margin=0.5))
    ids = torch.arange(4)
    assert bool((slow.laws.duration(ids) > 1.3 * fast.laws.duration(ids)).all())


def test_the_tracker_refuses_segments_that_start_inside_a_path():
    with pytest.raises(ValueError, match="whole paths"):
        LawTracker(_env(2, segments="paper"))
    env = _env(2)
    ctl = LawTracker(env)
    gen = torch.Generator().manual_seed(0)
    plan = sample_segments(env.paths, torch.arange(2), gen)
    with pytest.raises(ValueError, match="starts inside its path"):
        rollout(env, ctl, plan)


def test_the_controller_registry_builds_it_and_checks_its_keys():
    env = _env(2)
    assert isinstance(make_controller({"name": "law_tracker", "limit_margin": 0.9}, env), LawTracker)
    with pytest.raises(ValueError, match="unknown keys"):
        make_controller({"name": "law_tracker", "margin": 0.9}, env)
