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

WINDOWS = {"task_failed": "ball_lost", "deviation": "deviation_limit", "robot_stopped": "reached_end"}


def window(rows: list[dict[str, str]], first: int, last: int) -> dict[str, float | int]:
    """Mean termination shares and duration (s) over iterations first..last (inclusive) of the curve's rows."""
    sel = [r for r in rows if first <= int(r["iteration"]) <= last]
    mean = {name: sum(float(r[f"Episode_Termination/{key}"] or 0.0) for r in sel) / len(sel)
            for key, name in WINDOWS.items()}
    mean["duration_s"] = sum(float(r["Metrics/duration_s"] or 0.0) for r in sel) / len(sel)
    return {"first": first, "last": last, **mean}


def summary(rows: list[dict[str, str]], what: str, paper_steps: float) -> dict:
    """The JSON summary of curve rows (strings, as read back from the CSV)."""
    last = rows[-1]
    n = int(last["iteration"]) + 1
    return {"what": what, "iterations": n, "env_steps": int(float(last["env_steps"])),
            "wall_time_s": float(last["wall_time_s"]), "paper_env_steps": paper_steps,
            "last_100_iterations": window(rows, n - 100, n - 1), "iterations_300_399": window(rows, 300, 399)}


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
