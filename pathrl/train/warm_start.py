"""Warm start: begin a run from the weights of another (e.g. the tracking policy before adding ball feedback,
or the fixed-legs ARMAR-4 policy before its legs become actions).

The new run may observe more: extra joints (their position, velocity and acceleration sit in the three
per-joint blocks at the front of the state) and task inputs (appended at the end). Each input of the source
keeps its weights at its new column; new columns get zero weights and the observation normalizers start at
mean 0 / std 1 there. New actions (extra joints) get zero output weights and bias: action 0, the middle of
the joint's valid range, which holds a joint at rest. So the new policy initially behaves exactly like the
source, with the new joints held still.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import torch
import yaml

from pathrl.policy.widen import LayoutError, actor_for_joints, input_columns, joint_rows, widen_inputs, widen_outputs
from pathrl.storage import CheckpointError, latest_valid_checkpoint, load_checkpoint

__all__ = ["WarmStartError", "input_columns", "joint_rows", "source_checkpoint", "source_joints", "warm_start",
           "widen_inputs", "widen_outputs"]

#: The warm-start source is missing or does not fit the new run (the layout functions raise it too).
WarmStartError = LayoutError


def source_checkpoint(path: str | Path) -> Path:
    """The checkpoint of a shipped model dir (model.pt) or a training run (latest model_<it>.pt)."""
    p = Path(path)
    if p.is_file():
        return p
    if (p / "model.pt").is_file():
        return p / "model.pt"
    ckpt = latest_valid_checkpoint(p, warn=False) if p.is_dir() else None
    if ckpt is None:
        raise WarmStartError(f"init_from={path}: no model.pt or model_<iteration>.pt there")
    return ckpt


def source_joints(ckpt: Path) -> tuple[list[str], list[str]] | None:
    """(joints, path joints) of the robot the checkpoint was trained on, from the config.yaml beside it."""
    cfg_path = ckpt.parent / "config.yaml"
    if not cfg_path.is_file():
        return None
    try:
        robot = (yaml.safe_load(cfg_path.read_text()) or {}).get("robot") or {}
    except yaml.YAMLError as exc:
        raise WarmStartError(f"{cfg_path}: invalid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(robot.get("joints"), list) or not isinstance(robot.get("path_joints"), list):
        return None
    return [str(j) for j in robot["joints"]], [str(j) for j in robot["path_joints"]]


def warm_start(alg, source: str | Path, num_obs: int, init_std: float | None = None,
               joints: Sequence[str] | None = None, path_joints: Sequence[str] | None = None) -> Path:
    """Load actor and critic of `source` into the PPO `alg` (a distillation run's student: the actor only).
    With the new robot's `joints` and `path_joints` given, a source trained on fewer joints (same path joints)
    is mapped joint by joint; otherwise the inputs are only widened at the end. The action std is reset to
    `init_std` (a converged source has almost no exploration left). Returns the checkpoint used."""
    ckpt = source_checkpoint(source)
    try:
        loaded = load_checkpoint(ckpt)
        actor = dict(loaded["actor_state_dict" if "actor_state_dict" in loaded else "student_state_dict"])
        critic = dict(loaded["critic_state_dict"]) if "critic_state_dict" in loaded else None
    except CheckpointError as exc:
        raise WarmStartError(f"init_from={source}: {exc}") from None
    except KeyError as exc:
        raise WarmStartError(f"{ckpt}: no policy weights in the checkpoint (missing {exc})") from None
    if init_std is not None and "distribution.std_param" in actor:
        actor["distribution.std_param"] = torch.full_like(actor["distribution.std_param"], init_std)
    src = source_joints(ckpt) if joints is not None else None
    critic_obs = _input_width(alg, num_obs)
    if src is not None and list(src[0]) != list(joints):
        if critic is None:  # a distilled student (pathrl.train.distill)
            raise WarmStartError(f"init_from={source}: a distilled student must have the new robot's joints")
        if path_joints is not None and list(src[1]) != list(path_joints):
            raise WarmStartError(f"init_from={source}: path joints differ ({src[1]} vs {list(path_joints)})")
        if critic_obs != num_obs:
            raise WarmStartError(f"init_from={source}: a source on other joints cannot start an asymmetric critic")
        cols = input_columns(joint_rows(src[0], joints), len(joints), actor["mlp.0.weight"].shape[1], num_obs)
        actor = actor_for_joints(actor, src[0], joints, num_obs, init_std)
        critic = widen_inputs(critic, num_obs, cols)
    else:
        actor = widen_inputs(actor, num_obs)
        critic = None if critic is None else widen_inputs(critic, critic_obs)
    state = {"actor_state_dict": actor}
    if critic is not None:  # a distilled student has none: the run's new critic stays
        state["critic_state_dict"] = critic
    try:
        alg.load(state, {"actor": True, "critic": critic is not None}, True)
    except RuntimeError as exc:
        raise WarmStartError(f"init_from={source}: network does not fit ({str(exc).splitlines()[0]})") from None
    return ckpt


def _input_width(alg, num_obs: int) -> int:
    """Inputs of the run's critic (an asymmetric critic also sees the privileged group, appended after the policy's
    `num_obs`); `num_obs` where the algorithm has no critic of that shape."""
    critic = getattr(alg, "_raw_critic", None)
    weight = None if critic is None else critic.state_dict().get("mlp.0.weight")
    return num_obs if weight is None else int(weight.shape[1])
