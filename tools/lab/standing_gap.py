"""Sim-to-sim gap of the free-standing ARMAR-4: the batched torch model (``task.backend=analytic``,
:class:`pathrl.sim.standing.AnalyticStanding`) against PyBullet (``pybullet``, the evaluation backend).

For each model directory (a shipped policy or a leg controller), the same episodes of the evaluation plan
(``pathrl-eval``'s: test split, ``segments=paper``, `seed`) run three times:

* closed loop in PyBullet and closed loop in the model (each backend's pelvis reading feeds the policy): falls,
  mean pelvis tilt (over the upright steps), time to the fall, and the per-step gap between the two runs (tilt,
  pelvis offset) over the steps both are upright (the runs drift apart as the policy sees different readings);
* open loop: the model replays the joint setpoints PyBullet's run commanded, so the per-step gap is the model's
  alone: tilt and pelvis offset errors over the steps PyBullet stayed upright, and whether the model falls too.

Then env steps per second of the tracking env with random actions: the model at 64 and 1024 envs, PyBullet at 64
envs on one worker process. Everything single-threaded; run it niced beside a training:

    OMP_NUM_THREADS=1 nice -n 19 .venv/bin/python tools/lab/standing_gap.py --episodes 40 --out /tmp/gap.json
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import torch

from pathrl.dataset.io import load_pathset
from pathrl.envs.registry import EVAL_ENV, EnvRequest, make_env
from pathrl.eval.rollout import rollout
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.segments import evaluation_plan
from pathrl.robot.model import load_robot
from pathrl.runs import load_policy, load_run, make_controller
from pathrl.sim.standing import FALL_TILT_RAD, AnalyticStanding

MODELS = ["models/tracking/armar4_legs_balance_controller", "models/tracking/armar4_legs_target_point_balancing"]


class Recorder:
    """Wraps a policy and keeps the pelvis reading (N, 8) the env's feedback holds before every action."""

    def __init__(self, env, policy):
        self.env, self.policy, self.rows = env, policy, []

    def __call__(self, obs):
        self.rows.append(self.env.feedback.reading.clone().to(torch.float64))
        return self.policy(obs)


def _setup(run_dir: str, dataset: str):
    cfg, ckpt, summary = load_run(Path(run_dir))
    cfg = {**cfg, "task": {**cfg["task"], "workers": 1}}
    robot = load_robot(cfg["robot"])
    paths = load_pathset(dataset, "test", KnotStrategy.from_cfg(cfg["knots"]), robot=robot)
    return cfg, ckpt, summary, robot, paths


def run_backend(run_dir: str, dataset: str, episodes: int, seed: int, backend: str) -> dict:
    """Closed-loop rollouts of `run_dir` on the plan's first `episodes` episodes in `backend`: per episode the pelvis
    readings after each step (T + 1, 8), steps, fall step (or None) and the commanded setpoints."""
    cfg, ckpt, summary, robot, paths = _setup(run_dir, dataset)
    plan = evaluation_plan(paths, episodes, "paper", seed)
    request = EnvRequest("test", num_envs=episodes, seed=seed, knot_gap_norm=summary["knot_gap_norm"], paths=paths,
                         robot=robot, backend=backend)
    env = make_env(cfg, request, **EVAL_ENV)
    try:
        policy = make_controller(cfg["controller"], env) if "controller" in cfg else load_policy(cfg, env, ckpt)
        rec = Recorder(env, policy)
        t0 = time.perf_counter()
        records = rollout(env, rec, plan)
        wall = time.perf_counter() - t0
        rec.rows.append(env.feedback.reading.clone().to(torch.float64))
    finally:
        env.feedback.close()
    reading = torch.stack(rec.rows, dim=1)  # (N, T + 1, 8): [0] at reset
    out = []
    for i, r in enumerate(records):
        up = r.extra["task_series"]["upright"]
        fall = int((up < 0.5).nonzero()[0, 0]) + 1 if bool((up < 0.5).any()) else None
        out.append({"reading": reading[i, : r.steps + 1], "steps": r.steps, "fall": fall, "setpoints": r.setpoints})
    return {"episodes": out, "wall_s": wall, "dt": float(cfg["env"]["dt"]), "robot": robot}


