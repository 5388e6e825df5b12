"""MixedPrecisionMLPModel: the stock MLPModel's function and state dict, hidden layers in bfloat16."""

import json

import pytest
import torch
from rsl_rl.models import MLPModel
from rsl_rl.modules import MLP
from tensordict import TensorDict

from pathrl.eval.curve import CurvePoint, CurveProtocol, Target, _cached, curve_point, first_reaching
from pathrl.policy.models import MixedPrecisionMLPModel

DIST = {"class_name": "GaussianDistribution", "init_std": 0.2, "std_type": "scalar"}


def _obs(n=512, dim=94, seed=0):
    g = torch.Generator().manual_seed(seed)
    return TensorDict({"policy": torch.randn(n, dim, generator=g)}, batch_size=[n])


def _models(hidden_dtype):
    obs = _obs()
    args = (obs, {"actor": ["policy"]}, "actor", 7)
    kw = {"hidden_dims": [256, 128], "activation": "elu", "obs_normalization": True, "distribution_cfg": DIST}
    torch.manual_seed(0)
    ref = MLPModel(*args, **kw)
    mixed = MixedPrecisionMLPModel(*args, hidden_dtype=hidden_dtype, **kw)
    mixed.load_state_dict(ref.state_dict())  # same keys: loads strictly both ways
    ref.load_state_dict(mixed.state_dict())
    return obs, ref, mixed


def test_float32_hidden_layers_are_the_stock_model():
    obs, ref, mixed = _models("float32")
    assert torch.equal(ref(obs), mixed(obs)) and isinstance(mixed.mlp, MLP)


def test_bfloat16_hidden_layers_round_only_the_hidden_inputs():
    obs, ref, mixed = _models("bfloat16")
    out, want = mixed(obs), ref(obs)
    assert out.dtype == torch.float32
    # bfloat16 keeps 8 bits of mantissa: the hidden activations are within ~2^-8 relative, and so is the output
    err = (out - want).abs().max() / want.abs().max()
    assert 0 < err < 2e-2
    # deterministic: the same function in a rollout and in an update (PPO's ratio starts at exactly 1)
    assert torch.equal(out, mixed(obs))


def test_gradients_and_distribution_stay_float32():
    obs, _, mixed = _models("bfloat16")
    actions = mixed(obs, stochastic_output=True)
    loss = -mixed.get_output_log_prob(actions).mean()
    loss.backward()
    assert actions.dtype == torch.float32 and mixed.output_mean.dtype == torch.float32
    grads = [p.grad for p in mixed.parameters() if p.requires_grad]
    assert all(g is not None and g.dtype == torch.float32 and torch.isfinite(g).all() for g in grads)


def test_unknown_hidden_dtype_is_refused():
    with pytest.raises(ValueError, match="hidden_dtype"):
        MixedPrecisionMLPModel(_obs(4), {"actor": ["policy"]}, "actor", 7, hidden_dtype="float16")


def test_first_reaching_needs_both_limits_and_no_violation():
    target = Target(max_duration_s=4.28, max_dev_cm=3.3)
    pts = [CurvePoint(100, 1, 60.0, 4.1, 3.5, 0),  # fast but too far from the path
           CurvePoint(200, 2, 120.0, 4.2, 3.2, 3),  # violates a limit
           CurvePoint(300, 3, 180.0, 4.25, 3.3, 0),  # both limits met (inclusive)
           CurvePoint(400, 4, 240.0, 4.0, 3.0, 0)]
    assert first_reaching(pts[::-1], target) == pts[2]
    assert first_reaching(pts[:2], target) is None


def test_curve_point_reads_the_ball_columns_when_there():
    tracking = {"duration_s": 2.5, "cart_pos_dev_mean_cm": 3.0, "limit_violations": 0, "duration_end_of_path_s": None}
    ball = {**tracking, "duration_end_of_path_s": 2.25, "task_failed_pct": 1.5}
    assert curve_point(3, 100, 12.0, tracking) == CurvePoint(3, 300, 12.0, 2.5, 3.0, 0, None, None)
    assert curve_point(3, 100, None, ball) == CurvePoint(3, 300, None, 2.5, 3.0, 0, 2.25, 1.5)


def test_cached_curve_evaluation_must_come_from_the_same_simulator(tmp_path):
    path = tmp_path / "metrics.json"
    metrics = {"dataset": "d", "segments": "full", "episodes": 200, "task": {"simulator": "analytic"}}
    path.write_text(json.dumps(metrics))
    assert _cached(path, "d", CurveProtocol(None, "full", "analytic")) is not None
    assert _cached(path, "d", CurveProtocol(None, "full", "pybullet")) is None  # analytic never stands in for PyBullet
    assert _cached(path, "d", CurveProtocol(100, "full", "analytic")) is None
    path.write_text(json.dumps({"dataset": "d", "segments": "full", "episodes": 200}))  # tracking only: no simulator
    assert _cached(path, "d", CurveProtocol(None, "full", "pybullet")) is not None
