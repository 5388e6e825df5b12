"""Batched PyBullet feedback: N ball-on-plate scenes spread over worker processes (one DIRECT client per
scene), behind the env's :class:`pathrl.envs.feedback.Feedback` interface.

Each worker owns a contiguous block of envs. A decision step sends every worker its block of control-rate
setpoints (n_w, C, D) and receives the ball readings; the workers simulate in parallel. Scene ``i`` draws
its balls from ``seed + i``, so results do not depend on the number of workers.
"""

from __future__ import annotations

import multiprocessing as mp
from multiprocessing.connection import Connection

import numpy as np
import torch
from torch import Tensor

from pathrl.envs.feedback import USABLE_HALF, FeedbackStep, ball_observation
from pathrl.robot.model import RobotSpec


def _worker(conn: Connection, robot: RobotSpec, first: int, count: int, seed: int, control_rate: float) -> None:
    import torch as _torch

    _torch.set_num_threads(1)
    from pathrl.sim.ball_plate import BallOnPlateScene

    scenes = [BallOnPlateScene(robot, seed=seed + first + i, control_rate=control_rate) for i in range(count)]
    try:
        while True:
            cmd, *args = conn.recv()
            if cmd == "reset":
                local, q = args
                for i, qi in zip(local, q, strict=True):
                    scenes[i].reset(qi)
                conn.send(_read(scenes))
            elif cmd == "step":
                q, qd = args
                for s, qs, vs in zip(scenes, q, qd, strict=True):
                    s.follow(qs, vs)
                conn.send(_read(scenes))
            elif cmd == "close":
                break
    finally:
        for s in scenes:
            s.close()
        conn.close()


def _read(scenes) -> tuple[np.ndarray, np.ndarray]:
    """Ball (x, y) in plate coordinates (n, 2) and on-plate flags (n,) of every scene with a ball."""
    xy = np.zeros((len(scenes), 2))
    on = np.zeros(len(scenes), dtype=bool)
    for i, s in enumerate(scenes):
        if s.ball is not None:
            xy[i] = s.ball_on_plate()[:2]
            on[i] = s.ball_is_on_plate()
    return xy, on


class PyBulletBall:
    """Ball on plate simulated in PyBullet, N envs over `workers` processes (same interface as AnalyticBall)."""

    name = "ball_on_plate"
    num_obs = 4
    value_names = ("ball_dist", "ball_on_plate")

    def __init__(self, robot: RobotSpec, num_envs: int, control_rate: float = 240.0, seed: int = 0,
                 workers: int = 2):
        self.n = num_envs
        workers = max(1, min(int(workers), num_envs))
        bounds = np.linspace(0, num_envs, workers + 1).round().astype(int)
        self.blocks = [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        ctx = mp.get_context("spawn")
        self.conns: list[Connection] = []
        self.procs = []
        for a, b in self.blocks:
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, robot, a, b - a, seed, control_rate), daemon=True)
            proc.start()
            child.close()
            self.conns.append(parent)
            self.procs.append(proc)
        self.half = torch.tensor(USABLE_HALF, dtype=torch.float64)
        self.xy = torch.zeros(num_envs, 2, dtype=torch.float64)
        self.on = torch.zeros(num_envs, dtype=torch.bool)
        self.prev_rel = torch.zeros(num_envs, 2, dtype=torch.float64)

    def _gather(self) -> tuple[Tensor, Tensor]:
        parts = [c.recv() for c in self.conns]
        xy = torch.as_tensor(np.concatenate([p[0] for p in parts]))
        on = torch.as_tensor(np.concatenate([p[1] for p in parts]))
        return xy, on

    def reset(self, env_ids: Tensor, q: Tensor) -> None:
        if len(env_ids) == 0:
            return
        ids = env_ids.cpu().numpy()
        qn = q.detach().cpu().numpy()
        for (a, b), c in zip(self.blocks, self.conns, strict=True):
            sel = (ids >= a) & (ids < b)
            c.send(("reset", (ids[sel] - a).tolist(), qn[sel]))
        xy, on = self._gather()
        self.xy[env_ids] = xy[env_ids]
        self.on[env_ids] = on[env_ids]
        self.prev_rel[env_ids] = xy[env_ids] / self.half

    def step(self, q: Tensor, qd: Tensor) -> FeedbackStep:
        qn, vn = q.detach().cpu().numpy(), qd.detach().cpu().numpy()
        for (a, b), c in zip(self.blocks, self.conns, strict=True):
            c.send(("step", qn[a:b], vn[a:b]))
        xy, on = self._gather()
        self.prev_rel = self.xy / self.half
        was_on = self.on.clone()
        self.xy = torch.where(self.on.unsqueeze(1), xy, self.xy)  # a fallen ball keeps its last reading
        self.on = self.on & on
        return FeedbackStep(obs=self.observe(), values=self.values(), failed=was_on & ~self.on)

    def values(self) -> dict[str, Tensor]:
        return {"ball_dist": (self.xy / self.half).norm(dim=1), "ball_on_plate": self.on.to(torch.float64)}

    def observe(self) -> Tensor:
        return ball_observation(self.prev_rel, self.xy / self.half).clamp(-1.0, 1.0)

    def close(self) -> None:
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
