"""Where and why the free-standing ARMAR-4 falls: per-episode pelvis tilt direction, timing and upper-body motion.

Runs the evaluation plan of ``pathrl-eval`` (same episodes: ``segments=paper``, seed, PyBullet, 100 envs) with the
policy or controller of a model directory, and records after every decision step the pelvis reading (offset,
orientation, tilt), the commanded joint state and the TCP positions. Writes one JSON with, per episode: fall time,
the direction of the pelvis lean when it crossed 30 deg, the peak lean before, and the upper-body motion in the
second before the fall (or over the whole episode when it did not fall).

    OMP_NUM_THREADS=1 PATHRL_THREADS=1 .venv/bin/python tools/lab/armar4_fall_study.py \
        models/tracking/armar4_legs_target_point_balancing datasets/armar4/target_point 200 /tmp/a4_study.json \
        [controller spec as JSON, e.g. '{"name": "balance"}'] [episodes of the plan, e.g. 24,43] [plan seed]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import torch

from pathrl.baselines.balance import BalanceCfg, lean_vector
from pathrl.baselines.com import StaticCom
from pathrl.dataset.io import load_pathset
from pathrl.envs.registry import EVAL_ENV, EnvRequest, make_env
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.eval.evaluate import PYBULLET_ENVS
from pathrl.eval.rollout import rollout
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.segments import evaluation_plan
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.robot.model import load_robot
from pathrl.runs import load_policy, load_run, make_controller, policy_scale

ANKLE_HEIGHT = BalanceCfg.ankle_height  # m, ankle joints above the floor (the ZMP lies on the floor)


class Recorder:
    """Wraps a policy; before every action it stores the env's state of the last step (all envs)."""

    def __init__(self, env: PathTrackingEnv, policy):
        self.env, self.policy, self.rows = env, policy, []

    def __call__(self, obs):
        e = self.env
        self.rows.append({"reading": e.feedback.reading.clone(), "pos": e.pos.clone(), "vel": e.vel.clone(),
                          "acc": e.acc.clone(), "t": e.episode_length_buf.clone()})
        return self.policy(obs)


def _episode(rows: list[dict], i: int, fk: ForwardKinematics, com: StaticCom, path_index: torch.Tensor, dt: float,
             failed_at: int | None, n_steps: int) -> dict:
    """Diagnosis of env slot `i` of one batch (rows[k]: the state of all envs after k steps)."""
    steps = rows
    last = min(n_steps if failed_at is None else failed_at, len(steps) - 1)
    read = torch.stack([r["reading"][i] for r in steps[: last + 1]])  # (T, 8)
    lean = lean_vector(read[:, 3:7]).numpy()  # (T, 2) forward, left (rad)
    pos = torch.stack([r["pos"][i] for r in steps[: last + 1]])
    acc = torch.stack([r["acc"][i] for r in steps[: last + 1]])
    tcp = fk.tcp_positions(pos).numpy()  # (T, 2, 3)
    tcp_acc = np.zeros(len(tcp)) if len(tcp) < 3 else np.r_[0, np.linalg.norm(
        (tcp[2:] - 2 * tcp[1:-1] + tcp[:-2]) / dt**2, axis=2).max(axis=1), 0]
    tcp_vel = np.zeros(len(tcp)) if len(tcp) < 2 else np.r_[0, np.linalg.norm(
        (tcp[1:] - tcp[:-1]) / dt, axis=2).max(axis=1)]
    up_acc = acc[:, path_index].abs().amax(dim=1).numpy()
    w = slice(max(0, last - int(round(1.0 / dt))), last + 1)  # the last second
    c = 100.0 * com.offset(pos).numpy()  # (T, 3) cm, static COM of the commanded posture relative to the ankles
    vel = torch.stack([r["vel"][i] for r in steps[: last + 1]])
    zmp = 100.0 * com.zmp(pos, vel, acc, ANKLE_HEIGHT)[0].numpy()  # (T, 2) cm, ZMP of the commanded motion
    onset = np.flatnonzero(np.abs(np.degrees(lean[:, 0])) > 2.0)
    k = int(np.argmax(np.linalg.norm(lean, axis=1)))
    return {"steps": int(last), "fall_step": failed_at,
            "lean_at_end_deg": np.degrees(lean[-1]).round(2).tolist(),
            "peak_lean_deg": np.degrees(lean[k]).round(2).tolist(), "peak_lean_t": k * dt,
            "pelvis_offset_at_end_cm": (100 * read[-1, :3].numpy()).round(2).tolist(),
            "tcp_x_at_end": tcp[-1, :, 0].round(3).tolist(), "tcp_y_at_end": tcp[-1, :, 1].round(3).tolist(),
            "tcp_z_at_end": tcp[-1, :, 2].round(3).tolist(),
            "tcp_acc_max_last_s": float(tcp_acc[w].max()), "tcp_vel_max_last_s": float(tcp_vel[w].max()),
            "tcp_acc_max_episode": float(tcp_acc.max()), "joint_acc_max_last_s": float(up_acc[w].max()),
            "com_fwd_series_cm": c[:, 0].round(2).tolist(), "com_fwd_min_cm": float(c[:, 0].min()),
            "com_fwd_at_end_cm": float(c[-1, 0]), "com_fwd_at_onset_cm": float(c[onset[0], 0]) if len(onset) else None,
            "lean_onset_s": float(onset[0] * dt) if len(onset) else None,
            "zmp_fwd_series_cm": zmp[:, 0].round(2).tolist(), "zmp_fwd_min_cm": float(zmp[:, 0].min()),
            "zmp_fwd_at_onset_cm": float(zmp[onset[0], 0]) if len(onset) else None,
            "lean_fwd_series_deg": np.degrees(lean[:, 0]).round(1).tolist(),
            "torso_pitch_series": pos[:, path_index[1]].numpy().round(3).tolist(),
            "leg_series": pos[:, :12].numpy().round(3).tolist(),
            "torso_pitch_at_end": float(pos[-1, path_index[1]]), "torso_yaw_at_end": float(pos[-1, path_index[0]])}


