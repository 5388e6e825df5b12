"""Recording TrueAdapt adaptation episodes to ``trueadapt.mcap`` for ``pathrl-view``.

:func:`record_trueadapt` runs trajectories of a :class:`~pathrl.envs.trueadapt.TrueAdaptEnv` (built with
``autoreset=False``) under an actor, ``env.num_envs`` at a time like :func:`pathrl.eval.trueadapt.evaluate`, and
keeps per decision step the reference and the commanded (adapted) joint positions, the plate's TCP for both
(forward kinematics, :mod:`pathrl.robot.kinematics`), the adapted plate's orientation and the ball on it (plate
frame and world). An episode is recorded up to its first ending (the env keeps stepping an ended env until its
batch is done; those steps are dropped). Topics and layouts: :mod:`pathrl.logging.schema` (``TRUEADAPT_*``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict
from torch import Tensor

from pathrl.envs.trueadapt import TrueAdaptEnv
from pathrl.eval.trueadapt import ObservingPolicy, run_trajectories
from pathrl.logging.mcap_io import McapJsonWriter
from pathrl.logging.schema import LIMIT_FIELDS, TRUEADAPT_EPISODE, TRUEADAPT_ROBOT, TRUEADAPT_STEP
from pathrl.robot.kinematics import ForwardKinematics, matrix_to_quat
from pathrl.sim.feedback import PLATE_SIZE, plate_pose
from pathrl.storage import atomic_write

__all__ = ["FILE_NAME", "NOMINAL_RADIUS", "record_trueadapt", "robot_message", "run_batch"]

FILE_NAME = "trueadapt.mcap"
Actor = Callable[[TensorDict], Tensor]
#: radius shown for a ball whose simulator does not expose it (the PyBullet scene draws its own)
NOMINAL_RADIUS = 0.0275


@dataclass
class _Batch:
    """Per decision step (S + 1 rows, row 0 = the initial state) of a batch of n envs."""

    ref: list[Tensor]  # (n, D) each
    pos: list[Tensor]
    vel: list[Tensor]
    acc: list[Tensor]
    ball_xy: list[Tensor]  # (n, 2)
    failed: list[Tensor]  # (n,) bool
    deviation: list[Tensor]  # (n,)
    length: Tensor  # (n,) recorded decision steps of each episode
    outcome: dict[str, Tensor]  # per env: success, failed, dev_terminated, fraction, acc, jerk, offset


def _snapshot(env: TrueAdaptEnv, b: _Batch, n: int) -> None:
    b.ref.append(env.reference_at(0)[:n].clone())
    b.pos.append(env.pos[:n].clone())
    b.vel.append(env.vel[:n].clone())
    b.acc.append(env.acc[:n].clone())
    b.ball_xy.append(env.ball.xy[:n].detach().to(torch.float64).cpu().clone())
    b.failed.append(env.failed[:n].clone())
    dev = (env.pos[:n] - b.ref[-1]).abs().amax(dim=1)
    b.deviation.append(dev)


def run_batch(env: TrueAdaptEnv, actor: Actor, traj: Tensor) -> _Batch:
    """Run trajectories `traj` (bank indices (n,), n <= num_envs) to their ends
    (:func:`~pathrl.eval.trueadapt.run_trajectories`), keeping every step."""
    n = len(traj)
    b = _Batch([], [], [], [], [], [], [], torch.zeros(n, dtype=torch.long), {})

    def keep(stepped: Tensor) -> None:
        _snapshot(env, b, n)
        b.length[stepped] += 1

    b.outcome = run_trajectories(env, ObservingPolicy(actor), traj, keep)
    return b


def _world(fk: ForwardKinematics, q: Tensor, ball_xy: Tensor, radius: Tensor) -> dict[str, Tensor]:
    """TCP positions, plate quaternions (xyzw) and ball centres in the world for q (S, n, D), ball (S, n, 2)."""
    s, n, d = q.shape
    tcp = fk.tcp_positions(q.reshape(-1, d))[:, 0].reshape(s, n, 3)
    o, r = plate_pose(fk, q)
    local = torch.cat([ball_xy, (radius + PLATE_SIZE[2] / 2).expand(s, n).unsqueeze(-1)], dim=-1)
    ball = o + (r @ local.unsqueeze(-1)).squeeze(-1)
    return {"tcp": tcp, "quat": matrix_to_quat(r.reshape(-1, 3, 3)).reshape(s, n, 4), "ball": ball}


def robot_message(env: TrueAdaptEnv) -> dict[str, Any]:
    """The robot description (EVAL_ROBOT layout) plus the task's mode, dt and plate size."""
    rb = env.robot
    limits = [rb.pos_limits, *(np.stack([-x, x], axis=1) for x in (rb.vel_limits, rb.acc_limits, rb.jerk_limits))]
    msg = {"robot": rb.name, "joint_names": list(rb.joints), "path_joints": list(rb.path_joints),
           "urdf": str(rb.urdf), "tcp_links": [t.link for t in rb.tcps], "mode": env.cfg.mode, "dt": env.cfg.dt,
           "plate_size": list(PLATE_SIZE), "usable_half": env.half.tolist()}
    return msg | {key: np.asarray(lim, dtype=np.float64).tolist()
                  for key, lim in zip(LIMIT_FIELDS, limits, strict=True)}


