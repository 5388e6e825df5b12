"""A long training run's learning curve, committed: the CSV of every logged iteration (training rollouts, with the
action noise) and a JSON summary of the windows the docs quote (the last 100 iterations; iterations 300-399).

    tools/lab/curve_summary.py RUN_DIR OUT_DIR [--paper-steps N] [--what TEXT]

Writes OUT_DIR/<experiment>_seed<S>.csv and .json (atomically). Failure columns are the env's episode terminations:
task_failed (the ball left the plate), deviation (the deviation limit), robot_stopped (the end of the path reached).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
from pathlib import Path

from pathrl.storage.atomic import atomic_write
from pathrl.train.ship import curve_csv, read_training_log, training_curve

#: Names the summary gives some curve columns (the ball task's terminations); other columns keep their own.
NAMES = {"Episode_Termination/task_failed": "ball_lost", "Episode_Termination/deviation": "deviation_limit",
         "Episode_Termination/robot_stopped": "reached_end", "Metrics/duration_s": "duration_s",
         "Metrics/success": "success"}


def window(rows: list[dict[str, str]], first: int, last: int) -> dict[str, float | int] | None:
    """Means over iterations first..last (inclusive) of the curve's termination shares, duration (s) and success
    (where logged), named by NAMES; None when the run logged none of those iterations."""
    sel = [r for r in rows if first <= int(r["iteration"]) <= last]
    if not sel:
        return None
    cols = [c for c in rows[0] if c.startswith("Episode_Termination/") or c in NAMES]
    mean = {NAMES.get(c, c.split("/")[-1]): sum(float(r[c] or 0.0) for r in sel) / len(sel) for c in cols}
    return {"first": first, "last": last, **mean}


def summary(rows: list[dict[str, str]], what: str, paper_steps: float) -> dict:
    """The JSON summary of curve rows (strings, as read back from the CSV)."""
    last = rows[-1]
    n = int(last["iteration"]) + 1
    return {"what": what, "iterations": n, "env_steps": int(float(last["env_steps"])),
            "wall_time_s": float(last["wall_time_s"]), "paper_env_steps": paper_steps,
            "last_100_iterations": window(rows, max(n - 100, 0), n - 1), "iterations_300_399": window(rows, 300, 399)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--paper-steps", type=float, default=629e6, help="the paper's env steps for this task")
    ap.add_argument("--what", default="", help="one sentence: which run, which task")
    args = ap.parse_args(argv)
    per_iter, msgs = read_training_log(args.run_dir, 10**9)
    text = curve_csv(training_curve(per_iter, msgs))
    rows = list(csv.DictReader(io.StringIO(text)))
    name = f"{args.run_dir.parent.name}_{args.run_dir.name}"
    args.out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write(args.out_dir / f"{name}.csv", text)
    atomic_write(args.out_dir / f"{name}.json", json.dumps(summary(rows, args.what, args.paper_steps), indent=2) + "\n")
    print(f"{name}: {len(rows)} iterations -> {args.out_dir}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
