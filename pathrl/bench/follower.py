"""The follower's benchmarks (:mod:`pathrl.bench`): :class:`pathrl.deploy.Follower`'s latency (``decide``,
``replace_path``), every test path followed to its end at a control rate, and the follower fuzz
(:mod:`pathrl.deploy.fuzz`), each with the load average (wall-clock latencies depend on it)."""

from __future__ import annotations

import os
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from pathrl.deploy.fuzz import fuzz_follower
from pathrl.models import model_dir

__all__ = ["FOLLOWER_END", "FOLLOWER_MODELS", "ROOT", "bench_follower", "bench_follower_end", "follower_benches",
           "follower_fuzz", "load_avg"]

#: The checkout (its shipped models).
ROOT = Path(__file__).resolve().parents[2]

def _ms(wall: list[float], cpu: list[float]) -> dict:
    """Mean / p99 / max of wall-clock and thread CPU times (s) in ms: on a shared machine the wall clock includes
    the time the thread waited for a core, the CPU time does not."""
    w, c = 1e3 * np.asarray(wall), 1e3 * np.asarray(cpu)
    return {"mean_ms": w.mean(), "p99_ms": np.quantile(w, 0.99), "max_ms": w.max(),
            "cpu_mean_ms": c.mean(), "cpu_p99_ms": np.quantile(c, 0.99), "cpu_max_ms": c.max()}


def bench_follower(model: str, dataset: str, decisions: int = 400, changes: int = 100) -> dict:
    """Latency of :class:`pathrl.deploy.Follower` on one thread (warm-up excluded): `decide()` (the shipped policy,
    the env's step, the 24 setpoints; the final approach at path ends) decision after decision along test paths,
    and `replace_path` mid-path to a path from the robot to another test path (those inside the position range; the
    refused ones counted), given as knots and as a path `prepare`d beforehand."""
    from pathrl.dataset.io import load_dataset
    from pathrl.deploy import Follower, FollowerError

    torch.set_num_threads(1)
    follower = Follower.load(model)
    paths = load_dataset(dataset, follower.robot).splits["test"].knots
    wall, cpu, k = [], [], 0
    follower.reset(paths[0])
    while len(wall) < decisions + 50:
        if follower.done:
            k += 1
            follower.reset(paths[k % len(paths)])
        t0, c0 = time.perf_counter(), time.thread_time()
        follower.decide()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.thread_time() - c0)
    res = {"model": model, "decisions": decisions, **_ms(wall[50:], cpu[50:])}
    idx = follower.robot.path_index
    for kind in ("knots", "prepared"):
        wall, cpu, refused, i = [], [], 0, 0
        while len(wall) < changes + 5:
            i += 1
            follower.reset(paths[i % len(paths)])
            for _ in range(10):
                follower.decide()
            new = np.vstack([follower.state[0][idx], paths[(i + 1) % len(paths)]])
            try:  # a straight line from the robot to another path's start: refused where its spline leaves the range
                prepared = follower.prepare(new)
            except FollowerError:
                refused += 1
                continue
            arg = prepared if kind == "prepared" else new
            t0, c0 = time.perf_counter(), time.thread_time()
            follower.replace_path(arg)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.thread_time() - c0)
        res[f"replace_path_{kind}"] = {"changes": changes, "refused": refused, **_ms(wall[5:], cpu[5:])}
    return res


def bench_follower_end(model: str, dataset: str, rate_hz: float = 240.0) -> dict:
    """Every test path followed to its end by :class:`pathrl.deploy.Follower` with setpoints at `rate_hz`: the
    final error (largest joint, rad) from the path's last knot, limit violations of every setpoint (position,
    velocity, acceleration, jerk), the duration and the final approach."""
    from pathrl.dataset.io import load_dataset
    from pathrl.deploy import Follower
    from pathrl.limits.check import limit_violations
    from pathrl.limits.feasible import JointLimits

    torch.set_num_threads(1)
    follower = Follower.load(model, control_rate=rate_hz)
    paths = load_dataset(dataset, follower.robot).splits["test"].knots
    lim, idx = JointLimits.from_robot(follower.robot), follower.robot.path_index
    errors, violations, durations, approach, from_rest, not_done = [], 0, [], [], 0, 0
    for knots in paths:
        follower.reset(knots)
        ps, vs, accs = ([torch.as_tensor(x)[None]] for x in follower.state)
        decisions = 0
        while decisions < 1000:
            sp, decisions = follower.decide(), decisions + 1
            for lst, x in zip((ps, vs, accs), (sp.position, sp.velocity, sp.acceleration), strict=True):
                lst.append(torch.as_tensor(x))
            if follower.done:
                break
        not_done += not follower.done
        violations += int(limit_violations(torch.cat(ps), torch.cat(vs), torch.cat(accs), lim, 1.0 / rate_hz)["total"])
        errors.append(float(np.abs(follower.state[0][idx] - knots[-1]).max()))
        durations.append(0.1 * decisions)
        approach.append(follower.final_approach_s)
        from_rest += follower.approach_from_rest
    e = np.asarray(errors)
    return {"model": model, "rate_hz": rate_hz, "paths": len(paths), "not_done": not_done,
            "final_error_max": e.max(), "final_error_mean": e.mean(), "violations": violations,
            "duration_mean_s": float(np.mean(durations)), "approach_mean_s": float(np.mean(approach)),
            "approach_max_s": float(np.max(approach)), "approaches_from_rest": from_rest}


def load_avg() -> list[float] | None:
    """The system's load average over 1, 5 and 15 min (runnable processes; on a shared machine the wall-clock
    latencies depend on it), or None where the platform has none."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


FOLLOWER_MODELS = (("models/tracking/iiwa7_random", "datasets/iiwa7/random"),
                   ("models/tracking/armar6_random", "datasets/armar6/random"))


FOLLOWER_END = (("models/tracking/iiwa7_random", "datasets/iiwa7/random"),
                ("models/tracking/iiwa7_random_track_distill", "datasets/iiwa7/random"))


def follower_benches(res: dict, quick: bool) -> None:
    """The follower's latency (both robots) and its path ends (iiwa7: both shipped random-path policies)."""
    for model, dataset in FOLLOWER_MODELS:
        res[f"follower_{Path(model).name}"] = bench_follower(model, dataset, 100 if quick else 400,
                                                             10 if quick else 100)
    if not quick:
        for model, dataset in FOLLOWER_END:
            for rate in (100, 240, 500):
                res[f"follower_end_{Path(model).name}_{rate}hz"] = bench_follower_end(model, dataset, rate)
    res["follower_fuzz_iiwa7_random"] = follower_fuzz(quick)


def follower_fuzz(quick: bool) -> dict:
    """The follower under adversarial paths, path changes, stops and measured states (pathrl.deploy.fuzz), 300 trials
    (10 with `quick`), with the load average at its start and end (its time depends on it)."""
    start = load_avg()
    fuzz = fuzz_follower(model_dir("iiwa7_random"), 10 if quick else 300)
    return {**asdict(fuzz), "model": "models/tracking/iiwa7_random", "load_avg": [start, load_avg()]}