def summarize(run: dict) -> dict:
    """Falls (%), mean tilt over the upright steps (deg), mean time to the fall (s)."""
    eps, dt = run["episodes"], run["dt"]
    falls = [e["fall"] for e in eps if e["fall"] is not None]
    tilt = np.concatenate([e["reading"][1: _upright(e["fall"], e["steps"]) + 1, 7].numpy() for e in eps])
    return {"falls_pct": 100.0 * len(falls) / len(eps), "falls": len(falls),
            "fell": [i for i, e in enumerate(eps) if e["fall"] is not None],
            "mean_tilt_deg": float(np.degrees(tilt.mean())), "max_tilt_deg_upright": float(np.degrees(tilt.max())),
            "time_to_fall_s": float(np.mean(falls) * dt) if falls else None, "wall_s": run["wall_s"]}


def _upright(fall: int | None, steps: int) -> int:
    """The last step after which an episode's robot is still upright."""
    return steps if fall is None else fall - 1


def _gap(a: torch.Tensor, b: torch.Tensor) -> dict:
    """Per-step gaps of readings a, b (T, 8): tilt (deg) and pelvis offset (cm), mean and max."""
    tilt = np.degrees((a[:, 7] - b[:, 7]).abs().numpy())
    off = 100.0 * (a[:, :3] - b[:, :3]).norm(dim=1).numpy()
    return {"tilt_deg": tilt, "offset_cm": off}


def _pool(gaps: list[dict]) -> dict:
    out = {}
    for key in ("tilt_deg", "offset_cm"):
        v = np.concatenate([g[key] for g in gaps]) if gaps else np.zeros(1)
        out[key] = {"mean": float(v.mean()), "p95": float(np.quantile(v, 0.95)), "max": float(v.max())}
    return out


def closed_loop_gap(pb: dict, an: dict) -> dict:
    """The two closed-loop runs step by step, over the steps (after the first) both robots are upright."""
    gaps = []
    for a, b in zip(pb["episodes"], an["episodes"], strict=True):
        end = min(_upright(a["fall"], a["steps"]), _upright(b["fall"], b["steps"]))
        if end >= 1:
            gaps.append(_gap(a["reading"][1:end + 1], b["reading"][1:end + 1]))
    both = sum(a["fall"] is not None and b["fall"] is not None for a, b in zip(pb["episodes"], an["episodes"],
                                                                            strict=True))
    return {**_pool(gaps), "fell_in_both": both}


