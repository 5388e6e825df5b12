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

from pathrl.dataset.io import OUT_OF_LIMITS
from pathrl.envs.registry import EVAL_ENV, get_task
from pathrl.envs.rewards import build_reward_terms
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.eval.evaluate import load_policy, load_run
from pathrl.limits.braking import is_stopped
from pathrl.limits.integrate import interpolate_step
from pathrl.paths.inside import INSIDE_TOL, PathOutsideError, clip_spline_into, table_excess
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
    """A shipped policy following one path at a time (module docstring).

    A path that leaves the robot's position range (at a knot or on the spline between knots) is refused with a
    :class:`FollowerError` (``out_of_limits="refuse"``, the default) or clipped into it (``"clip"``: the knots are
    moved until the whole spline is inside). Every error of the follower is a :class:`FollowerError`; a failed
    :meth:`reset` or :meth:`replace_path` leaves the follower as it was.
    """

    def __init__(self, cfg: dict, checkpoint: Path, knot_gap: float, robot: RobotSpec, out_of_limits: str = "refuse"):
        if out_of_limits not in OUT_OF_LIMITS:
            raise FollowerError(f"out_of_limits must be one of {list(OUT_OF_LIMITS)}, got {out_of_limits!r}")
        try:
            feedback = get_task(cfg).feedback
        except ValueError as exc:
            raise FollowerError(str(exc)) from None
        if feedback is not None:
            raise FollowerError(f"the follower runs path-tracking policies; this one needs the {feedback} sensor")
        self.robot, self.cfg, self.checkpoint, self.out_of_limits = robot, cfg, checkpoint, out_of_limits
        self.knots = KnotStrategy.from_cfg(cfg["knots"])
        self.env_cfg = replace(TrackingEnvCfg.from_run(cfg, num_envs=1, seed=0, knot_gap_norm=knot_gap), **EVAL_ENV)
        self.env: PathTrackingEnv | None = None
        self.policy: torch.nn.Module | None = None
        self._stopping = False
        steps = round(self.env_cfg.control_rate * self.env_cfg.dt)
        self.setpoints_per_decision = int(steps)

    @classmethod
    def load(cls, model_dir: str | os.PathLike, out_of_limits: str = "refuse") -> Follower:
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
        try:
            robot = load_robot(cfg["robot"])
        except (KeyError, TypeError, ValueError) as exc:
            raise FollowerError(f"{model_dir}/config.yaml: robot: {exc}") from None
        return cls(cfg, ckpt, float(summary["knot_gap_norm"]), robot, out_of_limits)

    # ------------------------------------------------------------------ paths
    def _pathset(self, knots: np.ndarray) -> PathSet:
        """The path through `knots` (K, M) as the env follows it, inside the robot's position range (refused or
        clipped), or a FollowerError; nothing of the follower changes."""
        try:
            knots = np.asarray(knots, dtype=np.float64)
        except (TypeError, ValueError):
            raise FollowerError("path knots must be a (K, M) array of numbers") from None
        m = self.robot.path_dof
        if knots.ndim != 2 or knots.shape[1] != m or len(knots) < 2:
            raise FollowerError(f"path knots must be (K >= 2, {m}), got {knots.shape}")
        if not np.isfinite(knots).all():
            raise FollowerError("path knots must be finite")
        try:
            resampled = self.knots.apply(knots)
            paths = build_pathset([resampled], ["path"])
        except ValueError as exc:
            raise FollowerError(f"path knots: {exc}") from None
        lim = self.robot.pos_limits[self.robot.path_index]
        excess = float(table_excess(paths, torch.as_tensor(lim[:, 0]), torch.as_tensor(lim[:, 1]))[0])
        if excess <= (INSIDE_TOL if self.out_of_limits == "refuse" else 0.0):
            return paths
        if self.out_of_limits == "refuse":
            raise FollowerError(f"the path leaves robot {self.robot.name}'s position range by up to "
                                f"{1e3 * excess:.3g} mrad (at or between its knots); refused (out_of_limits='clip' "
                                "clips it)")
        try:
            return build_pathset([clip_spline_into(resampled, lim[:, 0], lim[:, 1], paths.table_step)], ["path"])
        except PathOutsideError as exc:
            raise FollowerError(str(exc)) from None

    def _measured(self, q: np.ndarray) -> np.ndarray:
        """The robot's measured joint positions (D,) as float64, or a FollowerError."""
        try:
            q = np.asarray(q, dtype=np.float64)
        except (TypeError, ValueError):
            raise FollowerError("q must be the robot's joint positions, an array of numbers") from None
        if q.shape != (self.robot.dof,):
            raise FollowerError(f"q must have shape ({self.robot.dof},) (the robot's joints), got {q.shape}")
        if not np.isfinite(q).all():
            raise FollowerError("q must be finite (a NaN or inf in the robot's joint positions)")
        return q

    def reset(self, knots: np.ndarray, q: np.ndarray | None = None) -> None:
        """Start following the path through `knots` (K, M) from rest at its first point. `q` (D,), if given, is
        the robot's measured position: it must be within START_TOLERANCE of the path's start (path joints)."""
        paths = self._pathset(knots)
        if q is not None:
            idx = self.robot.path_index
            gap = float(np.linalg.norm(self._measured(q)[idx] - paths.table[0, 0].numpy()))
            if gap > START_TOLERANCE:
                raise FollowerError(f"the robot is {gap:.3f} rad from the path's first knot (at most "
                                    f"{START_TOLERANCE}); start the path where the robot is")
        if self.env is None:
            self.env, self.policy = self._build(paths)
        else:
            self.env.set_paths(paths)
        first = torch.zeros(1, dtype=torch.long)
        self.env.start_segments(first, full_segments(paths, first))
        self._stopping = False

    def _build(self, paths: PathSet) -> tuple[PathTrackingEnv, torch.nn.Module]:
        """The one-env env on `paths` and the policy, or a FollowerError."""
        from pathrl.eval.evaluate import RunError

        try:
            env = PathTrackingEnv(self.env_cfg, self.robot, paths, build_reward_terms(self.cfg["reward"]["terms"]))
            return env, load_policy(self.cfg, env, self.checkpoint)
        except (RunError, KeyError, ValueError) as exc:
            raise FollowerError(f"{self.checkpoint}: {exc}") from None

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
        if not bool(torch.isfinite(action).all()):
            if not bool(env.braking[0]):
                raise FollowerError("the policy returned a non-finite action; nothing was sent (stop() brakes "
                                    "without the policy)")
            action = torch.zeros_like(action)  # braking: the env's law, not the action, sets the acceleration
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

