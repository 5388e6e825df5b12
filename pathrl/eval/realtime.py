"""Real-time figure (paper Table IX): computation time per episode over the episode's duration, for one robot
controlled by one policy, with and without the physics simulation of its scene.

Each episode runs one env (the deployment case). Timed per decision: the policy (MLP 256-128), the action's
setpoints (24 at 240 Hz), the valid acceleration range and observation of the next decision and, in the
simulated variant, the 24 PyBullet steps that execute the setpoints (iiwa7: plate and ball; ARMAR-4 with
legs: free-standing on the floor; others: fixed base). The ratio of an episode is its compute time over its
trajectory duration; the table reports the highest ratio over the episodes. Computation time does not
depend on the network's weights, so an untrained network of the paper's size is timed. Times are the
process's CPU time (one torch thread): on an idle core that is the wall time, and it is not inflated by
other load on the machine (e.g. a training run beside it).
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np
import torch

from pathrl import native
from pathrl.dataset.io import load_pathset
from pathrl.envs.rewards import build_reward_terms
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.limits.backend import current
from pathrl.limits.integrate import interpolate_step
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.segments import Segments, evaluation_plan
from pathrl.robot.model import RobotSpec

__all__ = ["REWARD", "main", "realtime_ratios"]


REWARD = {"path_length": {"weight": 4.0}, "deviation_max": {"weight": 0.9}, "deviation_mean": {"weight": 0.9}}


def _scene(robot: RobotSpec):
    if robot.name == "iiwa7":
        from pathrl.sim.ball_plate import BallOnPlateScene

        return BallOnPlateScene(robot)
    if robot.name == "armar4_legs":
        from pathrl.sim.humanoid import StandingScene

        return StandingScene(robot)
    from pathrl.sim.scene import FixedBaseScene

    return FixedBaseScene(robot)


def realtime_ratios(robot: RobotSpec, dataset_path: str, episodes: int = 50, simulate: bool = True,
                    seed: int = 0, compile_limits: bool = True) -> dict[str, Any]:
    """Per-episode compute / duration ratios (%) on paper-protocol segments of a test split.

    With ``compile_limits`` (:class:`pathrl.limits.backend.LimitBackend`) the episodes are first run once untimed: the
    timed pass then repeats states whose kernels are all compiled (a first compilation inside a timed
    episode would dominate its ratio).
    """
    with replace(current(), compiled=compile_limits).active():
        return _realtime_ratios(robot, dataset_path, episodes, simulate, seed, compile_limits)


def _realtime_ratios(robot: RobotSpec, dataset_path: str, episodes: int, simulate: bool, seed: int,
                     compile_limits: bool) -> dict[str, Any]:
    paths = load_pathset(dataset_path, "test", KnotStrategy("curvature", 0.3), robot=robot)
    cfg = TrackingEnvCfg(num_envs=1, seed=seed, autoreset=False, end_obs=True, end_tolerance=0.05)
    env = PathTrackingEnv(cfg, robot, paths, build_reward_terms(REWARD))
    torch.manual_seed(seed)
    mlp = torch.nn.Sequential(torch.nn.Linear(env.num_obs, 256), torch.nn.ELU(), torch.nn.Linear(256, 128),
                              torch.nn.ELU(), torch.nn.Linear(128, robot.dof))
    plan = evaluation_plan(paths, episodes, "paper", seed)
    if compile_limits:
        _timed_episodes(env, mlp, plan, episodes, None)
    scene = _scene(robot) if simulate else None
    try:
        ratios, per_decision = _timed_episodes(env, mlp, plan, episodes, scene)
    finally:
        if scene is not None:
            scene.close()
    r = np.asarray(ratios)
    d = np.asarray(per_decision)
    return {"robot": robot.name, "simulated": simulate, "compile_limits": compile_limits,
            "limits": "native" if current().native and native.available() else "torch", "episodes": episodes,
            "decisions": int(d.size), "max_compute_to_duration_pct": float(r.max()),
            "mean_compute_to_duration_pct": float(r.mean()), "decision_ms_mean": 1e3 * float(d.mean()),
            "decision_ms_max": 1e3 * float(d.max())}


def _timed_episodes(env: PathTrackingEnv, mlp: torch.nn.Module, plan: Segments, episodes: int,
                    scene) -> tuple[list[float], list[float]]:
    """Run the plan's first ``episodes`` segments; per-episode ratio (%) and per-decision CPU times (s)."""
    cfg, c = env.cfg, env.control_steps
    ratios, per_decision = [], []
    for i in range(episodes):
        seg = Segments(plan.path[i : i + 1], plan.start_s[i : i + 1], plan.end_s[i : i + 1],
                       plan.end_knot[i : i + 1])
        env.start_segments(torch.tensor([0]), seg)
        if scene is not None:
            scene.reset(env.pos[0].numpy())
        compute, steps = 0.0, 0
        for _ in range(int(env.budget[0])):
            # timed: what runs on the robot per decision (policy, action -> setpoints, valid range and
            # state for the next decision); untimed: the env's training bookkeeping (progress, reward)
            t0 = time.process_time()
            with torch.inference_mode():
                act = mlp(env.get_observations()["policy"]).to(torch.float64)
            a1 = env.accelerations(act)
            q, qd, _ = interpolate_step(env.pos, env.vel, env.acc, a1, cfg.dt, c)
            dt = time.process_time() - t0
            _, _, done, _ = env.step(act)
            t0 = time.process_time()
            env._update_window()
            if scene is not None:
                scene.follow(q[0].numpy(), qd[0].numpy())
            dt += time.process_time() - t0
            compute += dt
            per_decision.append(dt)
            steps += 1
            if bool(done[0]):
                break
        ratios.append(100.0 * compute / (steps * cfg.dt))
    return ratios, per_decision


def main(argv: list[str] | None = None) -> int:
    """``python -m pathrl.eval.realtime ROBOT DATASET_DIR OUT.json [--episodes N]``: both variants -> JSON."""
    import argparse
    from pathlib import Path

    from pathrl.robot.external import load_robot_by_name
    from pathrl.storage import write_json_atomic

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("robot")
    ap.add_argument("dataset")
    ap.add_argument("out", type=Path)
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--eager", action="store_true", help="limit kernels not compiled")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    robot = load_robot_by_name(args.robot)
    res = {key: realtime_ratios(robot, args.dataset, args.episodes, simulate, compile_limits=not args.eager)
           for key, simulate in (("policy_and_limits", False), ("with_simulation", True))}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out, res)
    for k, v in res.items():
        print(f"{args.robot} {k}: max {v['max_compute_to_duration_pct']:.2f} % of the trajectory duration, "
              f"{v['decision_ms_mean']:.2f} ms per decision (max {v['decision_ms_max']:.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