def open_loop_gap(pb: dict, robot, control_rate: float = 240.0) -> dict:
    """The model replays PyBullet's commanded setpoints (all episodes at once, the ended ones holding their last
    setpoint); its readings against PyBullet's over the steps (after the first) both robots are upright, and the
    episodes where only one of them fell."""
    eps = pb["episodes"]
    c = int(round(control_rate * pb["dt"]))
    t_max = max(e["steps"] for e in eps)
    q = torch.stack([torch.cat([e["setpoints"][1:], e["setpoints"][-1:].expand(c * t_max - c * e["steps"], -1)])
                     for e in eps]).to(torch.float64)  # (E, T c, D)
    model = AnalyticStanding(robot, len(eps), control_rate)
    model.reset(torch.arange(len(eps)), torch.stack([e["setpoints"][0] for e in eps]).to(torch.float64))
    rows, fell = [model.reading.clone()], torch.full((len(eps),), -1)
    for k in range(t_max):
        out = model.step(q[:, k * c:(k + 1) * c], torch.zeros_like(q[:, k * c:(k + 1) * c]))
        rows.append(model.reading.clone())
        fell = torch.where(out.failed & (fell < 0), torch.full_like(fell, k + 1), fell)
    reading = torch.stack(rows, dim=1)
    gaps, agree, model_only, pb_only, lead = [], 0, 0, 0, []
    for i, e in enumerate(eps):
        m_fell = 0 < int(fell[i]) <= e["steps"]
        end = min(_upright(e["fall"], e["steps"]), _upright(int(fell[i]) if m_fell else None, e["steps"]))
        if end >= 1:
            gaps.append(_gap(e["reading"][1:end + 1], reading[i, 1:end + 1]))
        agree += m_fell == (e["fall"] is not None)
        model_only += m_fell and e["fall"] is None
        pb_only += (not m_fell) and e["fall"] is not None
        if m_fell and e["fall"] is not None:
            lead.append((e["fall"] - int(fell[i])) * pb["dt"])
    return {**_pool(gaps), "fall_agreement_pct": 100.0 * agree / len(eps), "fell_in_model_only": model_only,
            "fell_in_pybullet_only": pb_only, "model_falls_earlier_by_s": float(np.mean(lead)) if lead else None}


def speed(run_dir: str, dataset: str, backend: str, num_envs: int, seconds: float) -> float:
    """Env steps per second of the run's training env (auto-reset, random actions) with `backend`."""
    cfg, _, summary, robot, paths = _setup(run_dir, dataset)
    request = EnvRequest("test", num_envs=num_envs, seed=0, knot_gap_norm=summary["knot_gap_norm"], paths=paths,
                         robot=robot, backend=backend)
    env = make_env(cfg, request)
    gen = torch.Generator().manual_seed(0)
    try:
        env.reset()
        env.step(torch.rand(num_envs, env.num_actions, generator=gen) * 2 - 1)
        t0, steps = time.perf_counter(), 0
        while time.perf_counter() - t0 < seconds:
            env.step(torch.rand(num_envs, env.num_actions, generator=gen) * 2 - 1)
            steps += 1
        return num_envs * steps / (time.perf_counter() - t0)
    finally:
        env.feedback.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", nargs="+", default=MODELS, help="model directories (policies or leg controllers)")
    ap.add_argument("--dataset", default="datasets/armar4/target_point", help="dataset with the test split")
    ap.add_argument("--episodes", type=int, default=40, help="episodes of the evaluation plan (one batch)")
    ap.add_argument("--seed", type=int, default=0, help="plan seed (pathrl-eval's seed)")
    ap.add_argument("--speed-seconds", type=float, default=20.0, help="wall time per speed measurement (0: skip)")
    ap.add_argument("--out", default=None, help="write the numbers as JSON here")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    report: dict = {"episodes": args.episodes, "seed": args.seed, "fall_tilt_deg": math.degrees(FALL_TILT_RAD)}
    for run_dir in args.models:
        pb = run_backend(run_dir, args.dataset, args.episodes, args.seed, "pybullet")
        an = run_backend(run_dir, args.dataset, args.episodes, args.seed, "analytic")
        row = {"pybullet": summarize(pb), "analytic": summarize(an), "closed_loop_gap": closed_loop_gap(pb, an),
               "open_loop_gap": open_loop_gap(pb, pb["robot"])}
        report[run_dir] = row
        print(run_dir, json.dumps(row, indent=1))
    if args.speed_seconds > 0:
        run_dir = args.models[0]
        report["env_steps_per_s"] = {
            "analytic_64": speed(run_dir, args.dataset, "analytic", 64, args.speed_seconds),
            "analytic_1024": speed(run_dir, args.dataset, "analytic", 1024, args.speed_seconds),
            "pybullet_64_one_worker": speed(run_dir, args.dataset, "pybullet", 64, args.speed_seconds)}
        print(json.dumps(report["env_steps_per_s"], indent=1))
    if args.out:
        Path(args.out).write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
