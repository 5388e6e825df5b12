"""Residual policies over a controller (pathrl.policy.residual): the composition, the wrapper, and a run whose
untrained residual evaluates exactly like its controller."""

from __future__ import annotations

import pytest
import torch
import yaml
from tensordict import TensorDict
from test_train import run, train_cmd
from torch import nn

from pathrl.eval.evaluate import EvalOptions, evaluate
from pathrl.policy.residual import (
    BASE_GROUP,
    ResidualEnv,
    ResidualPolicy,
    check_residual_cfg,
    compose,
    zero_last_layer,
)

RESIDUAL = ("+experiment=iiwa7_ball_balancing_residual", "env.num_envs=32")


class StubEnv:
    num_envs, num_actions = 2, 2

    def __init__(self):
        self.actions = []

    def get_observations(self) -> TensorDict:
        return TensorDict({"policy": torch.zeros(2, 3)}, batch_size=[2])

    def step(self, actions):
        self.actions.append(actions.clone())
        return self.get_observations(), torch.zeros(2), torch.zeros(2), {}


def test_compose_adds_the_scaled_residual_and_clips_into_the_action_space():
    base = torch.tensor([[0.5, -0.9], [0.0, 1.0]])
    residual = torch.tensor([[1.0, -1.0], [-2.0, 0.4]])
    assert torch.equal(compose(base, residual, 0.25), torch.tensor([[0.75, -1.0], [-0.5, 1.0]]))


def test_the_residual_env_steps_with_the_controller_action_plus_the_scaled_residual():
    inner = StubEnv()
    env = ResidualEnv(inner, lambda obs: torch.full((2, 2), 0.5), scale=0.5)
    obs = env.get_observations()
    assert torch.equal(obs[BASE_GROUP], torch.full((2, 2), 0.5))
    env.step(torch.tensor([[1.0, -1.0], [0.0, 2.0]]))
    assert torch.equal(inner.actions[0], torch.tensor([[1.0, 0.0], [0.5, 1.0]]))


def test_a_zeroed_residual_policy_acts_as_its_controller():
    actor = nn.Sequential(nn.Linear(5, 8), nn.ELU(), nn.Linear(8, 2))
    zero_last_layer(actor)
    controller = lambda obs: torch.tensor([[0.3, -0.2]])  # noqa: E731

    class Actor(nn.Module):
        def forward(self, obs):
            return actor(torch.cat([obs["policy"], obs[BASE_GROUP]], dim=1))

    policy = ResidualPolicy(controller, Actor(), 0.25)
    obs = TensorDict({"policy": torch.randn(1, 3)}, batch_size=[1])
    assert torch.equal(policy(obs), torch.tensor([[0.3, -0.2]]))


@pytest.mark.parametrize("spec, key", [({"scale": 0.0, "controller": {}}, "scale"),
                                       ({"scale": True, "controller": {}}, "scale"),
                                       ({"scale": 0.2}, "keys"),
                                       ({"scale": 0.2, "controller": "tray"}, "controller")])
def test_bad_residual_specs_are_refused(spec, key):
    with pytest.raises(ValueError, match=key):
        check_residual_cfg(spec)


def test_an_untrained_residual_run_evaluates_exactly_as_its_controller(tiny_dataset, tmp_path):
    """Two iterations with the actor frozen (critic warm-up): the shipped policy is still the controller, and
    pathrl-eval gives the controller's episodes to the last digit."""
    res = tmp_path / "residual"
    r = run(train_cmd(tiny_dataset, res, 2, *RESIDUAL, "critic_warmup.iterations=2"))
    assert r.returncode == 0, r.stderr[-2000:]
    actor = torch.load(res / "model_1.pt", weights_only=True)["actor_state_dict"]
    assert float(actor["mlp.4.weight"].abs().sum()) == 0.0 and float(actor["mlp.4.bias"].abs().sum()) == 0.0
    cfg = yaml.safe_load((res / "config.yaml").read_text())
    ctl = tmp_path / "controller"
    ctl.mkdir()
    as_controller = {**cfg, "residual": {}, "controller": cfg["residual"]["controller"]}
    (ctl / "config.yaml").write_text(yaml.safe_dump(as_controller))
    (ctl / "summary.json").write_text((res / "summary.json").read_text())
    opts = EvalOptions(dataset_path=str(tiny_dataset), segments="full", backend="analytic", num_envs=8,
                       progress=False, record=False)
    a, b = evaluate(res, opts), evaluate(ctl, opts)
    assert a["limit_violations"] == 0
    for key in ("duration_s", "task_failed_pct", "cart_pos_dev_mean_cm"):
        assert a[key] == b[key], key


def test_a_residual_run_with_distillation_is_refused(tiny_dataset, tmp_path):
    r = run(train_cmd(tiny_dataset, tmp_path / "a", 1, *RESIDUAL, "agent=distillation", "critic_warmup.iterations=0",
                      "+teacher.name=tray"))
    assert r.returncode == 2 and "residual" in r.stderr.strip().splitlines()[-1], r.stderr[-500:]


def test_a_resumed_residual_run_equals_an_uninterrupted_one(tiny_dataset, tmp_path):
    """The controller's plan in progress is part of the checkpoint: 2 + 1 resumed iterations give the weights of
    3 uninterrupted ones."""
    args = (*RESIDUAL, "critic_warmup.iterations=0")
    whole, split = tmp_path / "whole", tmp_path / "split"
    assert run(train_cmd(tiny_dataset, whole, 3, *args)).returncode == 0
    assert run(train_cmd(tiny_dataset, split, 2, *args)).returncode == 0
    ck = torch.load(split / "model_1.pt", weights_only=True)
    assert ck["env_state_exact"] and ck["controller_state"]["controller"]["correction"].shape == (32, 7)
    r = run(train_cmd(tiny_dataset, split, 3, *args, "resume=true"))
    assert r.returncode == 0, r.stderr[-2000:]
    a = torch.load(whole / "model_2.pt", weights_only=True)["actor_state_dict"]
    b = torch.load(split / "model_2.pt", weights_only=True)["actor_state_dict"]
    assert all(torch.equal(a[k], b[k]) for k in a)
