"""Settings of the path-tracking env (:class:`pathrl.envs.tracking.PathTrackingEnv`; ``conf/env/*.yaml``)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FREE_JOINT_ACTIONS", "TrackingEnvCfg"]


FREE_JOINT_ACTIONS = ("centred", "posture", "linear")


@dataclass(frozen=True)
class TrackingEnvCfg:
    """Environment settings (``conf/env/*.yaml``)."""

    num_envs: int = 4096
    device: str = "cpu"
    seed: int = 0
    dt: float = 0.1  # decision step (s)
    control_rate: float = 240.0  # setpoints per second (24 per step), used by backends and evaluation
    substeps: int = 8  # intermediate positions per step for progress and deviation
    episode_budget_s: float = 16.0  # time budget for a whole path (s)
    scale_budget: bool = True  # scale the budget by the fraction of the path in the segment
    segments: str = "paper"  # training segments: paper | full
    start_range: tuple[float, float] = (0.0, 0.8)
    min_fraction: float = 0.2
    max_deviation: float | None = None  # terminate if a step's max deviation exceeds this (rad)
    stop_tolerance: float = 0.01  # |v| and |a| below this count as stopped
    stop_bonus: bool = True
    knot_gap_norm: float | None = None  # D (rad); default: the path set's largest knot gap
    n_state: int = 9  # knots in the observation
    knot_obs: str = "relative"  # knots as seen from the robot (relative) or in joint space (absolute, paper)
    end_obs: bool = False  # add the vector to the end knot and the arc length left, both at knot-gap scale
    end_tolerance: float | None = None  # also reached: within this (weighted, rad) of the end knot, < D arc left
    feedback_obs: bool = True  # with a feedback source: its sensor values are part of the state
    tcp_obs: bool = False  # + per TCP the reference position at s and reference - commanded (the authors' ball state)
    tcp_obs_box: tuple[float, ...] = (-1.0, 1.0, -1.0, 1.0, -0.7, 1.3)  # x, y, z ranges (m) -> [-1, 1]
    tcp_obs_error: float = 0.1  # reference - commanded TCP (m) that maps to 1
    fail_terminates: bool = True  # with a feedback source: its failure (ball off the plate) ends the episode
    free_joint_actions: str = "centred"  # joints outside the path: centred (0 holds) | posture | linear (paper)
    posture_omega: float = 3.0  # free_joint_actions=posture: natural frequency of the pull to the start posture (rad/s)
    autoreset: bool = True

    def __post_init__(self) -> None:
        """Refuse values that would run but give a wrong result (one-line ValueError naming the key)."""
        for key in ("num_envs", "substeps", "n_state"):
            if int(getattr(self, key)) < 1:
                raise ValueError(f"env.{key} must be >= 1, got {getattr(self, key)}")
        for key in ("dt", "control_rate", "episode_budget_s", "posture_omega", "stop_tolerance"):
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
        for key in ("max_deviation", "end_tolerance", "knot_gap_norm"):
            v = getattr(self, key)
            if v is not None and not float(v) > 0.0:
                raise ValueError(f"env.{key} must be > 0 or null, got {v}")

