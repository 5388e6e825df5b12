"""Termination terms and reasons (pathrl.envs.terminations), hand-computed, and the env's reason tensor."""

from __future__ import annotations

import torch

from pathrl.envs.terminations import (
    TERMINATION_REASONS,
    TerminationReason,
    deviation_exceeded,
    end_reached,
    robot_stopped,
    termination_reason,
    timed_out,
)

R = TerminationReason


def _b(*xs: int) -> torch.Tensor:
    return torch.tensor(xs, dtype=torch.bool)


def test_labels_are_the_names_in_metrics_json():
    assert TERMINATION_REASONS == ("robot_stopped", "deviation", "task_failed", "time_out")
    assert R.STOPPED.label == "robot_stopped" and R(4).label == "time_out"


def test_first_reason_in_priority_order_wins():
    #          env: 0  1  2  3  4  5
    stopped = _b(1, 0, 0, 0, 0, 1)
    deviation = _b(1, 1, 0, 0, 0, 0)
    task_failed = _b(0, 1, 1, 0, 0, 0)
    time_out = _b(0, 0, 1, 1, 0, 1)
    r = termination_reason(stopped, deviation, task_failed, time_out)
    assert r.dtype == torch.int8
    assert r.tolist() == [R.STOPPED, R.DEVIATION, R.TASK_FAILED, R.TIME_OUT, R.NONE, R.STOPPED]


def test_terms():
    s, end = torch.tensor([1.0, 0.95, 0.5, 1.0 - 1e-10]), torch.ones(4)
    assert end_reached(s, end, None, 0.1, None).tolist() == [True, False, False, True]
    to_end = torch.tensor([0.0, 0.01, 0.01, 0.5])  # within 0.02 of the end knot and < 0.1 arc length left
    assert end_reached(s, end, to_end, 0.1, 0.02).tolist() == [True, True, False, True]
    vel = torch.tensor([[0.0, 0.005], [0.0, 0.02], [0.0, 0.0]])
    acc = torch.zeros(3, 2)
    assert robot_stopped(_b(1, 1, 0), vel, acc, 0.01).tolist() == [True, False, False]
    dev = torch.tensor([0.1, 0.3])
    assert deviation_exceeded(dev, 0.25).tolist() == [False, True]
    assert deviation_exceeded(dev, None).tolist() == [False, False]
    assert timed_out(torch.tensor([9, 10, 11]), torch.tensor([10, 10, 10])).tolist() == [False, True, True]


def test_env_sets_one_reason_per_env_and_logs_their_shares(tiny_dataset):
    from pathrl.cli.common import compose, to_container
    from pathrl.envs.registry import EnvRequest, make_env
    from pathrl.schema import TrainAppCfg

    cfg = to_container(compose("train", [f"dataset.path={tiny_dataset}", "env.max_deviation=1e-6"], TrainAppCfg))
    env = make_env(cfg, EnvRequest(num_envs=8, seed=3))
    _, _, dones, extras = env.step(torch.ones(8, env.num_actions))  # full acceleration leaves the path at once
    assert bool(dones.all()) and env.termination.tolist() == [R.DEVIATION] * 8
    log = extras["log"]
    assert float(log["Episode_Termination/deviation"]) == 1.0
    assert float(log["Episode_Termination/robot_stopped"]) == float(log["Episode_Termination/time_out"]) == 0.0
    assert "Episode_Termination/task_failed" not in log  # no feedback task
