"""The benchmark suite of `make bench` (:mod:`pathrl.bench`) and its output: ``bench/results.json`` (every bench), or
the follower's benches merged into an existing file (``--follower-only``, ``--follower-fuzz-only``).

The realtime timing of a task family comes from its registry ``timing`` step (:mod:`pathrl.families`):
:data:`FAMILY_TIMING` names the model and test split each is timed on.
"""

from __future__ import annotations

import json
import os
import platform
from pathlib import Path
from typing import Any

import torch

from pathrl import native
from pathrl.bench.env import (
    bench_ball_task,
    bench_decision,
    bench_env,
    bench_physics,
    bench_ppo_iteration,
    bench_reference,
    limit_code,
)
from pathrl.bench.follower import ROOT, follower_benches, follower_fuzz, load_avg
from pathrl.eval.limit_fuzz import fuzz_env, fuzz_report
from pathrl.models import model_ref
from pathrl.repro import trueadapt as adapt
from pathrl.storage import write_json_atomic

__all__ = ["FAMILY_TIMING", "MODES", "family_timing", "follower_only", "machine", "merge", "run_suite"]

#: Limit code modes (:func:`pathrl.bench.env.limit_code`) and the suffix of their result keys.
MODES = {"native": "", "torch": "_torch", "eager": "_eager"}
#: The families whose realtime timing is benched: (result key, family, model directory, test split, decisions and,
#: with ``quick``, fewer): the TrueAdapt decision (policy + valid range + setpoints, 50 ms cycle).
FAMILY_TIMING = (("trueadapt_decision", "trueadapt", model_ref(adapt.REALTIME_MODEL),
                  f"datasets/{adapt.ROBOT}/{adapt.REALTIME_DATA}", 2000, 100),)


def machine() -> dict[str, Any]:
    """The machine a result was measured on: CPUs, platform, torch, the native limit code, the load average."""
    return {"cpus": os.cpu_count(), "platform": platform.platform(), "torch": torch.__version__,
            "native_limits": native.available(), "load_avg_start": load_avg()}


def family_timing(name: str, model: Path, dataset: Path, decisions: int) -> dict[str, Any]:
    """The registry ``timing`` step of family `name` on `model` and `dataset`, `decisions` decisions (``episodes``
    of :class:`pathrl.eval.evaluate.EvalOptions`)."""
    from pathrl.eval.evaluate import EvalOptions
    from pathrl.families import family

    return family(name).step("timing")(model, EvalOptions(dataset_path=str(dataset), episodes=decisions))


def merge(out: Path, res: dict[str, Any]) -> None:
    """Write `res` into the JSON file `out`, keeping its other entries (atomic)."""
    old = json.loads(out.read_text()) if out.is_file() else {}
    write_json_atomic(out, {**old, **res})


def follower_only(out: Path, quick: bool, fuzz_only: bool) -> dict[str, Any]:
    """The follower's benches (`fuzz_only`: only its fuzz) merged into `out`; returns what was measured."""
    torch.set_num_threads(1)
    res: dict[str, Any] = {"machine": machine()}
    if fuzz_only:
        fuzz = {"follower_fuzz_iiwa7_random": follower_fuzz(quick)}
        merge(out, fuzz)
        return {**res, **fuzz}
    follower_benches(res, quick)
    res["machine"]["load_avg_end"] = load_avg()
    merge(out, res)
    return res


def _env_benches(res: dict[str, Any], modes: tuple[str, ...], n: int, sec: float) -> None:
    """Env steps/s of iiwa7 and ARMAR-4 legs in every mode and on 2 threads / cores, then one decision per robot."""
    for robot in ("iiwa7", "armar4_legs"):
        for mode in modes:
            res[f"env_{robot}{MODES[mode]}"] = bench_env(robot, n, sec, mode)
        res[f"env_{robot}{MODES[modes[0]]}_threads2"] = bench_env(robot, n, sec, modes[0], threads=2)
        if modes[0] == "native":  # both cores for the native code, torch ops on one
            res[f"env_{robot}_cores2"] = bench_env(robot, n, sec, "native", threads=1, native_threads=2)
    for robot in ("iiwa7", "armar6", "armar4_legs"):
        for mode in modes:
            res[f"decision_{robot}{MODES[mode]}"] = bench_decision(robot, mode=mode)


