"""Benchmarks (`make bench`): env steps/s (batched vs single-env reference), PPO iteration time, and the
time per decision of policy + limits for one env. Writes bench/results.json and prints a table.

Paths are synthetic smooth paths inside the joint limits (no dataset needed), so the numbers measure
the env itself. The valid acceleration range, most of a step, runs in one of three ways (``limits`` in
each result; a :class:`pathrl.limits.backend.LimitBackend`): ``native`` (the C build in ``pathrl/native``, the
default), ``torch`` (the torch reference with compiled kernels, ``pathrl.limits.kernels``) and ``eager`` (torch,
nothing compiled). Threads: 1; 2 (``*_threads2``); and ``*_cores2``: torch on 1 thread, the native code on 2.
Compilation happens in untimed warm-up steps. A family's realtime timing (the TrueAdapt decision) is its registry
``timing`` step. The benchmarks: pathrl/bench/ (env.py, follower.py, suite.py, report.py). ``--quick``: tiny sizes.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> None:
    """Parse the command line and run the suite (or only the follower's benches) of :mod:`pathrl.bench.suite`."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=5.0, help="time per env benchmark")
    ap.add_argument("--quick", action="store_true", help="tiny sizes (tests)")
    ap.add_argument("--limits", default="native,torch,eager",
                    help="valid-range code to measure, comma-separated: native, torch (compiled), eager")
    ap.add_argument("--fuzz-steps", type=int, default=10_000_000,
                    help="adversarial limit fuzz: decision steps per robot (pathrl.eval.limit_fuzz)")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results.json"))
    ap.add_argument("--follower-only", action="store_true",
                    help="only the follower: latency (decide, replace_path) and every test path to its end at "
                         "100, 240 and 500 Hz; merged into --out")
    ap.add_argument("--follower-fuzz-only", action="store_true",
                    help="only the follower fuzz (adversarial paths, path changes, stops, measured states; "
                         "pathrl.deploy.fuzz), with the load average in its entry; merged into --out")
    args = ap.parse_args()
    modes = tuple(args.limits.split(","))
    if not modes or any(m not in ("native", "torch", "eager") for m in modes):
        ap.error(f"--limits: expected a comma-separated subset of native,torch,eager, got {args.limits!r}")
    from pathrl.bench.report import print_follower, print_results
    from pathrl.bench.suite import follower_only, run_suite

    out = Path(args.out)
    if args.follower_only or args.follower_fuzz_only:
        print_follower(follower_only(out, args.quick, args.follower_fuzz_only))
        return
    print_results(run_suite(out, args.quick, args.seconds, modes, args.fuzz_steps), out)


if __name__ == "__main__":
    main()
