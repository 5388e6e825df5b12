"""Run and model directories loaded: a run's config, checkpoint and summary (:func:`load_run`), and what acts in it,
its policy network (:func:`load_policy`) or its model-based controller (:func:`make_controller`, ``controller:`` in
its config). Below evaluation and deployment, which both start from here.

A controller that drives part of the robot with a policy network (``balance``: the upper body from a shipped model
directory, its ``policy`` setting) gets that network from :func:`load_policy`; a residual run's policy acts on top of
its controller. Both ways round live in this module.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import torch
import yaml
from rsl_rl.models import MLPModel, RNNModel
from tensordict import TensorDict

from pathrl.baselines.controllers import controller_cfg
from pathrl.config.migrate import migrate
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.models import regrouped
from pathrl.policy import MixedPrecisionMLPModel, policy_role
from pathrl.policy.residual import BASE_GROUP, ResidualPolicy, check_residual_cfg
from pathrl.policy.widen import LayoutError, actor_for_joints
from pathrl.storage import CheckpointError, latest_checkpoint, load_checkpoint

__all__ = ["POLICY_MODELS", "RunError", "committed_split", "load_policy", "load_run", "make_controller",
           "policy_scale"]


class RunError(ValueError):
    """A run / model directory is incomplete or unreadable."""


def committed_split(path: str, split: str) -> str:
    """A run's dataset path, or the committed copy of its test split (``datasets/<robot>/<kind>``, the same
    paths) when the generated ``data/<robot>/<kind>`` is not on this machine (a fresh checkout)."""
    p = Path(path)
    if split == "test" and not p.exists() and p.parts[:1] == ("data",):
        alt = Path("datasets", *p.parts[1:])
        if (alt / "dataset.json").is_file():
            print(f"note: {p} not found; evaluating on the committed test split {alt}", file=sys.stderr)
            return str(alt)
    return path


def load_run(run_dir: Path) -> tuple[dict[str, Any], Path | None, dict[str, Any]]:
    """(resolved config in the current layout, checkpoint path, training summary) of a run or model directory.

    A model-based controller's directory (``controller:`` in its config) has no checkpoint (None)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        moved = regrouped(run_dir)
        hint = f" (shipped models are grouped by family: {moved})" if moved else ""
        raise RunError(f"run_dir not found: {run_dir}{hint}")
    cfg_path = run_dir / "config.yaml"
    if not cfg_path.is_file():
        raise RunError(f"{cfg_path} missing: not a pathrl run or model directory")
    try:
        cfg = yaml.safe_load(cfg_path.read_text())
    except yaml.YAMLError as exc:
        raise RunError(f"{cfg_path}: invalid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(cfg, dict):
        raise RunError(f"{cfg_path}: expected a mapping of config groups, got {type(cfg).__name__}")
    try:
        cfg = migrate(cfg)  # saved by older code: the keys added since, at the values those runs used
    except ValueError as exc:
        raise RunError(f"{cfg_path}: {exc}") from None
    ckpt = run_dir / "model.pt"
    if not ckpt.is_file():
        ckpt = latest_checkpoint(run_dir)
    if ckpt is None and "controller" not in cfg:
        raise RunError(f"{run_dir}: no checkpoint (model.pt or model_<iteration>.pt)")
    summary = {}
    if (run_dir / "summary.json").is_file():
        try:
            summary = json.loads((run_dir / "summary.json").read_text())
        except json.JSONDecodeError as exc:
            raise RunError(f"{run_dir / 'summary.json'}: invalid JSON ({exc})") from None
        if not isinstance(summary, dict):
            raise RunError(f"{run_dir / 'summary.json'}: expected a JSON object, got {type(summary).__name__}")
    return cfg, ckpt, summary


def policy_scale(run_dir: Path, summary: dict[str, Any]) -> float:
    """The length scale D (``knot_gap_norm``) a policy's state was normalised with in training, from the run's
    ``summary.json``. RunError without it: a D recomputed from other paths would scale the state differently, and
    the policy would run on, with other deviations, without a word."""
    gap = summary.get("knot_gap_norm")
    if gap is None:
        where = Path(run_dir) / "summary.json"
        state = "has no knot_gap_norm" if where.is_file() else "is missing"
        raise RunError(f"{where} {state}: the policy's length scale (the state's normalisation in training) is "
                       "recorded there; restore it from the run")
    try:
        value = float(gap)
    except (TypeError, ValueError):
        value = float("nan")
    if not (math.isfinite(value) and value > 0):
        raise RunError(f"{Path(run_dir) / 'summary.json'}: knot_gap_norm must be a number > 0, got {gap!r}")
    return value


#: Policy network classes a run's config may name (``agent.actor`` or ``agent.student``): evaluation builds
#: nothing else from a config it is handed.
POLICY_MODELS = {"MLPModel": MLPModel, "rsl_rl.models:MLPModel": MLPModel,
                 "pathrl.train.models:MixedPrecisionMLPModel": MixedPrecisionMLPModel,
                 "RNNModel": RNNModel, "rsl_rl.models:RNNModel": RNNModel}


def load_policy(cfg: dict[str, Any], env: PathTrackingEnv, ckpt: Path) -> torch.nn.Module:
    """The deterministic policy of checkpoint `ckpt` (weights only): the PPO actor, a distillation run's student,
    or a residual run's actor on top of its controller (:class:`~pathrl.policy.residual.ResidualPolicy`)."""
    if not cfg.get("residual"):
        return _load_network(cfg, env, ckpt, env.get_observations())
    try:
        scale, spec = check_residual_cfg(cfg["residual"])
        controller = make_controller(spec, env)
    except ValueError as exc:
        raise RunError(f"{ckpt.parent}: {exc}") from None
    obs = env.get_observations()
    obs[BASE_GROUP] = torch.zeros(env.num_envs, env.num_actions)
    return ResidualPolicy(controller, _load_network(cfg, env, ckpt, obs), scale).eval()


def _load_network(cfg: dict[str, Any], env: PathTrackingEnv, ckpt: Path, obs: TensorDict) -> torch.nn.Module:
    """The policy network of checkpoint `ckpt`, built for observations like `obs`."""
    agent = cfg.get("agent") or {}
    role = policy_role(agent)
    spec = dict(agent.get(role) or {})
    cls = POLICY_MODELS.get(str(spec.pop("class_name", "")))
    if cls is None:
        raise RunError(f"agent.{role}.class_name: expected one of {sorted(POLICY_MODELS)}")
    groups = {role: list((agent.get("obs_groups") or {}).get(role) or ["policy"])}
    try:
        state = load_checkpoint(ckpt)
    except CheckpointError as exc:
        raise RunError(str(exc)) from None
    try:
        model = cls(obs, groups, role, env.num_actions, **spec)
        model.load_state_dict(_onto_robot(cfg, env, dict(state[f"{role}_state_dict"]), model))
    except (RuntimeError, KeyError, TypeError, LayoutError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise RunError(f"{ckpt}: the checkpoint does not fit the run's policy ({first[:200]})") from None
    return model.to(env.device).eval()


def _onto_robot(cfg: dict[str, Any], env: PathTrackingEnv, state: dict[str, torch.Tensor],
                model: torch.nn.Module) -> dict[str, torch.Tensor]:
    """`state` as is, or, for a policy trained on a robot with fewer joints and the same path joints than `env`'s
    (the fixed-base ARMAR-4 upper body on the standing robot), moved onto `env`'s joints: the extra joints' actions
    are 0 (:func:`pathrl.policy.widen.actor_for_joints`)."""
    src = list((cfg.get("robot") or {}).get("joints") or [])
    joints, path_joints = list(env.robot.joints), list((cfg.get("robot") or {}).get("path_joints") or [])
    if not src or src == joints:
        return state
    if path_joints != [joints[i] for i in env.path_index.tolist()]:
        raise LayoutError(f"the policy's path joints {path_joints} are not the env's")
    num_obs = int(model.state_dict()["mlp.0.weight"].shape[1])
    return actor_for_joints(state, src, joints, num_obs)


def make_controller(spec: dict, env: PathTrackingEnv) -> Any:
    """The model-based controller named by `spec` (``{"name": "tray", **settings}``,
    :data:`pathrl.baselines.controllers.CONTROLLERS`) for `env`; ValueError on a bad spec. A controller with a
    ``policy`` setting (a model directory; empty: none) gets that directory's policy network as its ``upper``,
    loaded once the controller has accepted `env`."""
    cls, cfg = controller_cfg(spec)
    controller = cls(env, cfg)
    if "policy" in cfg.__dataclass_fields__:
        controller.upper = _policy_of(cfg.policy, env, spec["name"])
    return controller


def _policy_of(run_dir: str, env: Any, name: str) -> torch.nn.Module | None:
    """The shipped policy network of `run_dir` (weights only), or None (`run_dir` empty)."""
    if not run_dir:
        return None
    cfg, ckpt, _ = load_run(Path(run_dir))
    if ckpt is None:
        raise ValueError(f"controller {name}: {run_dir} has no policy network")
    return load_policy(cfg, env, ckpt)
