"""Saved run configs (``config.yaml`` of runs and ``models/``) brought up to the current layout, in one place.

Every config written by ``pathrl-train`` carries ``config_version`` (:data:`CONFIG_VERSION`); configs saved before
the key existed are version 0. :func:`migrate` applies the steps from a config's version to the current one, so
that the rest of the code reads every config with all keys present. A step only adds keys, with the value that
reproduces what the old runs did (their behaviour is the behaviour of the code at the time they were trained).

No Hydra here (the env package reads configs through this module).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["ADDED_IN_V2", "ADDED_IN_V3", "ADDED_IN_V4", "ADDED_KEYS", "CONFIG_VERSION", "NO_TASK", "config_version",
           "migrate"]

#: Version of the config layout written by this code.
CONFIG_VERSION = 4

#: The task of configs saved before tasks existed (plain path tracking).
NO_TASK: dict[str, Any] = {"name": "tracking", "feedback": None, "backend": "analytic", "workers": 2,
                           "observe": True, "fail_terminates": True, "imu": False}

#: Keys added to the layout while it was version 0, with the value that reproduces what runs saved without them
#: did (``group.key``: filled in when the group exists; top-level keys always).
ADDED_KEYS: dict[str, Any] = {
    "dataset.out_of_limits": "refuse",
    "env.knot_obs": "relative",
    "env.end_obs": False,
    "env.end_tolerance": None,
    "env.free_joint_actions": "linear",
    "env.posture_omega": 3.0,
    "env.tcp_obs": False,
    "env.tcp_obs_box": [-1.0, 1.0, -1.0, 1.0, -0.7, 1.3],
    "env.tcp_obs_error": 0.1,
    "task.imu": False,
    "task.adapt": {},
    "init_from": None,
    "float32_from": None,
    "teacher": {},
    "residual": {},
    "critic_warmup": {"iterations": 0, "learning_rate": None},
    "native_limits": True,  # the native limit code where available, as every run before the key (pathrl.limits.backend)
}


#: Keys added in version 2 (the same convention as :data:`ADDED_KEYS`).
ADDED_IN_V2: dict[str, Any] = {
    "env.error_obs": False,
    "env.error_obs_scale": 0.1,
    "bias_search": {},
}

#: Keys added in version 3.
ADDED_IN_V3: dict[str, Any] = {
    "lr_decay": {"final": None, "start": 0.0},
}

#: Keys added in version 4.
ADDED_IN_V4: dict[str, Any] = {
    "critic_warmup.freeze_normalizer": False,
}


def config_version(cfg: Mapping[str, Any]) -> int:
    """The layout version of a config (0: saved before ``config_version`` existed); ValueError for a version this
    code does not know (a config from newer code)."""
    version = cfg.get("config_version", 0)
    if not isinstance(version, int) or isinstance(version, bool) or not 0 <= version <= CONFIG_VERSION:
        raise ValueError(f"config_version: expected an integer 0..{CONFIG_VERSION}, got {version!r} "
                         "(a config written by a newer pathrl?)")
    return version


def _v0_to_v1(cfg: dict[str, Any]) -> None:
    """Version 0 -> 1: the task group of configs from before tasks, and every key of :data:`ADDED_KEYS`."""
    cfg["task"] = {**NO_TASK, **(cfg.get("task") or {})}
    if "critic_warmup" in cfg and not cfg["critic_warmup"]:  # its first form, ``critic_warmup: 0``: no warm-up
        del cfg["critic_warmup"]
    _fill(cfg, ADDED_KEYS)


def _v1_to_v2(cfg: dict[str, Any]) -> None:
    """Version 1 -> 2: the keys of :data:`ADDED_IN_V2` (the joint tracking error observation off, no bias search)."""
    _fill(cfg, ADDED_IN_V2)


def _v2_to_v3(cfg: dict[str, Any]) -> None:
    """Version 2 -> 3: the keys of :data:`ADDED_IN_V3` (a constant learning rate)."""
    _fill(cfg, ADDED_IN_V3)


def _v3_to_v4(cfg: dict[str, Any]) -> None:
    """Version 3 -> 4: the keys of :data:`ADDED_IN_V4` (the actor's observation normaliser keeps learning)."""
    _fill(cfg, ADDED_IN_V4)


def _fill(cfg: dict[str, Any], added: Mapping[str, Any]) -> None:
    """Each ``group.key`` of `added` missing from `cfg` set to its value (when the group exists; top level always)."""
    for dotted, value in added.items():
        group, _, key = dotted.rpartition(".")
        target = cfg.get(group) if group else cfg
        if isinstance(target, dict) and key not in target:
            target[key] = copy.deepcopy(value)


#: Step ``k`` brings a version-``k`` config to version ``k + 1`` (in place).
STEPS: tuple[Callable[[dict[str, Any]], None], ...] = (_v0_to_v1, _v1_to_v2, _v2_to_v3, _v3_to_v4)


def migrate(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of a resolved or saved run config in the current layout (:data:`CONFIG_VERSION`); a current config
    comes back equal. ValueError for a config from newer code."""
    version = config_version(cfg)
    out = copy.deepcopy(dict(cfg))
    for step in STEPS[version:]:
        step(out)
    out["config_version"] = CONFIG_VERSION
    return out
