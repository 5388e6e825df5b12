"""Synthetic ``episodes.mcap`` / ``run.mcap`` in the evaluation and training layouts (tests, demo, bench).

The episodes are made up but kinematically consistent: a smooth joint-space reference curve per episode,
an executed trajectory that follows it with a smooth time-scaling plus a small bounded deviation,
decision-step velocities/accelerations by finite differences, and TCP positions by forward kinematics.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pathrl.logging.mcap_io import McapJsonWriter
from pathrl.logging.schema import (
    EVAL_EPISODE_METRICS,
    EVAL_JOINT_STATE,
    EVAL_REFERENCE,
    EVAL_ROBOT,
    EVAL_TCP,
    RUN_CONFIG,
    TRAIN_SCALARS,
)

__all__ = ["write_synthetic_episodes", "write_synthetic_run"]

DT = 0.1  # decision step (s), as conf/env/tracking.yaml


def _arc_length(q: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))])


def write_synthetic_episodes(
    path: str | Path, robot: str = "iiwa7", episodes: int = 3, steps: int = 45, seed: int = 0, dt: float = DT
) -> Path:
    """Write `episodes` episodes of about `steps` decision steps for conf robot `robot`; returns `path`."""
    from pathrl.robot.external import load_robot_by_name
    from pathrl.robot.kinematics import ForwardKinematics

    spec = load_robot_by_name(robot)
    fk = ForwardKinematics(spec)
    rng = np.random.default_rng(seed)
    lo, hi = spec.pos_limits[:, 0], spec.pos_limits[:, 1]
    mid, half = (lo + hi) / 2, (hi - lo) / 2
    pidx = spec.path_index
    path = Path(path)
    with McapJsonWriter(path) as w:
        w.write(EVAL_ROBOT, _robot_message(spec), 0)
        t_ns = 0
        for ep in range(episodes):
            q0 = mid + rng.uniform(-0.35, 0.35, spec.dof) * half
            q1 = np.clip(q0 + rng.uniform(-1.2, 1.2, spec.dof), lo, hi)
            bend = rng.uniform(-0.4, 0.4, spec.dof)
            u = np.linspace(0.0, 1.0, 400)
            curve = q0 + u[:, None] * (q1 - q0) + np.sin(np.pi * u)[:, None] * bend
            arc = _arc_length(curve[:, pidx])
            start_s = float(rng.uniform(0.0, 0.5))
            s = np.linspace(0.0, arc[-1], 200)

            def ref_at(sq: np.ndarray, curve=curve, arc=arc) -> np.ndarray:
                return np.stack([np.interp(sq, arc, curve[:, j]) for j in range(spec.dof)], axis=1)

            q_ref = ref_at(s)
            tcp_ref = fk.tcp_positions_np(q_ref)
            n = max(8, steps + int(rng.integers(-5, 6)))
            tau = np.linspace(0.0, 1.0, n + 1)
            blend = tau**3 * (10 - 15 * tau + 6 * tau**2)  # smooth start and stop
            amp = rng.uniform(0.002, 0.03) * (1 + 3 * (ep % 7 == 3))
            q = ref_at(blend * arc[-1]) + amp * np.sin(np.pi * tau)[:, None] * rng.standard_normal(spec.dof)
            vel = np.gradient(q, dt, axis=0)
            acc = np.gradient(vel, dt, axis=0)
            vel[0] = acc[0] = 0.0
            w.write(
                EVAL_REFERENCE,
                {
                    "episode": ep,
                    "path": f"synthetic_{ep:04d}",
                    "s": s + start_s,
                    "position": q_ref[:, pidx],
                    "tcp_position": tcp_ref,
                },
                t_ns,
            )
            _write_states(w, fk, ep, q, vel, acc, t_ns, dt)
            t_ns += int(round((n + 1) * dt * 1e9))
            metrics = _metrics(fk, q, ref_at(blend * arc[-1]), pidx)
            w.write(
                EVAL_EPISODE_METRICS,
                {
                    "episode": ep,
                    "path": f"synthetic_{ep:04d}",
                    "start_s": start_s,
                    "end_s": start_s + arc[-1],
                    "duration_s": n * dt,
                    "termination": "robot_stopped",
                    "terminated_early": False,
                    **metrics,
                    "limit_violations": 0,
                },
                t_ns,
            )
            w.flush()
    return path


def _robot_message(spec) -> dict:
    """The ``/eval/robot`` message of a robot spec."""
    return {
        "robot": spec.name,
        "joint_names": list(spec.joints),
        "path_joints": list(spec.path_joints),
        "position_limits": spec.pos_limits.tolist(),
        "velocity_limits": [[-v, v] for v in spec.vel_limits.tolist()],
        "acceleration_limits": [[-v, v] for v in spec.acc_limits.tolist()],
        "jerk_limits": [[-v, v] for v in spec.jerk_limits.tolist()],
        "urdf": str(spec.urdf),
        "tcp_links": [t.link for t in spec.tcps],
    }


def _write_states(w: McapJsonWriter, fk, ep: int, q, vel, acc, t_ns: int, dt: float) -> None:
    """Joint states and TCP poses of one episode's samples (N, D), starting at log time t_ns."""
    tcp_p, tcp_q = (x.numpy() for x in fk.tcp_poses(q))
    for k in range(len(q)):
        tk = t_ns + int(round(k * dt * 1e9))
        w.write(
            EVAL_JOINT_STATE,
            {
                "episode": ep,
                "t": k * dt,
                "position": q[k],
                "velocity": vel[k],
                "acceleration": acc[k],
            },
            tk,
        )
        w.write(
            EVAL_TCP,
            {"episode": ep, "t": k * dt, "position": tcp_p[k], "orientation_xyzw": tcp_q[k]},
            tk,
        )