def study(run_dir: str, dataset: str, episodes: int, out: str, controller: dict | None = None,
          only: list[int] | None = None, seed: int = 0) -> None:
    """Evaluate `run_dir` (or `controller` on its env) on `episodes` (or the episodes `only` of that plan) and write
    the diagnosis to `out`."""
    torch.set_num_threads(1)
    cfg, ckpt, summary = load_run(Path(run_dir))
    robot = load_robot(cfg["robot"])
    paths = load_pathset(dataset, "test", KnotStrategy.from_cfg(cfg["knots"]), robot=robot)
    plan = evaluation_plan(paths, episodes, "paper", seed)
    ids = torch.as_tensor(only if only else range(episodes))
    plan = type(plan)(*(getattr(plan, f)[ids] for f in ("path", "start_s", "end_s", "end_knot")))
    episodes = len(ids)
    n = min(PYBULLET_ENVS, episodes)
    gap = summary.get("knot_gap_norm") if controller else policy_scale(Path(run_dir), summary)  # RunError without it
    request = EnvRequest("test", num_envs=n, seed=0, knot_gap_norm=gap, paths=paths, robot=robot, backend="pybullet")
    env = make_env(cfg, request, **EVAL_ENV)
    try:
        policy = make_controller(controller, env) if controller else load_policy(cfg, env, ckpt)
        fk = ForwardKinematics(robot)
        com = StaticCom(robot, ["leg_ank2_r0", "leg_ank2_r1"])
        result = []
        for b0 in range(0, episodes, n):
            sub = type(plan)(*(getattr(plan, f)[b0:b0 + n] for f in ("path", "start_s", "end_s", "end_knot")))
            rec = Recorder(env, policy)
            records = rollout(env, rec, sub)
            rec.rows.append({"reading": env.feedback.reading.clone(), "pos": env.pos.clone(),
                             "vel": env.vel.clone(), "acc": env.acc.clone(), "t": env.episode_length_buf.clone()})
            for i, r in enumerate(records):
                up = r.extra["task_series"]["upright"]
                fail = int((up < 0.5).nonzero()[0, 0]) + 1 if bool(up[-1] < 0.5) else None
                d = _episode(rec.rows, i, fk, com, env.path_index, env.cfg.dt, fail, r.steps)
                d.update(episode=int(ids[b0 + i]), duration_s=r.duration_s, path=paths.names[r.path],
                         finish_s=r.finish_step * env.cfg.dt if r.finish_step >= 0 else None)
                result.append(d)
    finally:
        env.feedback.close()
    Path(out).write_text(json.dumps(result, indent=1))
    fell = [d for d in result if d["fall_step"] is not None]
    print(f"{len(fell)}/{len(result)} fell ({100 * len(fell) / len(result):.1f} %), mean duration "
          f"{np.mean([d['duration_s'] for d in result]):.2f} s")


if __name__ == "__main__":
    ctrl = json.loads(sys.argv[5]) if len(sys.argv) > 5 and sys.argv[5] else None
    subset = [int(x) for x in sys.argv[6].split(",")] if len(sys.argv) > 6 and sys.argv[6] else None
    plan_seed = int(sys.argv[7]) if len(sys.argv) > 7 else 0
    study(sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], ctrl, subset, plan_seed)
