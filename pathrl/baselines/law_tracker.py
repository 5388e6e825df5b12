"""A model-based path tracker: each whole path's time-optimal law (toppra), smoothed, tracked by a PD law.

Per path of the env's :class:`~pathrl.paths.pathset.PathSet`, once: the time-optimal law along the path from
rest to rest under ``limit_margin`` of the joint velocity and acceleration limits, its path velocity averaged
over ``smooth_s`` seconds so the acceleration turns at a bounded rate (toppra's is bang-bang: unbounded jerk),
tabulated as arc length against time (:func:`pathrl.baselines.tray_time_law.build_time_laws` without a plate).

Per decision (batched, float64; every tensor is (N, ...)): the law's time at the env's arc length (a Markov
lookup, so the controller needs no clock), the law's position, velocity and acceleration one decision later,
and the critically damped tracking law (:func:`~pathrl.baselines.tracking.tracking_acceleration`, natural
frequency ``track_omega``) mapped to the env's action. The valid acceleration range keeps every limit and the
env's braking law takes over at the path end, as for a learned policy.

It sees the whole path, so it is a teacher (``teacher: {name: law_tracker}`` of a distillation run) and a
baseline that shows what the paper's state and reward leave on the table, not a policy with the paper's
inputs. Episodes must follow whole paths (``segments: full``): a law starts at rest at the path's start.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDict
from torch import Tensor

from pathrl.baselines.tracking import linear_action, tracking_acceleration
from pathrl.baselines.tray_time_law import TimeLawCfg, build_time_laws
from pathrl.envs.tracking import PathTrackingEnv

__all__ = ["LawTracker", "LawTrackerCfg"]


@dataclass(frozen=True)
class LawTrackerCfg:
    """Settings of :class:`LawTracker` (share of the limits, s, rad/s, rad)."""

    limit_margin: float = 0.95  # share of the joint velocity and acceleration limits the law uses
    smooth_s: float = 0.3  # s, moving average of the law's path velocity (bounds its jerk)
    track_omega: float = 10.0  # rad/s, natural frequency of the tracking law
    grid_step: float = 0.02  # rad of arc length between toppra gridpoints
    fd_s: float = 0.01  # s, time step of the finite differences for the law's velocity and acceleration


class LawTracker:
    """The module docstring's tracker for the envs of one :class:`PathTrackingEnv` (every joint on the path)."""

    def __init__(self, env: PathTrackingEnv, cfg: LawTrackerCfg | None = None):
        if len(env.path_index) != env.robot.dof:
            raise ValueError(f"LawTracker needs every joint on the path; {env.robot.name} has free joints")
        if env.cfg.segments != "full":
            raise ValueError("LawTracker follows whole paths from rest; set env.segments=full")
        self.env, self.cfg = env, cfg or LawTrackerCfg()
        law = TimeLawCfg(limit_margin=self.cfg.limit_margin, smooth_s=self.cfg.smooth_s, grid_step=self.cfg.grid_step)
        idx = env.path_index
        self.laws = build_time_laws(env.paths, env.limits.vel[idx], env.limits.acc[idx], None, law)
        h = self.cfg.fd_s
        self._offsets = torch.tensor([-h, 0.0, h], dtype=torch.float64, device=env.device)

    def target(self) -> tuple[Tensor, Tensor, Tensor]:
        """The law's position, velocity and acceleration (N, D) one decision after the env's arc length."""
        env, h = self.env, self.cfg.fd_s
        if bool((env.start_s > 1e-9).any()):
            raise ValueError("LawTracker follows whole paths from rest; an episode starts inside its path")
        n = env.num_envs
        t = self.laws.time_at(env.seg_path, env.s) + env.cfg.dt
        s = self.laws.arc_at(env.seg_path, t.unsqueeze(1) + self._offsets)  # (N, 3)
        q = env.paths.position_at(env.seg_path.repeat_interleave(3), s.reshape(-1)).reshape(n, 3, -1)
        return q[:, 1], (q[:, 2] - q[:, 0]) / (2 * h), (q[:, 2] - 2 * q[:, 1] + q[:, 0]) / h**2

    def __call__(self, obs: TensorDict) -> Tensor:
        """Actions (N, D) in [-1, 1] for the env's current state (the env's linear action mapping inverted)."""
        env = self.env
        q_d, v_d, a_d = self.target()
        a1 = tracking_acceleration(env.pos, env.vel, env.acc, q_d, v_d, a_d, env.cfg.dt, self.cfg.track_omega)
        return linear_action(a1, env.a_min, env.a_max).to(torch.float32)