def _metrics(fk, q: np.ndarray, q_ref: np.ndarray, pidx) -> dict[str, float]:
    """Joint (rad) and TCP (cm) deviation of q (N, D) from q_ref (N, D): mean, max, final."""
    dev_cm = 100 * np.linalg.norm(fk.tcp_positions_np(q) - fk.tcp_positions_np(q_ref), axis=-1)
    jdev = np.linalg.norm(q[:, pidx] - q_ref[:, pidx], axis=1)
    return {
        "joint_dev_mean_rad": float(jdev.mean()),
        "joint_dev_max_rad": float(jdev.max()),
        "joint_dev_final_rad": float(jdev[-1]),
        "cart_pos_dev_mean_cm": float(dev_cm.mean()),
        "cart_pos_dev_max_cm": float(dev_cm.max()),
        "cart_pos_dev_final_cm": float(dev_cm[-1].mean()),
    }


def write_synthetic_run(path: str | Path, iterations: int = 50, seed: int = 0) -> Path:
    """A ``run.mcap`` with a config message and a few RSL-RL style scalar curves."""
    rng = np.random.default_rng(seed)
    path = Path(path)
    with McapJsonWriter(path) as w:
        w.write(
            RUN_CONFIG,
            {
                "config": {"robot": {"name": "iiwa7"}, "seed": seed, "reward": {"w_dev": 1.0}},
                "train_cfg": {"num_steps_per_env": 24, "algorithm": {"class_name": "PPO"}},
            },
            0,
        )
        for it in range(iterations):
            values = {
                "Loss/value": float(np.exp(-it / 20) + 0.05 * rng.random()),
                "Loss/surrogate": float(-0.01 * rng.random()),
                "Train/mean_reward": float(10 * (1 - np.exp(-it / 15)) + rng.normal(0, 0.2)),
                "Perf/total_fps": float(20000 + rng.normal(0, 300)),
            }
            if it >= 2:  # appears only after the first episodes end, as in RSL-RL
                values["Train/mean_episode_length"] = float(60 - 20 * (1 - np.exp(-it / 15)))
            w.write(TRAIN_SCALARS, {"iteration": it, "values": values}, (it + 1) * 10**9)
            if it >= 2:  # McapLogWriter keys RSL-RL's `.../time` tags by their step: elapsed whole seconds
                w.write(
                    TRAIN_SCALARS,
                    {
                        "iteration": int(2.5 * it),
                        "values": {"Train/mean_reward/time": values["Train/mean_reward"]},
                    },
                    (it + 1) * 10**9 + 1,
                )
    return path
