"""Batched PyBullet feedback: N scenes spread over worker processes (one DIRECT client per scene), behind the
env's :class:`pathrl.sim.feedback.Feedback` interface.

Each worker owns a contiguous block of envs. A decision step sends every worker its block of control-rate
setpoints (n_w, C, D) and receives the sensor readings; the workers simulate in parallel. Scene ``i`` is
seeded with ``seed + i``, so results do not depend on the number of workers.

* :class:`PyBulletBall`: iiwa with a plate and a ball (:mod:`pathrl.sim.ball_plate`).
* :class:`PyBulletStanding`: free-standing ARMAR-4 (:mod:`pathrl.sim.humanoid`); its torch twin for training is
  :class:`pathrl.sim.standing.AnalyticStanding` (same observation).

Building the scenes is a fifth of a ball evaluation's time (250 iiwa scenes: ~16 s). Inside :func:`kept_pools`, a
closed ball pool is kept and handed to the next feedback of the same robot, size, rate, seed and workers, its scenes
reseeded, so evaluations run one after another in one process (``pathrl-eval batch=FILE``) build their scenes
once; the results are those of a fresh pool (tests/test_feedback.py).
"""

from __future__ import annotations

import math
import multiprocessing as mp
from collections.abc import Iterator
from contextlib import contextmanager
from multiprocessing.connection import Connection
from typing import NoReturn

import numpy as np
import torch
from torch import Tensor

from pathrl.robot.kinematics import ForwardKinematics
from pathrl.robot.model import RobotSpec
from pathrl.sim.feedback import USABLE_HALF, FeedbackStep, PlateDrive, PlateIMU, ball_observation, ball_values
from pathrl.sim.standing import BASE_POS_SCALE, FALL_TILT_RAD, standing_observation, standing_values

__all__ = ["BASE_POS_SCALE", "PyBulletBall", "PyBulletStanding", "ScenePool", "kept_pools"]


def _make_scene(kind: str, robot: RobotSpec, seed: int, control_rate: float):
    """A fresh PyBullet scene of `kind` (``ball_on_plate`` or standing) for `robot`, stepped at `control_rate` Hz."""
    if kind == "ball_on_plate":
        from pathrl.sim.ball_plate import BallOnPlateScene

        return BallOnPlateScene(robot, seed=seed, control_rate=control_rate)
    from pathrl.sim.humanoid import StandingScene

    return StandingScene(robot, control_rate=control_rate, fall_tilt_deg=math.degrees(FALL_TILT_RAD))


def _read(kind: str, scenes) -> tuple[np.ndarray, np.ndarray]:
    """Sensor readings (n, k) and ok flags (n,): ball (x, y) on the plate and on-plate; or pelvis offset (3),
    pelvis orientation xyzw (4), tilt (rad) and upright."""
    if kind == "ball_on_plate":
        out = np.zeros((len(scenes), 2))
        ok = np.zeros(len(scenes), dtype=bool)
        for i, s in enumerate(scenes):
            if s.ball is not None:
                b = s.ball_on_plate()
                out[i] = b[:2]
                ok[i] = s.ball_is_on_plate(b)
        return out, ok
    out = np.zeros((len(scenes), 8))
    for i, s in enumerate(scenes):
        out[i, :3] = s.pelvis_offset()
        out[i, 3:7] = s.pelvis_pose()[1]
        out[i, 7] = math.radians(s.tilt_deg())
    return out, out[:, 7] <= FALL_TILT_RAD


def _worker(conn: Connection, kind: str, robot: RobotSpec, first: int, count: int, seed: int,
            control_rate: float) -> None:
    """A worker process: builds scenes `first` .. `first + count - 1` (seeded `seed + index`), then answers ``reset`` /
    ``step`` commands on `conn` with their readings until ``close``; a failed start is reported as one line."""
    import torch as _torch

    _torch.set_num_threads(1)
    scenes = []
    try:
        scenes += [_make_scene(kind, robot, seed + first + i, control_rate) for i in range(count)]
    except Exception as exc:  # noqa: BLE001 - reported to the parent as one line
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        for s in scenes:
            s.close()
        conn.close()
        return
    conn.send(("ready",))
    try:
        while True:
            cmd, *args = conn.recv()
            if cmd == "reset":
                local, q = args
                for i, qi in zip(local, q, strict=True):
                    scenes[i].reset(qi)
                conn.send(_read(kind, scenes))
            elif cmd == "step":
                local, q, qd = args
                for i, qs, vs in zip(local, q, qd, strict=True):
                    scenes[i].follow(qs, vs)
                conn.send(_read(kind, scenes))
            elif cmd == "reseed":
                for i, s in enumerate(scenes):
                    s.reseed(args[0] + first + i)
                conn.send(("ready",))
            elif cmd == "close":
                break
    finally:
        for s in scenes:
            s.close()
        conn.close()


