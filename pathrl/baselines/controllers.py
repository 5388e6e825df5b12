"""Model-based controllers that evaluate like a policy: ``controller: {name: ..., <cfg keys>}`` in a model directory's
config.yaml (``models/iiwa7_ball_tray_controller``), or ``teacher: {...}`` of a distillation run."""

from __future__ import annotations

from pathrl.baselines.ball_feedback import TrayController, TrayControllerCfg
from pathrl.baselines.greedy_follower import GreedyCfg, GreedyFollower
from pathrl.envs.tracking import PathTrackingEnv

CONTROLLERS = {"tray": (TrayController, TrayControllerCfg), "greedy": (GreedyFollower, GreedyCfg)}


def make_controller(spec: dict, env: PathTrackingEnv) -> TrayController | GreedyFollower:
    """The controller named by `spec` (``{"name": "tray", **gains}``) for `env`; ValueError on a bad spec."""
    if not isinstance(spec, dict) or spec.get("name") not in CONTROLLERS:
        name = spec.get("name") if isinstance(spec, dict) else spec
        raise ValueError(f"controller: unknown name {name!r}; known: {sorted(CONTROLLERS)}")
    cls, cfg_cls = CONTROLLERS[spec["name"]]
    keys = {k: v for k, v in spec.items() if k != "name"}
    known = set(cfg_cls.__dataclass_fields__)
    unknown = sorted(set(keys) - known)
    if unknown:
        raise ValueError(f"controller {spec['name']}: unknown keys {unknown}; known: {sorted(known)}")
    bad = [k for k, v in keys.items() if isinstance(v, bool) or not isinstance(v, int | float)]
    if bad:
        raise ValueError(f"controller {spec['name']}: {bad} must be numbers")
    return cls(env, cfg_cls(**keys))