def _ppo_benches(res: dict[str, Any], mode: str, n: int, quick: bool) -> None:
    """PPO iterations as pathrl-train runs them (2 threads, bfloat16 hidden layers where native), and in float32 on
    2 and 1 threads: what the bfloat16 hidden layers and the threads buy."""
    from pathrl.policy.models import BFLOAT16_EMULATED, bfloat16_slowdown

    # bfloat16 hidden layers only where the CPU has them natively: emulated they run >10x slower (pathrl-train warns)
    res["bfloat16_over_float32_layer"] = bfloat16_slowdown()
    hidden = "float32" if res["bfloat16_over_float32_layer"] > BFLOAT16_EMULATED else "bfloat16"
    with limit_code(mode):
        its = 1 if quick else 4
        for robot in ("iiwa7", "armar4_legs"):
            res[f"ppo_iteration_{robot}"] = bench_ppo_iteration(robot, n, its, hidden_dtype=hidden)
        if hidden == "bfloat16":
            res["ppo_iteration_iiwa7_float32"] = bench_ppo_iteration("iiwa7", n, its, hidden_dtype="float32")
        res["ppo_iteration_iiwa7_float32_1thread"] = bench_ppo_iteration("iiwa7", n, its, 1, "float32")


def _limit_fuzz(res: dict[str, Any], mode: str, quick: bool, fuzz_steps: int) -> None:
    """Adversarial limit fuzz: >= `fuzz_steps` decision steps per robot, every control-rate setpoint checked."""
    fuzz_envs = 256 if quick else 4096
    steps = -(-(20_000 if quick else fuzz_steps) // fuzz_envs)
    torch.set_num_threads(2)
    with limit_code(mode):
        for robot in ("iiwa7", "armar6", "armar4_legs"):
            res[f"limit_fuzz_{robot}"] = fuzz_report([fuzz_env(robot, steps, fuzz_envs, root=ROOT)])[robot]
    torch.set_num_threads(1)


def run_suite(out: Path, quick: bool, seconds: float, modes: tuple[str, ...], fuzz_steps: int) -> dict[str, Any]:
    """Every benchmark (`quick`: tiny sizes; `seconds` per env bench; limit code `modes`, the first the main one),
    written to `out` (atomic); returns the results."""
    torch.set_num_threads(1)
    sec, n = (0.5, 256) if quick else (seconds, 4096)
    res: dict[str, Any] = {"machine": machine()}
    _env_benches(res, modes, n, sec)
    follower_benches(res, quick)
    for key, name, model, dataset, decisions, few in FAMILY_TIMING:
        res[key] = family_timing(name, ROOT / model, ROOT / dataset, few if quick else decisions)
    main_key = f"env_iiwa7{MODES[modes[0]]}"
    res["reference_iiwa7"] = bench_reference("iiwa7", sec)
    res["batched_over_reference_iiwa7"] = res[main_key]["env_steps_per_s"] / res["reference_iiwa7"]["env_steps_per_s"]
    _ppo_benches(res, modes[0], n, quick)
    res["physics_ball_on_plate"] = bench_physics("ball_on_plate", sec)
    res["physics_armar4_standing"] = bench_physics("armar4_standing", sec)
    with limit_code(modes[0]):
        res["ball_task_analytic"] = bench_ball_task("analytic", n, sec)
        res["ball_task_pybullet"] = bench_ball_task("pybullet", 16 if quick else 64, sec)
    _limit_fuzz(res, modes[0], quick, fuzz_steps)
    pyb = res["ball_task_pybullet"]["env_steps_per_s"]
    res["ball_task_analytic_over_pybullet"] = res["ball_task_analytic"]["env_steps_per_s"] / pyb
    # Both sides on both cores (the PyBullet env steps its scenes in 2 worker processes): the faster 2-core setup.
    two = max(res[k]["env_steps_per_s"] for k in (main_key + "_threads2", "env_iiwa7_cores2") if k in res)
    res["kinematic_tracking_over_pybullet_ball"] = two / pyb
    res["kinematic_tracking_1thread_over_pybullet_ball"] = res[main_key]["env_steps_per_s"] / pyb
    res["machine"]["load_avg_end"] = load_avg()
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out, res)
    return res