def _write_batch(w: McapJsonWriter, env: TrueAdaptEnv, fk: ForwardKinematics, b: _Batch, traj: Tensor, first: int,
                 clock: float) -> float:
    """Write the episodes of one batch (ids first, first + 1, ...) from time `clock`; returns the clock after them."""
    n = len(traj)
    stack = {k: torch.stack(getattr(b, k)).cpu() for k in ("ref", "pos", "vel", "acc", "ball_xy", "failed",
                                                          "deviation")}
    radius = getattr(env.ball, "radius", None)
    radius = (radius[:n].detach().cpu().to(torch.float64) if radius is not None
              else torch.full((n,), NOMINAL_RADIUS, dtype=torch.float64))
    ref = _world(fk, stack["ref"], stack["ball_xy"], radius)
    ada = _world(fk, stack["pos"], stack["ball_xy"], radius)
    dt = env.cfg.dt
    for i in range(n):
        ep, steps = first + i, int(b.length[i])
        for k in range(steps + 1):
            t = clock + k * dt
            w.write(TRUEADAPT_STEP, {
                "episode": ep, "step": k, "t": k * dt, "reference": stack["ref"][k, i], "position": stack["pos"][k, i],
                "velocity": stack["vel"][k, i], "acceleration": stack["acc"][k, i], "reference_tcp": ref["tcp"][k, i],
                "tcp": ada["tcp"][k, i], "plate_quat_xyzw": ada["quat"][k, i], "ball_xy": stack["ball_xy"][k, i],
                "ball_position": ada["ball"][k, i], "ball_radius": float(radius[i]),
                "failed": bool(stack["failed"][k, i]), "deviation": float(stack["deviation"][k, i])}, int(t * 1e9))
        w.write(TRUEADAPT_EPISODE, {"episode": ep, "trajectory": int(traj[i]), "steps": steps,
                                    **{k: float(v[i]) for k, v in b.outcome.items()}},
                int((clock + steps * dt) * 1e9))
        clock += steps * dt + 1.0
    return clock


def record_trueadapt(env: TrueAdaptEnv, actor: Actor, episodes: int, out_path: Path,
                     trajectories: Tensor | None = None) -> dict[str, float]:
    """Run `episodes` episodes (bank trajectories 0, 1, ... cycled, or `trajectories` (M,)) under `actor`
    (observations TensorDict -> actions (N, D)) and write `out_path` atomically (module doc).

    Returns the success rate, mean trajectory fraction and the number of episodes and steps recorded."""
    if env.cfg.autoreset:
        raise ValueError("record_trueadapt: build the env with autoreset=False")
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    traj = torch.arange(episodes) % env.bank.num if trajectories is None else torch.as_tensor(trajectories)
    if traj.ndim != 1 or len(traj) == 0 or int(traj.min()) < 0 or int(traj.max()) >= env.bank.num:
        raise ValueError(f"trajectories must be bank indices in [0, {env.bank.num}), got {traj.tolist()}")
    fk = env.fk
    batches = [(lo, traj[lo:lo + env.num_envs]) for lo in range(0, len(traj), env.num_envs)]
    runs = [(lo, t, run_batch(env, actor, t)) for lo, t in batches]
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)

    def write(tmp: Path) -> None:
        with McapJsonWriter(tmp) as w:
            w.write(TRUEADAPT_ROBOT, robot_message(env), 0)
            clock = 0.0
            for lo, t, b in runs:
                clock = _write_batch(w, env, fk, b, t, lo, clock)

    atomic_write(out, write)
    success = torch.cat([b.outcome["success"] for _, _, b in runs])
    fraction = torch.cat([b.outcome["fraction"] for _, _, b in runs])
    return {"episodes": len(traj), "success": float(success.mean()), "fraction": float(fraction.mean()),
            "steps": int(sum(int(b.length.sum()) for _, _, b in runs))}
