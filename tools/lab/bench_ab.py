"""Env steps/s of two checkouts, interleaved in one process (a speed change measured on a noisy machine).

On the shared 2-core reference machine the same code runs 30-40 % faster or slower from one process to the
next, so two `make bench` runs cannot resolve a 20 % change. This script imports the `pathrl` of each
checkout in turn (purging the other from ``sys.modules``), steps the benchmark env (``pathrl.bench.env.make_env``,
or ``make_env`` of `tools/bench.py` in a checkout from before ``pathrl/bench/``; synthetic paths,
random actions, 4096 envs, compiled limit kernels, one thread) and reports CPU-time rates per repetition:

    python tools/lab/bench_ab.py --base /path/to/other/checkout [--robot iiwa7] [--reps 4]

Both checkouts must be importable with this interpreter (same dependencies). Prints one line per checkout.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import torch  # noqa: E402

HERE = Path(__file__).resolve().parents[2]


def _load(root: Path, roots: list[Path]):
    """The module with the benchmark env of `root` (``pathrl.bench.env``, or an older checkout's `tools/bench.py`)
    with that checkout's `pathrl` imported."""
    for name in [m for m in sys.modules if m == "pathrl" or m.startswith("pathrl.") or m == "bench"]:
        del sys.modules[name]
    others = {str(r) for r in roots} | {str(r / "tools") for r in roots}
    sys.path[:] = [p for p in sys.path if p not in others]
    sys.path[:0] = [str(root), str(root / "tools")]
    import importlib

    if (root / "pathrl" / "bench" / "env.py").is_file():
        return importlib.import_module("pathrl.bench.env")
    return importlib.import_module("bench")


def rate(bench, robot: str, steps: int, warmup: int = 30) -> float:
    """Env steps per CPU second of `bench.make_env(robot, 4096)` (compiled limit kernels) over `steps` steps after
    `warmup`."""
    from pathrl.robot.external import load_robot_by_name

    spec = load_robot_by_name(robot)
    try:
        from pathrl.limits.backend import LimitBackend
    except ImportError:  # a checkout from before the explicit limit backend: its process-wide switch
        from pathrl.limits import kernels

        kernels.set_compiled(True)
        env = bench.make_env(spec, 4096)
    else:
        env = bench.make_env(spec, 4096, limit_backend=LimitBackend(compiled=True))
    gen = torch.Generator().manual_seed(0)
    actions = [torch.rand(env.num_envs, env.num_actions, generator=gen) * 2 - 1 for _ in range(8)]
    for k in range(warmup):
        env.step(actions[k % 8])
    t0 = time.process_time()
    for k in range(steps):
        env.step(actions[k % 8])
    return env.num_envs * steps / (time.process_time() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", required=True, help="the other checkout (e.g. a clone at an older commit)")
    ap.add_argument("--robot", default="iiwa7")
    ap.add_argument("--reps", type=int, default=4)
    ap.add_argument("--steps", type=int, default=60)
    args = ap.parse_args()
    torch.set_num_threads(1)
    trees = {"base": Path(args.base).resolve(), "this": HERE}
    if not (trees["base"] / "pathrl").is_dir():
        sys.exit(f"--base {args.base}: no pathrl package there")
    results: dict[str, list[float]] = {k: [] for k in trees}
    for _ in range(args.reps):
        for name, root in trees.items():
            results[name].append(rate(_load(root, list(trees.values())), args.robot, args.steps))
    for name, rates in results.items():
        med = sorted(rates)[len(rates) // 2]
        print(f"{args.robot} {name:4s} ({trees[name]}): " + " ".join(f"{r / 1e3:.0f}k" for r in rates)
              + f"  env steps/s per CPU second, median {med / 1e3:.0f}k")


if __name__ == "__main__":
    main()
