"""Export a shipped policy's actor, observation normaliser included, to TorchScript and ONNX, and check both.

The exports are rsl-rl's own export modules (``MLPModel.as_jit`` / ``as_onnx``: normaliser, MLP, deterministic
output) of the actor in float32. A model trained with bfloat16 hidden layers
(:class:`~pathrl.policy.models.MixedPrecisionMLPModel`) is exported with the same weights computing in float32;
``export.json`` reports how far that is from the bfloat16 policy. The check runs the exports and the float32
PyTorch actor on observations recorded from the policy itself on test paths.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rsl_rl.modules import MLP

from pathrl.envs.registry import EVAL_ENV, EnvRequest, make_env
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.paths.segments import evaluation_plan
from pathrl.runs import load_policy
from pathrl.storage import atomic_write

__all__ = ["EXPORT_ATOL", "env_obs", "export_policy", "float32_actor", "record_observations"]


#: Largest |export - PyTorch| accepted by the check (float32 actions in [-1, 1]).
EXPORT_ATOL = 1e-5


def float32_actor(policy: torch.nn.Module) -> torch.nn.Module:
    """The policy computing in float32 throughout (a mixed-precision MLP, float32 hidden layers included, becomes
    rsl-rl's stock MLP with the same weights: only that one scripts)."""
    import copy

    actor = copy.deepcopy(policy).eval()
    if type(actor.mlp) is not MLP:
        plain = MLP.__new__(MLP)
        torch.nn.Sequential.__init__(plain, *actor.mlp)
        actor.mlp = plain
    return actor


def record_observations(env: PathTrackingEnv, policy: torch.nn.Module, count: int) -> torch.Tensor:
    """`count` observations (count, O) of `policy` following the env's paths (paper segments, fixed seed)."""
    n = env.num_envs
    plan = evaluation_plan(env.paths, n, "paper", 0)
    env.start_segments(torch.arange(n), plan)
    obs = []
    while sum(len(o) for o in obs) < count:
        td = env.get_observations()
        obs.append(td["policy"].clone())
        with torch.inference_mode():
            env.step(policy(td))
    return torch.cat(obs)[:count].float()


def _atomic(path: Path, write) -> None:
    atomic_write(path, lambda tmp: write(str(tmp)))


def export_policy(cfg: dict[str, Any], checkpoint: Path, request: EnvRequest, out_dir: Path,
                  observations: int = 1000) -> dict[str, Any]:
    """Write ``actor.pt`` (TorchScript), ``actor.onnx`` and ``export.json`` (sizes and the check) to `out_dir`; the
    observations the exports are checked on are recorded in the evaluation env of `cfg` that `request` asks for.

    Raises ValueError if an export differs from the PyTorch actor by more than EXPORT_ATOL.
    """
    import onnxruntime

    if cfg.get("residual"):
        raise ValueError("a residual policy acts through its controller, which has no TorchScript/ONNX form; "
                         "export exports whole policy networks")
    env = make_env(cfg, request, **EVAL_ENV)
    policy = load_policy(cfg, env, checkpoint)
    obs = record_observations(env, policy, observations)
    actor = float32_actor(policy)
    out_dir.mkdir(parents=True, exist_ok=True)
    jit_path, onnx_path = out_dir / "actor.pt", out_dir / "actor.onnx"
    scripted = torch.jit.script(actor.as_jit().cpu())
    _atomic(jit_path, lambda p: scripted.save(p))
    onnx_module = actor.as_onnx(verbose=False).cpu().eval()
    _atomic(onnx_path, lambda p: torch.onnx.export(
        onnx_module, onnx_module.get_dummy_inputs(), p, dynamo=True, external_data=False, opset_version=18,
        input_names=["obs"], output_names=["actions"], dynamic_shapes={"x": {0: torch.export.Dim("batch")}}))
    with torch.inference_mode():
        ref = actor.as_jit()(obs)
        trained = policy(env_obs(obs))
        jit_out = torch.jit.load(str(jit_path))(obs)
    sess = onnxruntime.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    onnx_out = torch.as_tensor(sess.run(None, {"obs": obs.numpy()})[0])
    report = {
        "observations": int(obs.shape[0]), "obs_dim": int(obs.shape[1]), "actions": int(ref.shape[1]),
        "max_abs_diff_torchscript": float((jit_out - ref).abs().max()),
        "max_abs_diff_onnx": float((onnx_out - ref).abs().max()),
        "max_abs_diff_trained_dtype": float((trained - ref).abs().max()),
        "hidden_dtype": str(getattr(policy.mlp, "dtype", torch.float32)).replace("torch.", ""),
        "inputs": "obs (B, obs_dim) float32: the env's policy observation",
        "outputs": "actions (B, actions) in [-1, 1]",
    }
    _atomic(out_dir / "export.json", lambda p: Path(p).write_text(json.dumps(report, indent=2) + "\n"))
    worst = max(report["max_abs_diff_torchscript"], report["max_abs_diff_onnx"])
    if not np.isfinite(worst) or worst > EXPORT_ATOL:
        raise ValueError(f"exported actor differs from PyTorch by {worst:.2e} (> {EXPORT_ATOL})")
    return report


def env_obs(obs: torch.Tensor):
    """Observations (B, O) as the TensorDict the PyTorch policy reads."""
    from tensordict import TensorDict

    return TensorDict({"policy": obs}, batch_size=[obs.shape[0]])
