"""Run a trained path-tracking policy in a robot's control loop: one robot, numpy in and out, no Hydra.

    follower = Follower.load("models/tracking/iiwa7_random", control_rate=500)
    follower.reset(knots)                   # (K, M) path knots; the robot is at rest at the first knot
    while not follower.done:                # done: at rest on the last knot (within SETTLE_TOLERANCE)
        sp = follower.decide()              # Setpoints for the next 0.1 s, 50 at 500 Hz
        robot.send(sp.position, sp.velocity)
    follower.replace_path(new_knots)        # mid-motion: the robot keeps its state, the path changes
    follower.stop()                         # from the next decision on: brake to rest within every limit

A follower is a one-env :class:`~pathrl.envs.tracking.PathTrackingEnv` stepped by the policy: the same valid
acceleration range (every limit holds at every setpoint, braking stays possible), the same integration as in
training and evaluation. There is no second implementation of the step. The env's acceleration is linear in time
within a decision, so its setpoints at any control rate with a whole number of setpoints per decision are exact.

The end of the path: where the env would brake to rest short of the last knot, the follower moves the robot onto
it with a jerk-limited state-to-state move (:mod:`pathrl.deploy.approach`, Ruckig) inside every limit; if that move
would leave the position range, the env's braking law first brings the robot to rest and the move starts from
rest (each joint then moves monotonically between two points inside the range).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

from pathrl.dataset.io import OUT_OF_LIMITS, bounds_problem
from pathrl.deploy.approach import Approach, plan_approach
from pathrl.envs.registry import EVAL_ENV, EnvRequest, get_task, make_env
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.limits.braking import is_stopped
from pathrl.limits.integrate import interpolate_step
from pathrl.paths.inside import INSIDE_TOL, PathOutsideError, keep_inside
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.pathset import PathSet
from pathrl.paths.quick import quick_knots, quick_pathset
from pathrl.paths.segments import full_segments
from pathrl.robot.model import RobotSpec, load_robot
from pathrl.runs import RunError, load_policy, load_run, policy_scale

__all__ = ["MEASURED_TOLERANCE", "ON_MEASURED", "SETTLE_TOLERANCE", "START_TOLERANCE", "Follower", "FollowerError",
           "PreparedPath", "Setpoints"]


#: Largest weighted joint distance (rad) between the robot and the start of a path it is asked to follow.
START_TOLERANCE = 0.05
#: A path is done when the robot is at rest within this distance (rad, largest joint) of its last knot.
SETTLE_TOLERANCE = 0.005
#: A policy that comes to rest this close (rad of arc length) to the path's end hands over to the final approach.
TAKEOVER_ARC = 0.25
#: Default largest joint difference (rad) between a measured position and the commanded one (``decide(q_measured)``).
MEASURED_TOLERANCE = 0.05
#: What ``decide(q_measured=...)`` does beyond the tolerance: raise a FollowerError (nothing moves) or warn.
ON_MEASURED = ("refuse", "warn")


class FollowerError(ValueError):
    """A path, state or model the follower cannot take (one line)."""


@dataclass(frozen=True)
class Setpoints:
    """One decision's setpoints at the control rate: position, velocity, acceleration, each (C, D) (rad, rad/s,
    rad/s^2), at t = dt k / C, k = 1..C after the decision."""

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray


@dataclass(frozen=True)
class PreparedPath:
    """A path checked and tabulated by :meth:`Follower.prepare` (off the control loop), for :meth:`Follower.reset`
    and :meth:`Follower.replace_path` of a follower of the same robot and knot strategy."""

    paths: PathSet
    owner: int  # id of the preparing follower's robot + knot strategy


class Follower:
    """A shipped policy following one path at a time (module docstring).

    A path that leaves the robot's position range (at a knot or on the spline between knots) is refused with a
    :class:`FollowerError` (``out_of_limits="refuse"``, the default) or clipped into it (``"clip"``: the knots are
    moved until the whole spline is inside). Every error of the follower is a :class:`FollowerError`; a failed
    :meth:`reset` or :meth:`replace_path` leaves the follower as it was.
    """

    def __init__(self, cfg: dict, checkpoint: Path, knot_gap: float, robot: RobotSpec, out_of_limits: str = "refuse",
                 control_rate: float | None = None, measured_tolerance: float = MEASURED_TOLERANCE,
                 on_measured: str = "refuse"):
        if out_of_limits not in OUT_OF_LIMITS:
            raise FollowerError(f"out_of_limits must be one of {list(OUT_OF_LIMITS)}, got {out_of_limits!r}")
        if on_measured not in ON_MEASURED:
            raise FollowerError(f"on_measured must be one of {list(ON_MEASURED)}, got {on_measured!r}")
        if not _number(measured_tolerance) > 0:
            raise FollowerError(f"measured_tolerance must be a number > 0 (rad), got {measured_tolerance!r}")
        try:
            feedback = get_task(cfg).feedback
        except ValueError as exc:
            raise FollowerError(str(exc)) from None
        if feedback is not None:
            raise FollowerError(f"the follower runs path-tracking policies; this one needs the {feedback} sensor")
        self.robot, self.cfg, self.checkpoint, self.out_of_limits = robot, cfg, checkpoint, out_of_limits
        self.knots = KnotStrategy.from_cfg(cfg["knots"])
        self.knot_gap = knot_gap
        self.env_cfg = replace(TrackingEnvCfg.from_run(cfg, num_envs=1, seed=0, knot_gap_norm=knot_gap), **EVAL_ENV)
        self.env: PathTrackingEnv | None = None
        self.policy: torch.nn.Module | None = None
        self._stopping = False
        self._approach: Approach | None = None  # the final approach, once planned
        self._approach_t = 0.0  # time along it at the last decision (s)
        #: Whether the last final approach started from rest (its move from motion would have left the range).
        self.approach_from_rest = False
        self.measured_tolerance, self.on_measured = float(measured_tolerance), on_measured
        #: Largest joint difference (rad) between the last measured position and the commanded one (or None).
        self.measured_error: float | None = None
        rate = self.env_cfg.control_rate if control_rate is None else control_rate
        self.setpoints_per_decision = self._ticks(rate)  # a FollowerError unless a whole number per decision
        self.control_rate = float(rate)
        self._lim = (robot.vel_limits, robot.acc_limits, robot.jerk_limits, robot.pos_limits)

    @classmethod
    def load(cls, model_dir: str | os.PathLike, out_of_limits: str = "refuse", control_rate: float | None = None,
             measured_tolerance: float = MEASURED_TOLERANCE, on_measured: str = "refuse") -> Follower:
        """The policy of a model or run directory (``config.yaml`` + ``model.pt``, loaded weights only).

        `control_rate` (Hz): the default rate of :meth:`decide`'s setpoints (default: the env's, 240 Hz); it must
        give a whole number of setpoints per decision (e.g. 100, 240, 250, 500, 1000 Hz for 0.1 s).
        `measured_tolerance` (rad) and `on_measured` ("refuse" or "warn"): see :meth:`decide`."""
        if not isinstance(model_dir, (str, os.PathLike)):
            raise FollowerError(f"model_dir must be a path (str or os.PathLike), got {type(model_dir).__name__}")
        try:
            cfg, ckpt, summary = load_run(Path(model_dir))
            if ckpt is None:
                raise FollowerError(f"{model_dir}: a model-based controller, not a policy")
            gap = policy_scale(Path(model_dir), summary)
        except RunError as exc:
            raise FollowerError(str(exc)) from None
        try:
            robot = load_robot(cfg["robot"])
        except (KeyError, TypeError, ValueError) as exc:
            raise FollowerError(f"{model_dir}/config.yaml: robot: {exc}") from None
        return cls(cfg, ckpt, gap, robot, out_of_limits, control_rate, measured_tolerance, on_measured)

    def _ticks(self, rate_hz: float) -> int:
        """Setpoints per decision at `rate_hz`, or a FollowerError unless it is a whole number >= 1."""
        try:
            n = float(rate_hz) * self.env_cfg.dt
        except (TypeError, ValueError):
            raise FollowerError(f"control rate must be a number (Hz), got {rate_hz!r}") from None
        if not np.isfinite(n) or n < 1 - 1e-9 or abs(n - round(n)) > 1e-6:
            raise FollowerError(f"control rate {rate_hz} Hz gives {n:.4g} setpoints per {self.env_cfg.dt} s "
                                "decision; it must be a whole number >= 1 (e.g. 100, 240, 500 Hz)")
        return int(round(n))

    # ------------------------------------------------------------------ paths
    def prepare(self, knots: np.ndarray | PreparedPath) -> PreparedPath:
        """The path through `knots` (K, M), checked against the position range (refused or clipped) and tabulated:
        the expensive part of :meth:`reset` and :meth:`replace_path`, to be done outside the control loop (any
        thread). Nothing of the follower changes; errors are FollowerErrors."""
        if isinstance(knots, PreparedPath):
            if knots.owner != self._owner:
                raise FollowerError("this path was prepared by a follower of another robot or knot strategy")
            return knots
        return PreparedPath(self._pathset(knots), self._owner)

    @property
    def _owner(self) -> int:
        return hash((self.robot.name, self.knots, self.out_of_limits))

    def _pathset(self, knots: np.ndarray) -> PathSet:
        """The path through `knots` (K, M) as the env follows it, inside the robot's position range (refused or
        clipped), or a FollowerError; nothing of the follower changes."""
        knots = _real_array(knots, "path knots must be a (K, M) array of numbers")
        m = self.robot.path_dof
        if knots.ndim != 2 or knots.shape[1] != m or len(knots) < 2:
            raise FollowerError(f"path knots must be (K >= 2, {m}), got {knots.shape}")
        if not np.isfinite(knots).all():
            raise FollowerError("path knots must be finite")
        problem = bounds_problem(knots)  # before tabulation: knots in degrees or mm would take minutes and gigabytes
        if problem:
            raise FollowerError(f"path: {problem}")
        try:  # the dataset pipeline's knot strategy and table, computed faster (pathrl.paths.quick)
            resampled = quick_knots(self.knots, knots)
            paths = quick_pathset(resampled)
        except ValueError as exc:
            raise FollowerError(f"path knots: {exc}") from None
        lim = self.robot.pos_limits[self.robot.path_index]
        refuse = self.out_of_limits == "refuse"
        try:
            return keep_inside(paths, [resampled], lim[:, 0], lim[:, 1], clip=not refuse,
                               tol=INSIDE_TOL if refuse else 0.0)
        except PathOutsideError as exc:
            if exc.excess is None:  # clipping did not bring it inside
                raise FollowerError(str(exc)) from None
            raise FollowerError(f"the path leaves robot {self.robot.name}'s position range by up to "
                                f"{1e3 * exc.excess:.3g} mrad (at or between its knots); refused (out_of_limits='clip' "
                                "clips it)") from None
        except ValueError as exc:  # e.g. every knot clipped onto one point
            raise FollowerError(f"the path clipped into the position range: {exc}") from None

    def _measured(self, q: np.ndarray) -> np.ndarray:
        """The robot's measured joint positions (D,) as float64, or a FollowerError."""
        q = _real_array(q, "q must be the robot's joint positions, an array of numbers")
        if q.shape != (self.robot.dof,):
            raise FollowerError(f"q must have shape ({self.robot.dof},) (the robot's joints), got {q.shape}")
        if not np.isfinite(q).all():
            raise FollowerError("q must be finite (a NaN or inf in the robot's joint positions)")
        return q

    def reset(self, knots: np.ndarray | PreparedPath, q: np.ndarray | None = None) -> None:
        """Start following the path through `knots` (K, M) (or a :meth:`prepare`d path) from rest at its first
        point. `q` (D,), if given, is the robot's measured position: it must be within START_TOLERANCE of the
        path's start (path joints)."""
        paths = self.prepare(knots).paths
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
        self._stopping, self._approach, self.measured_error = False, None, None

    def _build(self, paths: PathSet) -> tuple[PathTrackingEnv, torch.nn.Module]:
        """The one-env env on `paths` and the policy, or a FollowerError. A follower does not learn: its env computes
        no reward (the step's state, limits and observation do not depend on the reward terms)."""
        try:
            request = EnvRequest(num_envs=1, seed=0, knot_gap_norm=self.knot_gap, paths=paths, robot=self.robot,
                                 reward=False)
            env = make_env(self.cfg, request, **EVAL_ENV)
            return env, load_policy(self.cfg, env, self.checkpoint)
        except (RunError, KeyError, ValueError) as exc:
            raise FollowerError(f"{self.checkpoint}: {exc}") from None

    def replace_path(self, knots: np.ndarray | PreparedPath) -> float:
        """Follow the path through `knots` (K, M) (or a :meth:`prepare`d path: then this takes well under a
        millisecond) from now on, from its point nearest to the robot; the robot keeps its position, velocity and
        acceleration. Returns that point's distance from the robot (rad).

        Refused (FollowerError, nothing changes) during the final approach onto the last knot (its last ~0.1-0.3 s):
        the env's laws cannot take over from every state of that move (they left the position or velocity range by
        up to 1.3 mrad in the follower fuzz). Change the path before the end or once :attr:`done`."""
        env = self._env()
        paths = self.prepare(knots).paths
        if self._approaching:
            left = self._approach.duration - self._approach_t
            raise FollowerError(f"the robot is on its final approach to the last knot ({left:.2f} s left), a move the "
                                "env's limit laws cannot take over from; change the path before the end or once done")
        q = env.pos[0, env.path_index]
        near = (paths.table[0] - q).norm(dim=1)
        j = int(near[: int(torch.ceil(paths.length[0] / paths.table_step)) + 1].argmin())
        s = min(j * paths.table_step, float(paths.length[0]))
        env.set_paths(paths)
        env.replace_path(torch.zeros(1, dtype=torch.long), torch.zeros(1, dtype=torch.long),
                         torch.tensor([s], dtype=torch.float64))
        self._stopping, self._approach = False, None
        return float(near[j])

    # ------------------------------------------------------------------ control
    def decide(self, rate_hz: float | None = None, q_measured: np.ndarray | None = None) -> Setpoints:
        """The next decision as setpoints at `rate_hz` (default: the follower's control rate): the policy's action,
        at the path's end the final approach onto the last knot, after :meth:`stop` the braking law.

        `q_measured` (D,), optional, is the robot's measured position now. The commanded state never jumps to it
        (the limits hold for the commanded trajectory, and a jump would break them); its largest joint difference
        from the commanded position is kept in :attr:`measured_error`, and beyond `measured_tolerance` the decision
        is refused with a FollowerError and nothing advances (``on_measured="refuse"``; call :meth:`stop`) or a
        RuntimeWarning is issued and the decision goes on (``"warn"``)."""
        env = self._env()
        n = self.setpoints_per_decision if rate_hz is None else self._ticks(rate_hz)
        if q_measured is not None:
            self._check_measured(self._measured(q_measured))
        if self._approach is None and not self._stopping and (bool(env.braking[0]) or self._stalled_at_end()):
            self._plan_approach()
        if self._approach is not None:
            return self._approach_step(n)
        p0, v0, a0 = env.pos.clone(), env.vel.clone(), env.acc.clone()
        with torch.inference_mode():
            action = self.policy(env.get_observations())
        if not bool(torch.isfinite(action).all()):
            if not bool(env.braking[0]):
                raise FollowerError("the policy returned a non-finite action; nothing was sent (stop() brakes "
                                    "without the policy)")
            action = torch.zeros_like(action)  # braking: the env's law, not the action, sets the acceleration
        env.step(action)
        p, v, a = interpolate_step(p0, v0, a0, env.acc, env.cfg.dt, n)
        return Setpoints(p[0].numpy(), v[0].numpy(), a[0].numpy())

    def ticks(self, rate_hz: float | None = None, max_decisions: int = 100_000) -> Iterator[Setpoints]:
        """One setpoint per control tick at `rate_hz` until :attr:`done`: each a :class:`Setpoints` of shape
        (1, D) per field (a decision is taken every ``rate_hz * dt`` ticks)."""
        for _ in range(max_decisions):
            if self.done:
                return
            sp = self.decide(rate_hz)
            for k in range(len(sp.position)):
                yield Setpoints(sp.position[k : k + 1], sp.velocity[k : k + 1], sp.acceleration[k : k + 1])
        raise FollowerError(f"not done after {max_decisions} decisions")

    def _check_measured(self, q: np.ndarray) -> None:
        """Compare a measured position (D,) with the commanded one: refuse or warn beyond the tolerance."""
        err = float(np.abs(q - self._env().pos[0].numpy()).max())
        self.measured_error = err
        if err <= self.measured_tolerance:
            return
        msg = (f"the measured position is {err:.4f} rad (largest joint) from the commanded one, more than "
               f"{self.measured_tolerance} rad")
        if self.on_measured == "refuse":
            raise FollowerError(msg + "; nothing was sent (stop() brakes the commanded trajectory)")
        warnings.warn(msg + "; the commanded trajectory goes on", RuntimeWarning, stacklevel=3)

    def _stalled_at_end(self) -> bool:
        """The policy has brought the robot to rest within TAKEOVER_ARC of the path's end without the env counting
        the end as reached (it would stay there: the approach takes over)."""
        env = self.env
        return (self.path_left <= TAKEOVER_ARC and int(env.episode_length_buf[0]) > 0
                and bool(is_stopped(env.vel, env.acc, env.cfg.stop_tolerance)[0]))

    def _plan_approach(self) -> None:
        """At the path's end: plan the move onto the last knot from the commanded state; if it would leave the
        position range, plan it once the env's braking law has brought the robot to rest."""
        env = self.env
        p, v, a = (x[0].numpy() for x in (env.pos, env.vel, env.acc))
        target = p.copy()
        target[self.robot.path_index] = env.end_q[0].numpy()
        vel, acc, jerk, pos = self._lim
        at_rest = bool(is_stopped(env.vel, env.acc, env.cfg.stop_tolerance)[0])
        plan = plan_approach(p, v, a, target, vel, acc, jerk, pos)
        if plan is None and at_rest:  # stopped within the env's tolerance: from rest exactly (monotone per joint)
            plan = plan_approach(p, 0.0 * v, 0.0 * a, target, vel, acc, jerk, pos)
            if plan is None:
                raise FollowerError("no jerk-limited move from rest onto the path's last knot inside the limits")
        self._approach, self._approach_t = plan, 0.0
        self.approach_from_rest = at_rest

    def _approach_step(self, n: int) -> Setpoints:
        """The next decision's `n` setpoints of the final approach; the env's state follows it."""
        env, dt = self.env, self.env_cfg.dt
        t = self._approach_t + dt * np.arange(1, n + 1) / n
        p, v, a = self._approach.sample(t)
        self._approach_t += dt
        end = self._approach.sample(np.array([self._approach_t]))  # the state at the decision's end
        env.pos, env.vel, env.acc = (torch.as_tensor(x, dtype=env.pos.dtype) for x in end)
        env._update_window()  # the valid range from the new state (a later stop() or path change steps from it)
        return Setpoints(p, v, a)

    def stop(self) -> None:
        """Brake to rest from the next decision on (the env's braking law: every limit, jerk included). During the
        final approach the approach goes on instead: it ends at rest on the last knot inside every limit within its
        remaining ~0.1-0.3 s, and the braking law cannot take over from every state of it (see
        :meth:`replace_path`)."""
        env = self._env()
        if self._approaching:
            return
        env.braking[:] = True
        self._stopping, self._approach = True, None

    @property
    def _approaching(self) -> bool:
        """On the final approach, not yet at its end (at rest on the last knot, where the env can take over)."""
        return self._approach is not None and self._approach_t < self._approach.duration

    @property
    def done(self) -> bool:
        """At rest on the path's last knot (within SETTLE_TOLERANCE rad, largest joint), or at rest after a
        :meth:`stop`."""
        env = self._env()
        if self._stopping:
            return bool(env.braking[0]) and bool(is_stopped(env.vel, env.acc, env.cfg.stop_tolerance)[0])
        return (self._approach is not None and self._approach_t >= self._approach.duration
                and self.final_error <= SETTLE_TOLERANCE)

    @property
    def final_approach_s(self) -> float:
        """Duration (s) of the final approach planned for the current path (0 before the path's end)."""
        return 0.0 if self._approach is None else self._approach.duration

    @property
    def final_error(self) -> float:
        """Largest joint distance (rad) between the commanded position and the path's last knot (the knot the
        env follows: after the knot strategy, and after clipping with ``out_of_limits="clip"``)."""
        env = self._env()
        return float((env.pos[0, env.path_index] - env.end_q[0]).abs().max())

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


def _number(x: object) -> float:
    """`x` as a float, NaN if it is not a number (a NaN fails every range check)."""
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def _real_array(x: object, message: str) -> np.ndarray:
    """`x` as a float64 array, or a FollowerError with `message` (complex values included: casting drops their
    imaginary part)."""
    try:
        if np.iscomplexobj(x):
            raise TypeError
        return np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise FollowerError(message) from None