def _key(kind: str, robot: RobotSpec, num_envs: int, control_rate: float, seed: int, workers: int) -> tuple:
    """What makes two pools interchangeable (:func:`kept_pools`)."""
    return kind, repr(robot), int(num_envs), float(control_rate), int(seed), int(workers)


class ScenePool:
    """`num_envs` scenes of one kind over `workers` processes; readings come back as tensors."""

    def __init__(self, kind: str, robot: RobotSpec, num_envs: int, control_rate: float, seed: int, workers: int):
        self.key = _key(kind, robot, num_envs, control_rate, seed, workers)
        workers = max(1, min(int(workers), num_envs))
        bounds = np.linspace(0, num_envs, workers + 1).round().astype(int)
        self.blocks = [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        ctx = mp.get_context("spawn")
        self.conns: list[Connection] = []
        self.procs = []
        for a, b in self.blocks:
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, kind, robot, a, b - a, seed, control_rate), daemon=True)
            proc.start()
            child.close()
            self.conns.append(parent)
            self.procs.append(proc)
        errors = [msg for c in self.conns if (msg := self._recv(c))[0] == "error"]
        if errors:
            self.close()
            raise RuntimeError(f"PyBullet {kind} scene: {errors[0][1]}")

    def _recv(self, conn: Connection):
        """The next message of a worker; a worker that died (e.g. killed when memory ran out) is one line."""
        try:
            return conn.recv()
        except (EOFError, OSError):
            self._died(conn)

    def _send(self, conn: Connection, msg: tuple) -> None:
        """Send `msg` to a worker; one RuntimeError if it has died."""
        try:
            conn.send(msg)
        except OSError:
            self._died(conn)

    def _died(self, conn: Connection) -> NoReturn:
        """Close the pool and raise one RuntimeError naming the dead worker's exit code."""
        proc = self.procs[self.conns.index(conn)]
        proc.join(timeout=5.0)
        self.close()
        raise RuntimeError(f"a PyBullet worker process exited (exit code {proc.exitcode}; -9: killed, e.g. "
                           "out of memory: fewer envs per worker)") from None

    def _gather(self) -> tuple[Tensor, Tensor]:
        """Readings (num_envs, k) and ok flags (num_envs,) of all workers, in env order."""
        parts = [self._recv(c) for c in self.conns]
        return (torch.as_tensor(np.concatenate([p[0] for p in parts])),
                torch.as_tensor(np.concatenate([p[1] for p in parts])))

    def reset(self, env_ids: Tensor, q: Tensor) -> tuple[Tensor, Tensor]:
        """Reset envs `env_ids` at rest at `q`; readings of all envs."""
        ids = env_ids.cpu().numpy()
        qn = q.detach().cpu().numpy()
        for (a, b), c in zip(self.blocks, self.conns, strict=True):
            sel = (ids >= a) & (ids < b)
            self._send(c, ("reset", (ids[sel] - a).tolist(), qn[sel]))
        return self._gather()

    def step(self, q: Tensor, qd: Tensor, active: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """Follow setpoints (N, C, D) in the `active` scenes (N,) bool (default: all); readings of all envs
        (a scene left out keeps its state, so its reading repeats)."""
        qn, vn = q.detach().cpu().numpy(), qd.detach().cpu().numpy()
        on = np.ones(len(qn), dtype=bool) if active is None else active.detach().cpu().numpy()
        for (a, b), c in zip(self.blocks, self.conns, strict=True):
            local = np.flatnonzero(on[a:b])
            self._send(c, ("step", local.tolist(), qn[a:b][local], vn[a:b][local]))
        return self._gather()

    def reseed(self, seed: int) -> None:
        """Scene ``i`` draws from ``seed + i`` again, as a fresh pool's (a ball scene: its random balls)."""
        for c in self.conns:
            self._send(c, ("reseed", int(seed)))
        for c in self.conns:
            self._recv(c)

    def close(self) -> None:
        """Stop the worker processes (asked to close, killed after 10 s); safe to call twice."""
        for c in self.conns:
            try:
                c.send(("close",))
            except (BrokenPipeError, OSError):
                pass
        for p in self.procs:
            p.join(timeout=10)
            if p.is_alive():
                p.kill()
        self.conns, self.procs = [], []

    def __del__(self) -> None:
        if getattr(self, "procs", None):
            self.close()


#: The pools kept by :func:`kept_pools` (None: outside it, a closed pool stops its workers), by :attr:`ScenePool.key`.
_KEPT: dict[tuple, ScenePool] | None = None

#: The scene kinds whose pools are kept: a ball scene's reset removes the ball and re-poses the fixed-base robot, so
#: a kept scene starts an episode as a fresh one does. A standing robot keeps its ground contacts across resets.
_KEEPABLE = ("ball_on_plate",)


@contextmanager
def kept_pools() -> Iterator[None]:
    """Within: a closed feedback's pool (of a kind in :data:`_KEEPABLE`) is kept, and the next feedback asking for
    the same pool (kind, robot, size, rate, seed, workers) gets it reseeded instead of building its scenes again;
    every kept pool is closed on exit."""
    global _KEPT
    outer, _KEPT = _KEPT, {} if _KEPT is None else _KEPT
    try:
        yield
    finally:
        if outer is None:
            for pool in _KEPT.values():
                pool.close()
            _KEPT = None


def _pool(kind: str, robot: RobotSpec, num_envs: int, control_rate: float, seed: int, workers: int) -> ScenePool:
    """A kept pool of that key, reseeded (:func:`kept_pools`), else a new one."""
    key = _key(kind, robot, num_envs, control_rate, seed, workers)
    pool = _KEPT.pop(key, None) if _KEPT is not None else None
    if pool is None:
        return ScenePool(kind, robot, num_envs, control_rate, seed, workers)
    pool.reseed(seed)
    return pool


class _PooledFeedback:
    """Sensor feedback of `num_envs` PyBullet scenes of `kind` held by a :class:`ScenePool`; `ok` (num_envs,) bool."""

    kind = ""

    def __init__(self, robot: RobotSpec, num_envs: int, control_rate: float = 240.0, seed: int = 0,
                 workers: int = 2):
        self.pool = _pool(self.kind, robot, num_envs, control_rate, seed, workers)
        self.ok = torch.zeros(num_envs, dtype=torch.bool)

    def close(self) -> None:
        """Stop the pool's workers, or inside :func:`kept_pools` keep them for the next feedback of the same pool."""
        if _KEPT is not None and self.kind in _KEEPABLE and self.pool.conns and self.pool.key not in _KEPT:
            _KEPT[self.pool.key] = self.pool
            return
        self.pool.close()


class PyBulletBall(_PooledFeedback):
    """Ball on plate simulated in PyBullet (same interface and observation as AnalyticBall)."""

    kind = name = "ball_on_plate"
    num_obs = 4
    value_names = ("ball_dist", "ball_reach", "ball_on_plate", "ball_drive")
    ok_value = "ball_on_plate"

    def __init__(self, robot: RobotSpec, num_envs: int, control_rate: float = 240.0, seed: int = 0,
                 workers: int = 2, imu: bool = False, fk: ForwardKinematics | None = None):
        super().__init__(robot, num_envs, control_rate, seed, workers)
        fk = fk if fk is not None else ForwardKinematics(robot)  # the env's (make_env): plate sensor and drive
        self.imu = PlateIMU(robot, num_envs, control_rate, fk=fk) if imu else None
        self.plate_drive = PlateDrive(robot, num_envs, control_rate, fk=fk)
        self.num_obs = 4 + (PlateIMU.num_obs if imu else 0)
        self.half = torch.tensor(USABLE_HALF, dtype=torch.float64)
        self.xy = torch.zeros(num_envs, 2, dtype=torch.float64)
        self.prev_rel = torch.zeros(num_envs, 2, dtype=torch.float64)

    def reset(self, env_ids: Tensor, q: Tensor) -> None:
        """Put a new ball on the plate of envs `env_ids` (k,) with the robots at joint positions q (k, D) (rad)."""
        if len(env_ids) == 0:
            return
        xy, on = self.pool.reset(env_ids, q)
        self.xy[env_ids] = xy[env_ids]
        self.ok[env_ids] = on[env_ids]
        self.prev_rel[env_ids] = xy[env_ids] / self.half
        self.plate_drive.reset(env_ids, q)
        if self.imu is not None:
            self.imu.reset(env_ids, q)

    def step(self, q: Tensor, qd: Tensor, active: Tensor | None = None) -> FeedbackStep:
        """Follow the step's control-rate setpoints q, qd (N, C, D) (rad, rad/s) in the `active` scenes (N,) bool
        (default: all); the ball's observation, values and the envs whose ball fell off in this step."""
        xy, on = self.pool.step(q, qd, active)
        self.plate_drive.step(q)
        if self.imu is not None:
            self.imu.step(q)
        self.prev_rel = self.xy / self.half
        was_on = self.ok.clone()
        self.xy = torch.where(self.ok.unsqueeze(1), xy, self.xy)  # a fallen ball keeps its last reading
        self.ok = self.ok & on
        return FeedbackStep(obs=self.observe(), values=self.values(), failed=was_on & ~self.ok)

    def values(self) -> dict[str, Tensor]:
        """Task values (N,) for reward terms (:func:`~pathrl.sim.feedback.ball_values`)."""
        return ball_values(self.xy / self.half, self.ok, self.plate_drive.value)

    def observe(self) -> Tensor:
        """The ball part of the state (N, num_obs) in [-1, 1]: previous and current relative position (+ IMU)."""
        return ball_observation(self.prev_rel, self.xy / self.half, self.imu).clamp(-1.0, 1.0)


class PyBulletStanding(_PooledFeedback):
    """Free-standing ARMAR-4: pelvis offset, orientation and tilt relative to the initial upright pose.

    Observation (8, the authors' layout and scales): pelvis offset / (0.2/sqrt 3 m), pelvis quaternion
    (xyzw), tilt normalized from [0, 0.125 rad] to [-1, 1]. Values: ``base_tilt`` (rad), ``base_offset`` (m),
    ``base_orientation`` (arccos|w| 2/pi, 0..1) and ``upright``; the robot has fallen (failure, sticky) once
    the tilt exceeds 30 deg.
    """

    kind = name = "standing"
    num_obs = 8
    value_names = ("base_tilt", "base_offset", "base_orientation", "upright")
    ok_value = "upright"

    def __init__(self, robot: RobotSpec, num_envs: int, control_rate: float = 240.0, seed: int = 0,
                 workers: int = 2):
        super().__init__(robot, num_envs, control_rate, seed, workers)
        self.reading = torch.zeros(num_envs, 8, dtype=torch.float64)
        self.reading[:, 6] = 1.0

    def reset(self, env_ids: Tensor, q: Tensor) -> None:
        """Stand the robots of envs `env_ids` (k,) upright at joint positions q (k, D) (rad)."""
        if len(env_ids) == 0:
            return
        r, ok = self.pool.reset(env_ids, q)
        self.reading[env_ids] = r[env_ids]
        self.ok[env_ids] = ok[env_ids]

    def step(self, q: Tensor, qd: Tensor, active: Tensor | None = None) -> FeedbackStep:
        """Follow the step's control-rate setpoints q, qd (N, C, D) (rad, rad/s) in the `active` scenes (N,) bool
        (default: all); the pelvis observation, values and the envs whose robot fell in this step."""
        r, ok = self.pool.step(q, qd, active)
        was_up = self.ok.clone()
        self.reading = r
        self.ok = self.ok & ok
        return FeedbackStep(obs=self.observe(), values=self.values(), failed=was_up & ~self.ok)

    def values(self) -> dict[str, Tensor]:
        """Task values (N,): base_tilt (rad), base_offset (m), base_orientation (0..1) and upright (1/0)."""
        return standing_values(self.reading, self.ok)

    def observe(self) -> Tensor:
        """The pelvis part of the state (N, 8) in [-1, 1] (class docstring; :func:`standing_observation`)."""
        return standing_observation(self.reading)
