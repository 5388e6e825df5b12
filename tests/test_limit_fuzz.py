"""Adversarial limit fuzz (pathrl.eval.limit_fuzz): a smaller count here, 10^7 steps per robot in `make bench`."""

import pytest
import torch

import pathrl.envs.tracking as tracking
from pathrl.eval.limit_fuzz import fuzz_env
from pathrl.robot.external import load_robot_by_name


@pytest.mark.parametrize("robot", ["iiwa7", "armar6", "armar4_legs"])
def test_adversarial_streams_never_violate_a_limit(robot):
    res = fuzz_env(robot, steps=150, num_envs=500, seed=3)
    assert res.violations["total"] == 0, res.violations
    assert res.decision_steps == 75_000 and res.setpoints_checked == 75_000 * 24 * load_robot_by_name(robot).dof
    # every attack happened
    assert res.restarts_at_limits > 100 and res.restarts_on_path > 100 and res.brakes > 20
    assert res.nonfinite_actions > 0


def test_the_fuzz_sees_a_mapping_that_ignores_the_valid_range(monkeypatch):
    """The same streams through a mapping onto the full +-acceleration limit (no valid range) do violate."""
    def unsafe(actions, a_min, a_max, hold=None):
        lim = torch.maximum(a_max.abs(), a_min.abs()).amax(0, keepdim=True)
        return actions.clamp(-1.0, 1.0) * lim

    monkeypatch.setattr(tracking, "action_to_acceleration", unsafe)
    res = fuzz_env("iiwa7", steps=60, num_envs=200, seed=3)
    assert res.violations["position"] > 0 and res.violations["velocity"] > 0
