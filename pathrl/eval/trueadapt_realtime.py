"""Time per TrueAdapt adaptation decision (TrueAdapt Sec. V: the valid acceleration range took at most 0.9 ms on an
Intel i9-9900K): one env, one torch thread, the shipped policy, along the trajectories of a test split.

Timed per decision, as CPU time of the process (on an idle core the wall time, and not inflated by other load): the
policy on the observation, the action clipped into the valid range (paper eq. 8), the 240 Hz setpoints of the step,
the state at its end, the valid acceleration range there and the next observation. Untimed: the env's step itself
(the ball, the reward, the bookkeeping), which recomputes the same quantities. The valid range is also reported on
its own, the paper's figure.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pathrl.envs.trueadapt import TrueAdaptEnv, clip_to_range
from pathrl.limits.feasible import valid_acceleration_range
from pathrl.limits.integrate import end_of_step, interpolate_step

__all__ = ["decision_times", "main", "measure"]

#: The first decisions are not reported (allocations and caches warm up).
WARMUP = 50


def decision_times(env: TrueAdaptEnv, policy: torch.nn.Module, decisions: int) -> dict[str, Any]:
    """Per-decision CPU times (module docstring) of `decisions` decisions of env 0 (an autoresetting env of one
    env); milliseconds: mean, 99th percentile and max of the decision and the max of the valid range alone."""
    if env.num_envs != 1 or not env.cfg.autoreset:
        raise ValueError("decision_times needs a one-env TrueAdapt env with autoreset")
    lim, dt, c = env.limits, env.cfg.dt, env.control_steps
    total, valid = [], []
    obs = env.get_observations()
    with torch.inference_mode():
        while len(total) < decisions + WARMUP:
            t0 = time.process_time()
            act = policy(obs)
            a1 = clip_to_range(act.to(env.pos.dtype), lim.acc, env.a_min, env.a_max)
            interpolate_step(env.pos, env.vel, env.acc, a1, dt, c)
            p1, v1 = end_of_step(env.pos, env.vel, env.acc, a1, dt)
            t1 = time.process_time()
            valid_acceleration_range(p1, v1, a1, lim, dt, env.limit_backend)
            t2 = time.process_time()
            obs, *_ = env.step(act)  # untimed: recomputes the above, steps the ball, the reward
            t3 = time.process_time()
            env._observe()
            total.append((t2 - t0) + (time.process_time() - t3))
            valid.append(t2 - t1)
    t, v = 1e3 * np.asarray(total[WARMUP:]), 1e3 * np.asarray(valid[WARMUP:])
    return {"decisions": int(t.size), "decision_ms_mean": float(t.mean()),
            "decision_ms_p99": float(np.quantile(t, 0.99)), "decision_ms_max": float(t.max()),
            "valid_range_ms_max": float(v.max()), "valid_range_ms_mean": float(v.mean()), "cycle_ms": 1e3 * dt,
            "max_pct_of_cycle": float(100.0 * t.max() / (1e3 * dt))}


def measure(model: Path, dataset: str | None, decisions: int) -> dict[str, Any]:
    """:func:`decision_times` of the shipped model directory `model` on the test split `dataset` (default: the
    committed test split of the model's dataset), analytic ball."""
    from pathrl import native
    from pathrl.envs.device import EVAL_DEVICE
    from pathrl.envs.trueadapt import build_trueadapt_env
    from pathrl.limits.backend import current
    from pathrl.runs import committed_split, load_policy, load_run

    cfg, ckpt, _ = load_run(model)
    cfg["task"]["backend"] = "analytic"
    ds = dataset or committed_split(cfg["dataset"]["path"], "test")
    env = build_trueadapt_env(cfg, "test", 1, ds, 0, autoreset=True, device=EVAL_DEVICE)  # not the run's device
    res = decision_times(env, load_policy(cfg, env, ckpt), decisions)
    return {"model": str(model), "dataset": ds, "threads": torch.get_num_threads(),
            "limits": "native" if current().native and native.available() else "torch", **res}


def main(argv: list[str] | None = None) -> int:
    """``python -m pathrl.eval.trueadapt_realtime MODEL OUT.json [--dataset DIR] [--decisions N]``."""
    import argparse

    from pathrl.storage import write_json_atomic

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("model", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--dataset", default=None)
    ap.add_argument("--decisions", type=int, default=2000)
    args = ap.parse_args(argv)
    if args.decisions < 1:
        ap.error(f"--decisions must be >= 1, got {args.decisions}")
    if not (args.model / "config.yaml").is_file():
        ap.error(f"{args.model}: not a model directory (no config.yaml)")
    torch.set_num_threads(1)
    res = measure(args.model, args.dataset, args.decisions)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out, res)
    print(f"{args.model}: {res['decision_ms_mean']:.3f} ms per decision (p99 {res['decision_ms_p99']:.3f}, max "
          f"{res['decision_ms_max']:.3f} = {res['max_pct_of_cycle']:.1f} % of the {res['cycle_ms']:.0f} ms cycle); "
          f"valid range max {res['valid_range_ms_max']:.3f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
