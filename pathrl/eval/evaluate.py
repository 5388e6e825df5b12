"""Evaluate a trained run (or a shipped model directory): metrics.json + episodes.mcap."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pathrl.config.paper import load as load_paper
from pathrl.dataset.io import load_pathset
from pathrl.envs.registry import EVAL_ENV, EnvRequest, make_env, task_cfg, tracking_paths
from pathrl.envs.terminations import TerminationReason
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.eval.metrics import METRIC_KEYS, matched_samples, per_joint_errors, sample_deviations
from pathrl.eval.rollout import EpisodeRecord, rollout
from pathrl.limits.backend import current
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits
from pathrl.logging.mcap_io import McapJsonWriter
from pathrl.logging.schema import (
    EVAL_EPISODE_METRICS,
    EVAL_JOINT_STATE,
    EVAL_REFERENCE,
    EVAL_ROBOT,
    EVAL_TASK,
    EVAL_TCP,
    JOINT_STATE_SCHEMA,
    JOINT_STATE_SCHEMA_NAME,
    ROBOT_SCHEMA,
    ROBOT_SCHEMA_NAME,
)
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.pathset import PathSet
from pathrl.paths.segments import evaluation_plan
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.robot.model import RobotSpec, load_robot
from pathrl.runs import RunError, committed_split, load_policy, load_run, make_controller, policy_scale
from pathrl.storage import inside_models, write_json_atomic

__all__ = ["FAILURE_METRIC", "PYBULLET_ENVS", "EvalOptions", "EvalSource", "evaluate", "output_dir_of", "run_rollouts",
           "write_episodes_mcap"]


@dataclass(frozen=True)
class EvalOptions:
    """How :func:`evaluate` evaluates a run (the keys of ``pathrl-eval``, :class:`pathrl.schema.EvalAppCfg`).

    ``dataset_path``: None for the run's own dataset (its committed `split`). ``episodes``: None for one per path
    with ``segments="full"``, else 1200. ``out_dir``: None for :func:`output_dir_of` (never inside ``models/``
    unless ``write_models``). ``task`` adds a feedback task to a run trained without one (e.g. ``ball_on_plate``:
    the ball rides along unobserved, as the paper's "no balancing reward" row); a run with a task is simulated with
    ``backend`` (PyBullet by default, whatever it was trained with). ``compile_limits``: the rollouts run with
    compiled limit kernels (:class:`pathrl.limits.backend.LimitBackend`; same results to rounding); off by default:
    an evaluation is a few hundred steps, too short to earn back the per-process tracing (iiwa7, 1200 episodes:
    17 s eager, 35 s compiled). ``open_loop``: the task's sensor stays at its first value of each episode
    (:class:`FrozenSensor`). ``checkpoint``: a checkpoint file name in the run directory (e.g. ``model_99.pt``)
    instead of the latest one. ``out_of_limits``: paths of the dataset that leave the robot's position limits are
    refused or clipped (``refuse`` | ``clip``). ``workers``: the PyBullet worker processes of a TrueAdapt run
    (:mod:`pathrl.families.trueadapt`; None: its config's).
    """

    dataset_path: str | None = None
    split: str = "test"
    episodes: int | None = None
    segments: str = "paper"  # paper | full
    seed: int = 0
    out_dir: Path | None = None
    write_models: bool = False  # allow an output directory inside models/ (the shipped policies)
    num_envs: int = 1200
    record: bool = True  # also write episodes.mcap
    progress: bool = True
    task: str | None = None
    backend: str = "pybullet"  # pybullet | analytic
    compile_limits: bool = False
    open_loop: bool = False
    checkpoint: str | None = None
    out_of_limits: str = "refuse"
    workers: int | None = None  # PyBullet worker processes of a TrueAdapt run (None: its config's)


def output_dir_of(run_dir: Path, out_dir: Path | None = None) -> Path:
    """Where an evaluation of `run_dir` writes: `out_dir` if given, else the run directory, except for a shipped
    model (a directory under ``models/``, :func:`pathrl.storage.inside_models`): ``runs/eval/<name>`` (relative to the
    working directory), so that nothing is written into ``models/`` unless asked."""
    if out_dir is not None:
        return Path(out_dir)
    if inside_models(run_dir):
        return Path("runs", "eval", Path(run_dir).resolve().name)
    return Path(run_dir)


def _checked_out_dir(run_dir: Path, opts: EvalOptions) -> Path:
    """:func:`output_dir_of` `run_dir`; RunError if it is inside ``models/`` and ``opts.write_models`` is off."""
    out = output_dir_of(run_dir, opts.out_dir)
    if inside_models(out) and not opts.write_models:
        raise RunError(f"out_dir {out} is inside models/ (the shipped policies); give another out_dir or set "
                       "write_models to write the evaluation there")
    return out


def evaluate(run_dir: Path, opts: EvalOptions = EvalOptions()) -> dict[str, Any]:
    """Evaluate the policy of `run_dir` deterministically as `opts` says; write
    metrics.json (+ episodes.mcap) into :func:`output_dir_of` (checked first) and return the metrics.

    A task failure (ball off the plate) does not end an evaluation episode: the tracking metrics cover the whole
    path and the failure is reported per episode (``task_failed``) and as ``task_failed_pct``. A model-based
    controller's directory (``controller:`` in its config, :func:`pathrl.runs.make_controller`) evaluates like a
    policy.
    """
    out = _checked_out_dir(run_dir, opts)
    records, rollout_s, source = run_rollouts(run_dir, opts)
    return _finish(records, rollout_s, source, opts, out)


def run_rollouts(run_dir: Path, opts: EvalOptions = EvalOptions()) -> tuple[list[EpisodeRecord], float, EvalSource]:
    """The deterministic rollouts :func:`evaluate` measures: the episode records, their wall time (s) and what ran
    them (:class:`EvalSource`); nothing is written. For analyses beyond metrics.json (e.g. tools/lab/plate_tilt.py)."""
    torch.set_num_threads(int(os.environ.get("PATHRL_THREADS", "1")))
    cfg, ckpt, summary = load_run(run_dir)
    ckpt = _checkpoint(run_dir, ckpt, opts.checkpoint)
    gap = policy_scale(run_dir, summary) if ckpt is not None else summary.get("knot_gap_norm")
    cfg = _with_task(cfg, opts.task)
    robot = load_robot(cfg["robot"])
    knots = KnotStrategy.from_cfg(cfg["knots"])
    ds_path = opts.dataset_path or committed_split(cfg["dataset"]["path"], opts.split)
    paths = load_pathset(ds_path, opts.split, knots, robot=robot, out_of_limits=opts.out_of_limits)
    episodes = opts.episodes
    if episodes is None:
        episodes = paths.num_paths if opts.segments == "full" else int(load_paper("tracking").value("episodes"))
    plan = evaluation_plan(paths, episodes, opts.segments, opts.seed)
    if gap is None:  # a controller's directory without a summary: D of its training split, as in training
        gap = tracking_paths(cfg, "train", robot=robot).max_knot_gap()
    # The deviation cut-off is a training device; evaluation tracks every episode to its end or budget (EVAL_ENV).
    has_task = task_cfg(cfg)["feedback"] is not None
    num_envs = opts.num_envs
    if has_task and opts.backend == "pybullet":
        num_envs = min(num_envs, PYBULLET_ENVS)  # one PyBullet client per env
    if opts.open_loop and not has_task:
        raise RunError("open_loop=true: the run has no feedback task to freeze (give task=...)")
    request = EnvRequest(opts.split, num_envs=min(num_envs, episodes), seed=opts.seed, knot_gap_norm=gap,
                         paths=paths, robot=robot, backend=opts.backend, open_loop=opts.open_loop)
    try:  # task / robot mismatch, a scene that cannot be built
        env = make_env(cfg, request, **EVAL_ENV)
    except (ValueError, RuntimeError) as exc:
        raise RunError(str(exc)) from None
    try:
        policy = _policy(run_dir, cfg, env, ckpt)
        t0 = time.perf_counter()
        with replace(current(), compiled=opts.compile_limits).active():
            records = _run(env, policy, plan, episodes, opts.progress)
        rollout_s = time.perf_counter() - t0
    finally:
        if env.feedback is not None:
            env.feedback.close()
    return records, rollout_s, EvalSource(run_dir, ckpt, ds_path, robot, env, paths, cfg if has_task else None)


@dataclass(frozen=True)
class EvalSource:
    """What the rollouts ran: the run directory and its checkpoint (None: a controller), the dataset path, the robot,
    the env and its path bank, and the run config if it has a feedback task (None: path tracking only)."""

    run_dir: Path
    ckpt: Path | None
    ds_path: str
    robot: RobotSpec
    env: PathTrackingEnv
    paths: PathSet
    task_run_cfg: dict[str, Any] | None


def _policy(run_dir: Path, cfg: dict[str, Any], env: PathTrackingEnv, ckpt: Path | None):
    """The run's policy at `ckpt`, or its model-based controller (``controller:`` in `cfg`)."""
    if "controller" not in cfg:
        return load_policy(cfg, env, ckpt)
    try:
        return make_controller(cfg["controller"], env)
    except ValueError as exc:
        raise RunError(f"{run_dir}: {exc}") from None


def _checkpoint(run_dir: Path, latest: Path | None, name: str | None) -> Path | None:
    """The checkpoint to evaluate: the file `name` in `run_dir` if given, else the run's `latest`."""
    if name is None:
        return latest
    if Path(name).name != name:
        raise RunError(f"checkpoint={name}: give a file name in run_dir (e.g. model_99.pt)")
    ckpt = Path(run_dir) / name
    if not ckpt.is_file():
        raise RunError(f"checkpoint not found: {ckpt}")
    return ckpt


def _with_task(cfg: dict[str, Any], task: str | None) -> dict[str, Any]:
    """The run's config with feedback task `task` added (None, ``tracking``: unchanged); the task's sensor is
    observed only if the run was trained with it."""
    if task is None or task == "tracking":
        return cfg
    trained_task = task_cfg(cfg)
    if trained_task["feedback"] not in (None, task):
        raise RunError(f"task={task}: the run was trained with task {trained_task['feedback']}")
    observe = trained_task["feedback"] == task and trained_task["observe"]
    return {**cfg, "task": {**trained_task, "name": task, "feedback": task, "observe": observe}}


#: Name of the failure share in the paper's tables, per feedback task.
FAILURE_METRIC = {"ball_on_plate": "ball_fell_pct", "standing": "fell_pct"}

#: Parallel envs (= PyBullet clients, spread over the worker processes) when evaluating in PyBullet.
PYBULLET_ENVS = 100


def _run(env: PathTrackingEnv, policy, plan, episodes: int, progress: bool) -> list[EpisodeRecord]:
    bar = _progress(episodes) if progress else None
    records = rollout(env, policy, plan, progress=(lambda k: bar[0].update(bar[1], advance=k)) if bar else None)
    if bar:
        bar[0].stop()
    return records


def _finish(records: list[EpisodeRecord], rollout_s: float, src: EvalSource, opts: EvalOptions,
            out: Path) -> dict[str, Any]:
    """Per-episode and aggregate metrics of the rollouts (`rollout_s`: their wall time, s); writes metrics.json
    (+ episodes.mcap) into `out`."""
    robot, env, paths = src.robot, src.env, src.paths
    t0 = time.perf_counter()
    fk = env.fk  # the env's kinematics (evaluation envs are on the CPU: EVAL_ENV)
    limits = JointLimits.from_robot(robot)
    setpoints, path_index = [r.setpoints for r in records], torch.as_tensor(robot.path_index)
    matched = matched_samples(setpoints, path_index, paths, [r.path for r in records], [r.start_s for r in records],
                              [r.end_s for r in records])
    devs = sample_deviations(setpoints, matched, path_index, fk)
    per_episode = [_episode_metrics(r, dev, env, limits, paths) for r, dev in zip(records, devs, strict=True)]
    per_joint = per_joint_errors(torch.cat([e - r for e, r in matched]), robot.path_joints)
    metrics = _aggregate(per_episode, robot, src.ds_path, opts.split, opts.segments, opts.seed, per_joint)
    if src.task_run_cfg is not None:
        t = task_cfg(src.task_run_cfg)
        backend = type(getattr(env.feedback, "inner", env.feedback)).__name__
        metrics["task"] = {"name": t["name"], "backend": backend, "simulator": opts.backend, "observed": t["observe"],
                           "open_loop": opts.open_loop}
        metrics["task_failed_pct"] = 100.0 * float(np.mean([p["task_failed"] for p in per_episode]))
        metrics[FAILURE_METRIC[t["feedback"]]] = metrics["task_failed_pct"]
        metrics["task_failed_after_end_pct"] = 100.0 * float(np.mean([p["task_failed_after_end"] for p in per_episode]))
    metrics["eval_wall_time_s"] = time.perf_counter() - t0 + rollout_s
    metrics["rollout_wall_time_s"] = rollout_s
    metrics["run_dir"] = str(src.run_dir)
    metrics["checkpoint"] = src.ckpt.name if src.ckpt is not None else None
    out.mkdir(parents=True, exist_ok=True)
    if opts.record:
        write_episodes_mcap(out / "episodes.mcap", robot, paths, records, per_episode, fk)
    write_json_atomic(out / "metrics.json", metrics)
    return metrics


def _progress(total: int):
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    p = Progress("[bold]evaluate", BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    task = p.add_task("episodes", total=total)
    p.start()
    return p, task


def _episode_metrics(r: EpisodeRecord, dev: dict[str, float], env: PathTrackingEnv, limits: JointLimits,
                     paths) -> dict[str, Any]:
    viol = limit_violations(r.setpoints, r.setpoint_vel, r.setpoint_acc, limits, r.extra["control_dt"])
    return {
        "episode": r.episode,
        "path": paths.names[r.path],
        "start_s": r.start_s,
        "end_s": r.end_s,
        "duration_s": r.duration_s,
        "duration_end_of_path_s": r.finish_step * r.extra["dt"] if r.finish_step >= 0 else None,
        "termination": r.termination,
        "terminated_early": r.termination != TerminationReason.STOPPED.label,
        # the task's ok flag (ball on the plate, robot upright) is sticky: 0 at the end <=> it failed at some point
        **(_task_failure(r, env.feedback.ok_value) if r.extra.get("task") else {}),
        **dev,
        "limit_violations": int(viol["total"]),
    }


def _task_failure(r: EpisodeRecord, ok_value: str) -> dict[str, Any]:
    """Whether the task failed (ball lost, robot fallen), when (s after the episode start) and whether after the
    end of the path was reached (during the braking or the standstill that follows)."""
    ok = r.extra["task_series"][ok_value]  # (T,) sticky: 1 until the failure
    failed = bool(ok[-1] < 0.5)
    step = int((ok < 0.5).nonzero()[0, 0]) + 1 if failed else None  # steps done when the failure was seen
    return {"task_failed": failed, "task_failed_at_s": step * r.extra["dt"] if failed else None,
            "task_failed_after_end": failed and 0 <= r.finish_step < step}


def _aggregate(per: list[dict[str, Any]], robot: RobotSpec, dataset: str, split: str, segments: str,
               seed: int, per_joint: dict[str, dict[str, float]] | None = None) -> dict[str, Any]:
    def mean(key: str) -> float:
        return float(np.mean([p[key] for p in per]))

    out: dict[str, Any] = {"robot": robot.name, "dataset": str(dataset), "split": split, "segments": segments,
                           "seed": seed, "episodes": len(per), "duration_s": mean("duration_s")}
    for k in METRIC_KEYS:
        out[k] = mean(k)
    out["terminated_early_pct"] = 100.0 * mean("terminated_early")
    reached = [p["duration_end_of_path_s"] for p in per if p["duration_end_of_path_s"] is not None]
    out["duration_end_of_path_s"] = float(np.mean(reached)) if reached else None  # over episodes that got there
    out["reached_end_pct"] = 100.0 * len(reached) / len(per)
    out["limit_violations"] = int(sum(p["limit_violations"] for p in per))
    if per_joint is not None:  # offset / RMS / share of each path joint over all samples (metrics.per_joint_errors)
        out["per_joint"] = per_joint
    out["per_episode"] = per
    return out


def write_episodes_mcap(path: Path, robot: RobotSpec, paths, records: list[EpisodeRecord],
                        per_episode: list[dict[str, Any]], fk: ForwardKinematics) -> None:
    """Evaluation episodes as MCAP (JSON): robot once, per episode reference + states + TCP + metrics.

    Written to a temporary file renamed at the end (no per-episode flush needed: an interrupted evaluation
    leaves no file)."""
    tmp = path.with_suffix(".mcap.tmp")
    w = McapJsonWriter(tmp)
    w.channel(EVAL_ROBOT, ROBOT_SCHEMA_NAME, ROBOT_SCHEMA)
    w.channel(EVAL_JOINT_STATE, JOINT_STATE_SCHEMA_NAME, JOINT_STATE_SCHEMA)
    w.write(EVAL_ROBOT, {
        "robot": robot.name, "joint_names": list(robot.joints), "path_joints": list(robot.path_joints),
        "position_limits": robot.pos_limits.tolist(),
        "velocity_limits": [[-v, v] for v in robot.vel_limits.tolist()],
        "acceleration_limits": [[-v, v] for v in robot.acc_limits.tolist()],
        "jerk_limits": [[-v, v] for v in robot.jerk_limits.tolist()],
        "urdf": str(robot.urdf), "tcp_links": [t.link for t in robot.tcps],
    }, 0)
    path_index = torch.as_tensor(robot.path_index)
    refs = []  # reference samples per episode: arc length (200,), path joints (200, M), full robot (200, D)
    for r in records:
        s = torch.linspace(r.start_s, r.end_s, 200, dtype=torch.float64)
        q_ref = paths.position_at(torch.full((200,), r.path, dtype=torch.long), s)
        full = r.pos[-1].expand(200, -1).clone()
        full[:, path_index] = q_ref
        refs.append((s, q_ref, full))
    tcp_refs = fk.tcp_poses_of([full for _, _, full in refs])
    tcps = fk.tcp_poses_of([r.pos for r in records])
    t_ns = 0
    for r, m, (s, q_ref, _), (tcp_ref, _), (tcp_p, tcp_q) in zip(records, per_episode, refs, tcp_refs, tcps,
                                                                  strict=True):
        w.write(EVAL_REFERENCE, {"episode": r.episode, "path": paths.names[r.path], "s": s,
                                   "position": q_ref, "tcp_position": tcp_ref}, t_ns)
        dt = r.extra["dt"]
        pos, vel, acc, tcp_p, tcp_q = (x.tolist() for x in (r.pos, r.vel, r.acc, tcp_p, tcp_q))
        series = {n: v.to(torch.float64).tolist() for n, v in (r.extra.get("task_series") or {}).items()}
        for k in range(len(pos)):
            tk = t_ns + int(round(k * dt * 1e9))
            w.write(EVAL_JOINT_STATE, {"episode": r.episode, "t": k * dt, "position": pos[k],
                                       "velocity": vel[k], "acceleration": acc[k]}, tk)
            w.write(EVAL_TCP, {"episode": r.episode, "t": k * dt, "position": tcp_p[k],
                               "orientation_xyzw": tcp_q[k]}, tk)
            if k > 0 and series:  # feedback after step k (ball on the plate, pelvis tilt)
                w.write(EVAL_TASK, {"episode": r.episode, "t": k * dt, **{n: v[k - 1] for n, v in series.items()}},
                        tk)
        t_ns += int(round((r.steps + 1) * dt * 1e9))
        w.write(EVAL_EPISODE_METRICS, m, t_ns)
    w.close()
    os.replace(tmp, path)
