"""A non-learned online path follower through the env's valid acceleration range: greedy progress per decision.

Every decision (0.1 s), per env (batched; every tensor is (N, ...)):

1. ``speeds`` candidate path speeds ``v_k`` from 0 to a cap: the fastest the joint velocity limits allow along
   the path tangent at the env's arc length s, and the fastest at which the path's curvature over the next
   ``lookahead`` rad needs at most ``curve_margin`` of the acceleration limits (|q_j''(s)| v^2 <= m a_j);
2. for each, the target at the end of the step is the path point ``s + v_k dt`` moving at ``v_k`` along the
   tangent; a critically damped tracking law (:func:`~pathrl.baselines.tracking.tracking_acceleration`, natural
   frequency ``track_omega``) gives the end-of-step acceleration, clipped into the valid range (so every limit holds,
   and braking stays possible, exactly as for a policy);
3. every candidate step is simulated with the env's own :func:`~pathrl.envs.tracking.advance` (the same
   integration, progress and deviation as the env's step), and the follower takes the candidate that moves
   furthest along the path among those whose step deviation (``dev_max``) stays within ``dev_bound``; if
   none does, the one with the smallest deviation.

Beyond the curvature cap it looks one step ahead: what learning adds over it is planning the speed along the
path (slowing down early enough, cutting a turn on purpose, accelerating out of it). It acts through
:meth:`~pathrl.envs.tracking.PathTrackingEnv.step` like a policy (``controller: {name: greedy}`` in a model
directory's config.yaml), so the env's end-of-path braking and every metric apply unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDict
from torch import Tensor

from pathrl.baselines.tracking import linear_action, tracking_acceleration
from pathrl.envs.tracking import PathTrackingEnv, advance

__all__ = ["GreedyCfg", "GreedyFollower"]


@dataclass(frozen=True)
class GreedyCfg:
    """Candidates, deviation bound (rad) and tracking frequency (rad/s) of :class:`GreedyFollower`."""

    speeds: int = 11
    dev_bound: float = 0.1
    track_omega: float = 15.0
    lookahead: float = 1.0  # rad of arc length whose curvature caps the speed
    curve_margin: float = 0.5  # share of the acceleration limits the curvature may use at the capped speed


class GreedyFollower:
    """The module docstring's follower for the envs of one :class:`PathTrackingEnv` (every joint on the path)."""

    def __init__(self, env: PathTrackingEnv, cfg: GreedyCfg | None = None):
        if len(env.path_index) != env.robot.dof:
            raise ValueError(f"GreedyFollower needs every joint on the path; {env.robot.name} has free joints")
        self.env, self.cfg = env, cfg or GreedyCfg()
        if self.cfg.speeds < 2:
            raise ValueError(f"GreedyFollower: speeds must be >= 2, got {self.cfg.speeds}")

    def accelerations(self) -> Tensor:
        """End-of-step accelerations (N, D) of the chosen candidates."""
        env, c = self.env, self.cfg
        n, d, k = env.num_envs, env.robot.dof, c.speeds
        dt, paths = env.cfg.dt, env.paths
        h = paths.table_step
        here = paths.position_at(env.seg_path, env.s)
        tangent = (paths.position_at(env.seg_path, env.s + h) - here) / h
        tangent = tangent / tangent.norm(dim=1, keepdim=True).clamp(min=1e-12)
        v_cap = (env.limits.vel / tangent.abs().clamp(min=1e-9)).amin(dim=1)  # (N,) rad/s along the path
        g = 5 * h  # curvature by central differences over 5 table steps
        ahead = env.s.unsqueeze(1) + torch.linspace(0.0, c.lookahead, 21, dtype=torch.float64, device=env.device)
        curv = (paths.position_at(env.seg_path, ahead + g) - 2 * paths.position_at(env.seg_path, ahead)
                + paths.position_at(env.seg_path, ahead - g)) / g**2  # (N, 21, M)
        v_curve = (c.curve_margin * env.limits.acc / curv.abs().clamp(min=1e-9)).sqrt().amin(dim=(1, 2))
        v_cap = torch.minimum(v_cap, v_curve)
        frac = torch.linspace(0.0, 1.0, k, dtype=torch.float64, device=env.device)
        speed = v_cap.unsqueeze(1) * frac  # (N, K)
        rows = lambda x: x.repeat_interleave(k, dim=0)  # noqa: E731
        s_target = (env.s.unsqueeze(1) + speed * dt).minimum(env.end_s.unsqueeze(1))
        q_d = paths.position_at(env.seg_path, s_target).reshape(n * k, d)
        v_d = (tangent.unsqueeze(1) * speed.unsqueeze(2)).reshape(n * k, d)
        a1 = tracking_acceleration(rows(env.pos), rows(env.vel), rows(env.acc), q_d, v_d, torch.zeros_like(v_d), dt,
                                   c.track_omega)
        a1 = torch.minimum(torch.maximum(a1, rows(env.a_min)), rows(env.a_max))
        _, _, moved, dev_max, _ = advance(rows(env.pos), rows(env.vel), rows(env.acc), a1, env.path_index,
                                          rows(env.s), rows(env.end_s), rows(env.seg_path), paths.table,
                                          paths.length, env.dev_weights, dt, env.cfg.substeps, h)
        moved, dev_max = moved.view(n, k), dev_max.view(n, k)
        ok = dev_max <= c.dev_bound
        score = torch.where(ok, moved, -dev_max - 1e6)  # within the bound: progress; else: least deviation
        best = score.argmax(dim=1)
        return a1.view(n, k, d)[torch.arange(n, device=env.device), best]

    def __call__(self, obs: TensorDict) -> Tensor:
        """Actions (N, D) in [-1, 1] for the env's current state (the env's linear action mapping inverted)."""
        env = self.env
        return linear_action(self.accelerations(), env.a_min, env.a_max).to(torch.float32)
