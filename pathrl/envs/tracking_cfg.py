"""Settings of the path-tracking env (:class:`pathrl.envs.tracking.PathTrackingEnv`), defined once.

:class:`EnvSettings` is the ``env`` config group: the Hydra schema of ``conf/env/*.yaml`` (registered by
:mod:`pathrl.cli.store`) and, read back with :meth:`EnvSettings.from_mapping`, the typed settings at run time. Its
defaults are the only ones; ``conf/env/tracking.yaml`` sets only the values training uses differently.
:class:`TrackingEnvCfg` adds what the env takes from the rest of a run config (device, seed, ``knots.n_state``,
``task.observe`` / ``task.fail_terminates``) and from the caller (``knot_gap_norm``, ``autoreset``, ``limit_backend``);
:meth:`TrackingEnvCfg.from_run` builds it from a resolved run config (saved runs through
:func:`pathrl.config.migrate.migrate`). No Hydra here.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from pathrl.limits.backend import LimitBackend

__all__ = ["FREE_JOINT_ACTIONS", "EnvSettings", "TrackingEnvCfg"]


FREE_JOINT_ACTIONS = ("centred", "posture", "linear")


@dataclass(frozen=True)
class EnvSettings:
    """The ``env`` config group (``conf/env/*.yaml``)."""

    num_envs: int = 4096
    dt: float = 0.1  # decision step (s)
    control_rate: float = 240.0  # setpoints per second (24 per step), used by backends and evaluation
    substeps: int = 8  # intermediate positions per step for progress and deviation
    episode_budget_s: float = 16.0  # time budget for a whole path (s)
    scale_budget: bool = True  # scale the budget by the fraction of the path in the segment
    segments: str = "paper"  # training segments: paper (random sub-segments) | full
    start_range: tuple[float, float] = (0.0, 0.8)  # paper segments: start within this fraction of the path
    min_fraction: float = 0.2  # paper segments: shortest segment as a fraction of the path
    max_deviation: float | None = None  # terminate if a step's max deviation exceeds this (rad)
    stop_tolerance: float = 0.01  # |v| and |a| below this count as stopped
    stop_bonus: bool = True
    knot_obs: str = "relative"  # knots as seen from the robot (relative) or in joint space (absolute, paper)
    end_obs: bool = False  # add the vector to the end knot and the arc length left, both at knot-gap scale
    end_tolerance: float | None = None  # also reached: within this (weighted, rad) of the end knot, < D arc left
    free_joint_actions: str = "centred"  # joints outside the path: centred (0 holds) | posture | linear (paper)
    posture_omega: float = 3.0  # free_joint_actions=posture: natural frequency of the pull to the start posture (rad/s)
    tcp_obs: bool = False  # + per TCP the reference position at s and reference - commanded (the authors' ball state)
    tcp_obs_box: tuple[float, ...] = (-1.0, 1.0, -1.0, 1.0, -0.7, 1.3)  # x, y, z ranges (m) -> [-1, 1]
    tcp_obs_error: float = 0.1  # reference - commanded TCP (m) that maps to 1
    error_obs: bool = False  # + per path joint the reference at s minus the commanded position (the tracking error)
    error_obs_scale: float = 0.1  # tracking error (rad) that maps to 1

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], **extra: Any):
        """The settings of a mapping (a resolved or saved ``env`` group), each value converted to its field's type
        (lists to tuples, ints to floats); missing keys take the defaults, `extra` adds or replaces fields;
        ValueError naming an unknown key or a bad value."""
        hints = typing.get_type_hints(cls)
        names = {f.name for f in dataclasses.fields(cls)}
        merged = {**values, **extra}
        unknown = sorted(set(merged) - names)
        if unknown:
            raise ValueError(f"env: unknown keys {unknown}; valid: {sorted(names)}")
        return cls(**{k: _convert(k, v, hints[k]) for k, v in merged.items()})

    def __post_init__(self) -> None:
        """Refuse values that would run but give a wrong result (one-line ValueError naming the key)."""
        for key in ("num_envs", "substeps"):
            if int(getattr(self, key)) < 1:
                raise ValueError(f"env.{key} must be >= 1, got {getattr(self, key)}")
        for key in ("dt", "control_rate", "episode_budget_s", "posture_omega", "stop_tolerance", "error_obs_scale"):
            if not float(getattr(self, key)) > 0.0:  # also refuses NaN
                raise ValueError(f"env.{key} must be > 0, got {getattr(self, key)}")
        for key, allowed in (("segments", ("paper", "full")), ("knot_obs", ("relative", "absolute")),
                             ("free_joint_actions", FREE_JOINT_ACTIONS)):
            if getattr(self, key) not in allowed:
                raise ValueError(f"env.{key} must be one of {', '.join(allowed)}; got {getattr(self, key)!r}")
        lo, hi = (float(x) for x in self.start_range)
        if not 0.0 <= lo <= hi < 1.0 or not 0.0 < self.min_fraction <= 1.0:
            raise ValueError(f"env.start_range must be 0 <= lo <= hi < 1 and env.min_fraction in (0, 1]; got "
                             f"{list(self.start_range)}, {self.min_fraction}")
        for key in ("max_deviation", "end_tolerance"):
            v = getattr(self, key)
            if v is not None and not float(v) > 0.0:
                raise ValueError(f"env.{key} must be > 0 or null, got {v}")


@dataclass(frozen=True)
class TrackingEnvCfg(EnvSettings):
    """Everything :class:`~pathrl.envs.tracking.PathTrackingEnv` is built with: the ``env`` group plus the values
    from elsewhere in the run config and from the caller."""

    device: str = "cpu"
    seed: int = 0
    knot_gap_norm: float | None = None  # D (rad); default: the path set's largest knot gap
    n_state: int = 9  # knots in the observation (knots.n_state)
    feedback_obs: bool = True  # with a feedback source: its sensor values are part of the state (task.observe)
    fail_terminates: bool = True  # with a feedback source: its failure (ball off the plate) ends the episode
    critic_obs: bool = False  # the observation also holds the privileged group "critic" (task.critic_obs)
    autoreset: bool = True
    #: the limit code of this env's steps (pathrl.limits.backend); None: the one in effect at each call (training:
    #: the run's native_limits / compile_limits around its iterations; evaluation: its compile_limits flag)
    limit_backend: LimitBackend | None = None

    @classmethod
    def from_run(cls, cfg: Mapping[str, Any], num_envs: int | None = None, seed: int | None = None,
                 knot_gap_norm: float | None = None) -> TrackingEnvCfg:
        """The env settings of a resolved or saved run config (brought up to date by
        :func:`pathrl.config.migrate.migrate`); `num_envs`, `seed`, `knot_gap_norm` replace the config's."""
        from pathrl.config.migrate import migrate

        cfg = migrate(cfg)
        task = cfg["task"]
        extra = {"device": str(cfg.get("device", "cpu")), "seed": int(cfg.get("seed", 0) if seed is None else seed),
                 "knot_gap_norm": knot_gap_norm, "n_state": int(cfg["knots"]["n_state"]),
                 "feedback_obs": bool(task["observe"]), "fail_terminates": bool(task["fail_terminates"]),
                 "critic_obs": bool(task.get("critic_obs", False))}
        if num_envs:
            extra["num_envs"] = int(num_envs)
        return cls.from_mapping(cfg["env"], **extra)

    def __post_init__(self) -> None:
        super().__post_init__()
        if int(self.n_state) < 1:
            raise ValueError(f"env.n_state must be >= 1, got {self.n_state}")
        if self.knot_gap_norm is not None and not float(self.knot_gap_norm) > 0.0:
            raise ValueError(f"env.knot_gap_norm must be > 0 or null, got {self.knot_gap_norm}")
        if self.limit_backend is not None and not isinstance(self.limit_backend, LimitBackend):
            raise ValueError(f"env limit_backend must be a LimitBackend or None, got {self.limit_backend!r}")


def _convert(key: str, value: Any, tp: Any) -> Any:
    """`value` as type `tp` (a field type of :class:`EnvSettings` / :class:`TrackingEnvCfg`)."""
    args = typing.get_args(tp)
    if value is None:
        if type(None) in args:
            return None
        raise ValueError(f"env.{key}: null is not allowed")
    if type(None) in args:  # X | None
        tp = next(a for a in args if a is not type(None))
    if tp is LimitBackend:
        return value  # checked by TrackingEnvCfg
    try:
        if typing.get_origin(tp) is tuple:
            return tuple(float(x) for x in value)
        if tp is bool:
            if not isinstance(value, bool):
                raise TypeError
            return value
        return tp(value)
    except (TypeError, ValueError):
        raise ValueError(f"env.{key}: expected {getattr(tp, '__name__', tp)}, got {value!r}") from None
