"""Model-based controllers that evaluate like a policy: ``controller: {name: ..., <cfg keys>}`` in a model directory's
config.yaml (``models/tracking/iiwa7_ball_tray_controller``), or ``teacher: {...}`` of a distillation run. The
registry and the check of a spec are here; :func:`pathrl.runs.make_controller` builds one (and loads a policy network
it drives)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from torch import Tensor

from pathrl.baselines.balance import BalanceCfg, BalanceController
from pathrl.baselines.ball_feedback import TrayController, TrayControllerCfg
from pathrl.baselines.greedy_follower import GreedyCfg, GreedyFollower
from pathrl.baselines.law_tracker import LawTracker, LawTrackerCfg
from pathrl.baselines.trueadapt_tray import AdaptTrayCfg, AdaptTrayController

__all__ = ["CONTROLLERS", "ReferenceReplay", "ReferenceReplayCfg", "controller_cfg"]


@dataclass(frozen=True)
class ReferenceReplayCfg:
    """No settings: the reference trajectory's own accelerations."""


class ReferenceReplay:
    """TrueAdapt's reference without adaptation as a controller: the actions (N, D) that replay each env's reference
    trajectory (:meth:`pathrl.envs.trueadapt.TrueAdaptEnv.reference_actions`); the base of a residual policy there."""

    def __init__(self, env: Any, cfg: ReferenceReplayCfg | None = None):
        if not hasattr(env, "reference_actions"):
            raise ValueError("controller reference: needs a trajectory-adaptation env (task=trueadapt_*)")
        self.env = env

    def __call__(self, obs: Any) -> Tensor:
        return self.env.reference_actions()


CONTROLLERS = {"tray": (TrayController, TrayControllerCfg), "greedy": (GreedyFollower, GreedyCfg),
               "reference": (ReferenceReplay, ReferenceReplayCfg), "balance": (BalanceController, BalanceCfg),
               "trueadapt_tray": (AdaptTrayController, AdaptTrayCfg),
               "law_tracker": (LawTracker, LawTrackerCfg)}


def controller_cfg(spec: dict) -> tuple[type, Any]:
    """The controller class named by `spec` (``{"name": "tray", **gains}``) and its settings; ValueError on a bad
    spec (unknown name or keys, a number given as text or the other way round)."""
    if not isinstance(spec, dict) or spec.get("name") not in CONTROLLERS:
        name = spec.get("name") if isinstance(spec, dict) else spec
        raise ValueError(f"controller: unknown name {name!r}; known: {sorted(CONTROLLERS)}")
    cls, cfg_cls = CONTROLLERS[spec["name"]]
    keys = {k: v for k, v in spec.items() if k != "name"}
    known = set(cfg_cls.__dataclass_fields__)
    unknown = sorted(set(keys) - known)
    if unknown:
        raise ValueError(f"controller {spec['name']}: unknown keys {unknown}; known: {sorted(known)}")
    text = {k for k, f in cfg_cls.__dataclass_fields__.items() if isinstance(f.default, str)}  # e.g. a model dir
    bad = [k for k, v in keys.items()
           if (not isinstance(v, str) if k in text else isinstance(v, bool) or not isinstance(v, int | float))]
    if bad:
        raise ValueError(f"controller {spec['name']}: {bad} must be numbers (text: {sorted(text)})")
    return cls, cfg_cls(**keys)
