"""A policy trained on part of a robot, run on the whole robot (pathrl.policy.widen, runs._onto_robot)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
import torch
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from pathrl.policy.widen import LayoutError, actor_for_joints, input_columns, joint_rows
from pathrl.runs import _onto_robot


def _actor(num_obs: int, num_actions: int) -> MLPModel:
    obs = TensorDict({"policy": torch.zeros(1, num_obs)}, batch_size=[1])
    return MLPModel(obs, {"actor": ["policy"]}, "actor", num_actions, [16, 8], "elu", True,
                    {"class_name": "GaussianDistribution", "init_std": 0.2, "std_type": "scalar"})


def _env(joints: list[str], path_joints: list[str]) -> SimpleNamespace:
    return SimpleNamespace(robot=SimpleNamespace(joints=joints),
                           path_index=torch.tensor([joints.index(j) for j in path_joints]))


def _source(seed: int = 0) -> tuple[MLPModel, dict[str, torch.Tensor]]:
    """Joints b, c (both path joints), 3 x 2 per-joint inputs and 5 path inputs, a non-trivial normaliser."""
    torch.manual_seed(seed)
    src = _actor(11, 2)
    state = src.state_dict()
    state["obs_normalizer._mean"] = torch.randn(1, 11)
    state["obs_normalizer._var"] = torch.rand(1, 11) + 0.5
    state["obs_normalizer._std"] = state["obs_normalizer._var"].sqrt()
    src.load_state_dict(state)
    return src.eval(), state


def test_a_fixed_base_policy_drives_the_same_joints_on_the_bigger_robot():
    """Legs a, d added around path joints b, c and 3 task inputs appended: b and c get the source's actions
    whatever the legs' inputs hold; the legs get action 0."""
    src, state = _source()
    cfg = {"robot": {"joints": ["b", "c"], "path_joints": ["b", "c"]}}
    new = _actor(3 * 4 + 5 + 3, 4)
    new.load_state_dict(_onto_robot(cfg, _env(["a", "b", "c", "d"], ["b", "c"]), dict(state), new))
    new.eval()
    cols = input_columns(joint_rows(["b", "c"], ["a", "b", "c", "d"]), 4, 11, 20)
    assert cols.tolist() == [1, 2, 5, 6, 9, 10, 12, 13, 14, 15, 16]
    x_src, x_new = torch.randn(6, 11), torch.randn(6, 20)
    x_new[:, cols] = x_src
    with torch.no_grad():
        a_src = src(TensorDict({"policy": x_src}, batch_size=[6]))
        a_new = new(TensorDict({"policy": x_new}, batch_size=[6]))
    torch.testing.assert_close(a_new[:, 1:3], a_src)
    assert a_new[:, [0, 3]].abs().max() == 0.0


def test_same_robot_loads_the_state_unchanged():
    _, state = _source()
    cfg = {"robot": {"joints": ["b", "c"], "path_joints": ["b", "c"]}}
    out = _onto_robot(cfg, _env(["b", "c"], ["b", "c"]), state, _actor(11, 2))
    assert out is state


def test_other_path_joints_are_refused():
    _, state = _source()
    cfg = {"robot": {"joints": ["b", "c"], "path_joints": ["b", "c"]}}
    with pytest.raises(LayoutError, match="path joints"):
        _onto_robot(cfg, _env(["a", "b", "c"], ["a", "b", "c"]), state, _actor(14, 3))
    with pytest.raises(LayoutError, match="lacks"):
        actor_for_joints(state, ["b", "z"], ["a", "b", "c"], 14)
