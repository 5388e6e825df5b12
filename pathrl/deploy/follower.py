"""Run a trained path-tracking policy in a robot's control loop: one robot, numpy in and out, no Hydra.

    follower = Follower.load("models/iiwa7_random")
    follower.reset(knots)                   # (K, M) path knots; the robot is at rest at the first knot
    while not follower.done:
        sp = follower.decide()              # Setpoints for the next 0.1 s, 24 at 240 Hz
        robot.send(sp.position, sp.velocity)
    follower.replace_path(new_knots)        # mid-motion: the robot keeps its state, the path changes
    follower.stop()                         # from the next decision on: brake to rest within every limit

A follower is a one-env :class:`~pathrl.envs.tracking.PathTrackingEnv` stepped by the policy: the same valid
acceleration range (every limit holds at every setpoint, braking stays possible), the same integration, the
same end-of-path braking as in training and evaluation. There is no second implementation of the step.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

from pathrl.envs.registry import EVAL_ENV, get_task
from pathrl.envs.rewards import build_reward_terms
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.eval.evaluate import load_policy, load_run
from pathrl.limits.braking import is_stopped
from pathrl.limits.integrate import interpolate_step
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.pathset import PathSet, build_pathset
from pathrl.paths.segments import full_segments
from pathrl.robot.model import RobotSpec, load_robot

__all__ = ["START_TOLERANCE", "Follower", "FollowerError", "Setpoints"]


#: Largest weighted joint distance (rad) between the robot and the start of a path it is asked to follow.
START_TOLERANCE = 0.05


class FollowerError(ValueError):
    """A path, state or model the follower cannot take (one line)."""


@dataclass(frozen=True)
class Setpoints:
    """One decision's setpoints at the control rate: position, velocity, acceleration, each (C, D) (rad, rad/s,
    rad/s^2), at t = dt k / C, k = 1..C after the decision."""

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray


class Follower:
    """A shipped policy following one path at a time (module docstring)."""

    def __init__(self, cfg: dict, checkpoint: Path, knot_gap: float, robot: RobotSpec):
        try:
            feedback = get_task(cfg).feedback
        except ValueError as exc:
            raise FollowerError(str(exc)) from None
        if feedback is not None:
            raise FollowerError(f"the follower runs path-tracking policies; this one needs the {feedback} sensor")
        self.robot, self.cfg, self.checkpoint = robot, cfg, checkpoint
        self.knots = KnotStrategy.from_cfg(cfg["knots"])
        self.env_cfg = replace(TrackingEnvCfg.from_run(cfg, num_envs=1, seed=0, knot_gap_norm=knot_gap), **EVAL_ENV)
        self.env: PathTrackingEnv | None = None
        self.policy: torch.nn.Module | None = None
        self._stopping = False
        steps = round(self.env_cfg.control_rate * self.env_cfg.dt)
        self.setpoints_per_decision = int(steps)

    @classmethod
    def load(cls, model_dir: str | os.PathLike) -> Follower:
        """The policy of a model or run directory (``config.yaml`` + ``model.pt``, loaded weights only)."""
        from pathrl.eval.evaluate import RunError

        try:
            cfg, ckpt, summary = load_run(Path(model_dir))
        except RunError as exc:
            raise FollowerError(str(exc)) from None
        if ckpt is None:
            raise FollowerError(f"{model_dir}: a model-based controller, not a policy")
        if "knot_gap_norm" not in summary:
            raise FollowerError(f"{model_dir}/summary.json: no knot_gap_norm (the state's length scale)")
        return cls(cfg, ckpt, float(summary["knot_gap_norm"]), load_robot(cfg["robot"]))

    # ------------------------------------------------------------------ paths
    def _pathset(self, knots: np.ndarray) -> PathSet:
        knots = np.asarray(knots, dtype=np.float64)
        m = self.robot.path_dof
        if knots.ndim != 2 or knots.shape[1] != m or len(knots) < 2:
            raise FollowerError(f"path knots must be (K >= 2, {m}), got {knots.shape}")
        if not np.isfinite(knots).all():
            raise FollowerError("path knots must be finite")
        return build_pathset([self.knots.apply(knots)], ["path"])

    def reset(self, knots: np.ndarray, q: np.ndarray | None = None) -> None:
        """Start following the path through `knots` (K, M) from rest at its first knot. `q` (D,), if given, is
        the robot's position: it must be within START_TOLERANCE of the first knot (path joints)."""
        paths = self._pathset(knots)
        if self.env is None:
            terms = build_reward_terms(self.cfg["reward"]["terms"])
            self.env = PathTrackingEnv(self.env_cfg, self.robot, paths, terms)
            self.policy = load_policy(self.cfg, self.env, self.checkpoint)
        else:
            self.env.set_paths(paths)
        first = torch.zeros(1, dtype=torch.long)
        self.env.start_segments(first, full_segments(paths, first))
        if q is not None:
            gap = self._distance(np.asarray(q, dtype=np.float64), self.env.pos[0].numpy())
            if gap > START_TOLERANCE:
                raise FollowerError(f"the robot is {gap:.3f} rad from the path's first knot (at most "
                                    f"{START_TOLERANCE}); start the path where the robot is")
        self._stopping = False

    def replace_path(self, knots: np.ndarray) -> float:
        """Follow the path through `knots` (K, M) from now on, from its point nearest to the robot; the robot
        keeps its position, velocity and acceleration. Returns that point's distance from the robot (rad)."""
        env = self._env()
        paths = self._pathset(knots)
        q = env.pos[0, env.path_index]
        near = (paths.table[0] - q).norm(dim=1)
        j = int(near[: int(torch.ceil(paths.length[0] / paths.table_step)) + 1].argmin())
        s = min(j * paths.table_step, float(paths.length[0]))
        env.set_paths(paths)
        env.replace_path(torch.zeros(1, dtype=torch.long), torch.zeros(1, dtype=torch.long),
                         torch.tensor([s], dtype=torch.float64))
        self._stopping = False
        return float(near[j])

    # ------------------------------------------------------------------ control
    def decide(self) -> Setpoints:
        """The next decision: the policy's action (the braking law once the path end is reached or after
        :meth:`stop`) as setpoints at the control rate."""
        env = self._env()
        p0, v0, a0 = env.pos.clone(), env.vel.clone(), env.acc.clone()
        with torch.inference_mode():
            action = self.policy(env.get_observations())
        env.step(action)
        p, v, a = interpolate_step(p0, v0, a0, env.acc, env.cfg.dt, self.setpoints_per_decision)
        return Setpoints(p[0].numpy(), v[0].numpy(), a[0].numpy())

    def stop(self) -> None:
        """Brake to rest from the next decision on (the env's braking law: every limit, jerk included)."""
        env = self._env()
        env.braking[:] = True
        self._stopping = True

    @property
    def done(self) -> bool:
        """At rest after the path's end or a :meth:`stop`."""
        env = self._env()
        return bool(env.braking[0]) and bool(is_stopped(env.vel, env.acc, env.cfg.stop_tolerance)[0])

    @property
    def state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Commanded position, velocity and acceleration (D,) at the last decision."""
        env = self._env()
        return env.pos[0].numpy().copy(), env.vel[0].numpy().copy(), env.acc[0].numpy().copy()

    @property
    def path_left(self) -> float:
        """Arc length (rad) from the follower's path position to the path's end."""
        env = self._env()
        return float(env.end_s[0] - env.s[0])

    def _env(self) -> PathTrackingEnv:
        if self.env is None:
            raise FollowerError("call reset(knots) first")
        return self.env

    def _distance(self, q: np.ndarray, start: np.ndarray) -> float:
        if q.shape != start.shape:
            raise FollowerError(f"q must have {start.shape[0]} joints, got {q.shape}")
        idx = self.env.path_index.numpy()
        return float(np.linalg.norm(q[idx] - start[idx]))
