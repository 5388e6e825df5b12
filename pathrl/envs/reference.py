"""Readable single-env reference of the path-tracking MDP (numpy + scipy + klimits).

This is the test oracle and the speed baseline of :class:`pathrl.envs.tracking.PathTrackingEnv`:
one robot, one path, plain loops, the limits computed by klimits (the authors' library), the
reference path evaluated from its scipy spline (no lookup tables). For identical paths and actions
the batched env must reproduce its states, rewards and terminations (tests/test_env_oracle.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from klimits import PosVelJerkLimitation

from pathrl.envs.rewards import RewardTerm, StepQuantities
from pathrl.paths.spline import arc_length_table, chord_params, dedupe_knots, fit_spline
from pathrl.robot.model import RobotSpec

__all__ = ["ReferencePath", "ReferenceSettings", "ReferenceStep", "ReferenceTrackingEnv"]


class ReferencePath:
    """One path: spline over chord length, arc length <-> parameter tables, knot arc lengths."""

    def __init__(self, knots: np.ndarray) -> None:
        self.knots = dedupe_knots(knots)
        self.spline = fit_spline(self.knots)
        self.u_table, self.s_table = arc_length_table(self.spline, self.knots)
        self.length = float(self.s_table[-1])
        self.knot_s = np.interp(chord_params(self.knots), self.u_table, self.s_table)
        self.knot_s[-1] = self.length

    def at(self, s: float) -> np.ndarray:
        """Position (M,) at arc length s (clamped to [0, L])."""
        s = min(max(s, 0.0), self.length)
        return self.spline(np.interp(s, self.s_table, self.u_table))


@dataclass
class ReferenceStep:
    """One step of the reference env: reward and its terms, terminated / time_out, arc length advanced `moved` (rad) and
    the joint deviation max / mean over the step (rad)."""

    reward: float
    terms: dict[str, float]
    terminated: bool
    time_out: bool
    moved: float
    dev_max: float
    dev_mean: float


@dataclass(frozen=True)
class ReferenceSettings:
    """Settings of the reference env (those of :class:`~pathrl.envs.tracking_cfg.TrackingEnvCfg` it uses): the
    knot gap D (rad) the observation is scaled by, `n_state` knots observed, decision step `dt` (s) split into
    `substeps` deviation samples, episode budget (steps), rest tolerance (rad/s, rad/s^2), the stop bonus, the
    deviation cut-off (rad; None: none), the knot observation (``relative`` | ``absolute``), the end observation and
    the end tolerance (rad; None: the end is reached by arc length only)."""

    knot_gap: float
    n_state: int = 9
    dt: float = 0.1
    substeps: int = 8
    budget_steps: int = 160
    stop_tolerance: float = 0.01
    stop_bonus: bool = True
    max_deviation: float | None = None
    knot_obs: str = "relative"
    end_obs: bool = False
    end_tolerance: float | None = None


class ReferenceTrackingEnv:
    """Single env with the same step order as the batched env (see its module docstring): `path` from arc length
    `start_s` to knot `end_knot`; `braking` (pos, vel, acc (D,) -> acc (D,)) is the end-of-path braking law."""

    def __init__(self, robot: RobotSpec, path: ReferencePath, start_s: float, end_knot: int,
                 reward_terms: list[RewardTerm], settings: ReferenceSettings, braking=None) -> None:
        dt, n_state = settings.dt, settings.n_state
        self.robot, self.path, self.terms = robot, path, reward_terms
        self.dt, self.substeps, self.n_state = dt, settings.substeps, n_state
        self.knot_gap, self.horizon = settings.knot_gap, (n_state - 1) * settings.knot_gap
        self.budget, self.stop_tol = settings.budget_steps, settings.stop_tolerance
        self.stop_bonus, self.max_dev = settings.stop_bonus, settings.max_deviation
        self.braking_law = braking
        self.knot_obs = settings.knot_obs
        self.end_obs = settings.end_obs
        self.end_tolerance = settings.end_tolerance
        self.limiter = PosVelJerkLimitation(
            time_step=dt, pos_limits=robot.pos_limits.copy(),
            vel_limits=np.stack([-robot.vel_limits, robot.vel_limits], 1),
            acc_limits=np.stack([-robot.acc_limits, robot.acc_limits], 1),
            jerk_limits=np.stack([-robot.jerk_limits, robot.jerk_limits], 1),
            acceleration_after_max_vel_limit_factor=0.01, set_velocity_after_max_pos_to_zero=True,
            limit_velocity=True, limit_position=True, normalize_acc_range=False, num_threads=1)
        w = robot.deviation_weights
        self.w = w * math.sqrt(len(w) / float(np.sum(w**2)))
        self.pi = robot.path_index
        self.end_knot = end_knot
        self.end_s = float(path.knot_s[end_knot])
        self.s = float(start_s)
        self.pos = np.zeros(robot.dof)
        self.pos[self.pi] = path.at(start_s)
        self.vel = np.zeros(robot.dof)
        self.acc = np.zeros(robot.dof)
        self.steps = 0
        self.braking = False
        self._window()

    def _window(self) -> None:
        i0 = int(np.searchsorted(self.path.knot_s, self.s, side="right")) - 1
        i0 = min(max(i0, 0), self.end_knot)
        ii = [min(i0 + k, self.end_knot) for k in range(self.n_state)]
        self.window_knots = self.path.knots[ii]
        self.window_s = self.path.knot_s[ii]
        self.l_obs = float(self.window_s[-1])
        self.close_to_end = self.l_obs >= self.end_s
        rng = self.limiter.calculate_valid_acceleration_range(self.pos, self.vel, self.acc)[0]
        self.a_min, self.a_max = rng[:, 0].copy(), rng[:, 1].copy()

    def observation(self) -> np.ndarray:
        """The observation vector of the current state (the batched env's layout)."""
        lo, hi = self.robot.pos_limits[:, 0], self.robot.pos_limits[:, 1]
        parts = [2 * (self.pos - lo) / (hi - lo) - 1, self.vel / self.robot.vel_limits,
                 self.acc / self.robot.acc_limits]
        plo, phi = lo[self.pi], hi[self.pi]
        if self.knot_obs == "relative":
            parts.append(((self.window_knots - self.pos[self.pi]) / self.horizon).ravel())
        else:
            parts.append((2 * (self.window_knots - plo) / (phi - plo) - 1).ravel())
        d0 = self.window_s[0]
        parts.append([2 * (self.s - d0) / self.knot_gap - 1])
        ahead = 2 * (self.window_s - d0) / self.horizon - 1
        parts.append(ahead[-1:])
        parts.append(ahead[1:])
        if self.end_obs:
            parts.append((self.path.at(self.end_s) - self.pos[self.pi]) / self.knot_gap)
            parts.append([2 * min(max((self.end_s - self.s) / self.knot_gap, 0.0), 1.0) - 1])
        return np.clip(np.concatenate([np.ravel(p) for p in parts]), -1, 1)

    def step(self, action: np.ndarray) -> ReferenceStep:
        """Apply `action` (D,) in [-1, 1] (mapped into the valid acceleration range; the braking law
        instead while braking) for one decision step."""
        action = np.asarray(action, dtype=np.float64)
        a1 = self.a_min + 0.5 * (np.clip(action, -1, 1) + 1) * (self.a_max - self.a_min)
        if self.braking:
            a1 = self.braking_law(self.pos, self.vel, self.acc)
        p0, v0, a0, T = self.pos, self.vel, self.acc, self.dt
        pts = [p0[self.pi]]
        for k in range(1, self.substeps + 1):
            t = T * k / self.substeps
            p = p0 + v0 * t + a0 * t**2 / 2 + (a1 - a0) * t**3 / (6 * T)
            pts.append(p[self.pi])
        seg = [float(np.linalg.norm(pts[k] - pts[k - 1])) for k in range(1, len(pts))]
        cum = np.cumsum(seg)
        moved = float(cum[-1])
        devs = [float(np.linalg.norm(self.w * (self.path.at(min(self.s + c, self.end_s)) - q)))
                for c, q in zip(cum, pts[1:], strict=True)]
        dev_max = max(devs)
        dev_mean = float(np.dot(devs, seg) / moved) if moved > 1e-12 else float(np.mean(devs))
        import torch  # reward terms are shared torch functions; evaluate them on 1-element tensors

        q = StepQuantities(*(torch.tensor([x], dtype=torch.float64) for x in (
            moved, max(self.l_obs - self.s, 0.0), self.horizon, dev_max, dev_mean, float(np.max(np.abs(action))))),
            close_to_end=torch.tensor([self.close_to_end]))
        terms = {t.name: float(t.weight * t(q)[0]) for t in self.terms}
        reward = sum(terms.values())
        self.pos = p0 + v0 * T + a0 * T**2 / 2 + (a1 - a0) * T**2 / 6
        self.vel = v0 + a0 * T + (a1 - a0) * T / 2
        self.acc = a1
        self.s = min(self.s + moved, self.end_s)
        self.steps += 1
        reached = self.s >= self.end_s - 1e-9
        if self.end_tolerance is not None:
            to_end = float(np.linalg.norm(self.w * (self.path.at(self.end_s) - self.pos[self.pi])))
            reached = reached or (to_end <= self.end_tolerance and self.end_s - self.s < self.knot_gap)
        at_rest = np.all(np.abs(self.vel) < self.stop_tol) and np.all(np.abs(self.acc) < self.stop_tol)
        stopped = self.braking and bool(at_rest)
        self.braking = self.braking or reached
        terminated = stopped or (self.max_dev is not None and dev_max > self.max_dev)
        time_out = self.steps >= self.budget and not terminated
        if self.stop_bonus and stopped:
            reward *= 1.0 + max(self.budget - self.steps, 0)
        self._window()
        return ReferenceStep(reward, terms, terminated, time_out, moved, dev_max, dev_mean)
