"""``float32_from``: bfloat16 hidden layers while the policy explores, float32 from a given iteration on."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
import torch
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from pathrl.policy.models import MixedPrecisionMLPModel
from pathrl.train.runner import PathRLRunner, float32_iteration

OBS = TensorDict({"policy": torch.zeros(1, 6)}, batch_size=[1])
DIST = {"class_name": "GaussianDistribution", "init_std": 0.2, "std_type": "scalar"}


def _model(cls=MixedPrecisionMLPModel, **kw):
    torch.manual_seed(0)
    return cls(OBS, {"actor": ["policy"]}, "actor", 3, [16, 8], "elu", True, DIST, **kw)


def _runner(start_it: int) -> PathRLRunner:
    runner = PathRLRunner.__new__(PathRLRunner)  # only the parts set_float32_from touches
    runner.alg = SimpleNamespace(actor=_model(), critic=_model(), update=lambda: {})
    runner.current_learning_iteration = start_it
    return runner


def test_switches_after_the_update_that_ends_the_iteration_before():
    runner = _runner(0)
    runner.set_float32_from(3)
    dtypes = []
    for _ in range(5):
        dtypes.append((runner.alg.actor.mlp.dtype, runner.alg.critic.mlp.dtype))
        runner.alg.update()
    bf, fp = torch.bfloat16, torch.float32
    assert dtypes == [(bf, bf), (bf, bf), (bf, bf), (fp, fp), (fp, fp)]  # iterations 0-2 bfloat16, 3- float32


def test_a_resumed_run_past_the_switch_starts_in_float32():
    runner = _runner(7)
    runner.set_float32_from(3)
    assert runner.alg.actor.mlp.dtype == torch.float32


def test_switched_model_is_the_stock_model():
    mixed, stock = _model(), _model(MLPModel)
    stock.load_state_dict(mixed.state_dict())
    x = TensorDict({"policy": torch.randn(32, 6)}, batch_size=[32])
    with torch.no_grad():
        before = mixed(x)
        runner = _runner(0)
        runner.alg.actor = mixed
        runner.set_float32_from(0)
        assert torch.equal(mixed(x), stock(x))
    assert not torch.equal(before, stock(x))  # bfloat16 was really on before the switch


def test_fraction_of_the_iterations():
    assert float32_iteration(0.5, 600) == 300
    assert float32_iteration(0.0, 600) == 0
    assert float32_iteration(1, 600) == 600  # never within the run
    assert float32_iteration(0.3333, 10) == 4
    for bad in (-0.1, 1.5, "half", float("nan")):
        with pytest.raises(ValueError, match="float32_from"):
            float32_iteration(bad, 600)


def test_bfloat16_warning_names_the_roles_to_switch_and_only_when_slow():
    from pathrl.policy.models import bfloat16_warning

    model = "pathrl.train.models:MixedPrecisionMLPModel"
    agent = {"actor": {"class_name": model, "hidden_dtype": "bfloat16"},
             "critic": {"class_name": model, "hidden_dtype": "float32"}, "algorithm": {"class_name": "PPO"}}
    msg = bfloat16_warning(agent, slowdown=12.0)
    assert msg is not None and "12x slower" in msg and msg.endswith("add agent.actor.hidden_dtype=float32 for a much "
                                                                    "faster run")
    assert "\n" not in msg and "critic" not in msg
    assert bfloat16_warning(agent, slowdown=0.6) is None  # native bfloat16: faster, nothing to say
    agent["actor"]["hidden_dtype"] = "float32"
    assert bfloat16_warning(agent, slowdown=12.0) is None  # nothing in bfloat16
