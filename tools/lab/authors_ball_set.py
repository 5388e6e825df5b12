"""Ball policies on the authors' released ball test paths, as their evaluation drew them: each path with each of
their four joint sign patterns (reflection vectors), 4 x 200 whole paths.

Their paths are not in this repository: pass a checkout of their code (``--checkout``). The script imports
``tracking/dataset/industrial/ball_balancing`` with its reflections (``pathrl-dataset import --format kiemel-json
--reflections`` does the same in one dataset), writes one dataset per reflection under ``--work``, runs
``pathrl-eval`` on each for every run directory and prints the four results and their mean (end of path, mean
Cartesian deviation, balls lost, limit violations).

Usage:
    .venv/bin/python tools/lab/authors_ball_set.py --checkout <pathTracking> \\
        models/tracking/iiwa7_ball_balancing_reward_scratch_deviation [--backend analytic]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from pathrl.dataset.io import load_dataset, save_dataset
from pathrl.dataset.kiemel import import_kiemel
from pathrl.robot.external import load_robot_by_name

ROOT = Path(__file__).resolve().parents[2]
SOURCE = "tracking/dataset/industrial/ball_balancing"
COLUMNS = ("duration_end_of_path_s", "cart_pos_dev_mean_cm", "ball_fell_pct", "limit_violations")


def reflected_sets(checkout: Path, work: Path) -> list[Path]:
    """Import the authors' ball test set from `checkout` with its reflections (``import_kiemel(reflections=True)``:
    the sign patterns of their ``spline_config.json``, paths named ``<name>_r<i>``) and write one dataset per
    reflection; the dataset dirs."""
    base = import_kiemel(checkout / SOURCE, work / "authors_ball", load_robot_by_name("iiwa7"), overwrite=True,
                         reflections=True)
    meta = {k: v for k, v in base.meta.items() if k not in ("format", "splits", "content_hash", "created", "stats")}
    test = load_dataset(work / "authors_ball").splits["test"]
    by_reflection: dict[int, list] = {}
    for name, knots in zip(test.names, test.knots, strict=True):
        by_reflection.setdefault(int(name.rsplit("_r", 1)[1]), []).append((name, knots))
    out = []
    for i in sorted(by_reflection):
        dest = work / f"authors_ball_reflection{i}"
        save_dataset(dest, {"test": by_reflection[i]}, meta, overwrite=True)
        out.append(dest)
    return out


def evaluate(run: str, dataset: Path, backend: str, out: Path) -> dict[str, float]:
    """`pathrl-eval` of `run` on every whole path of `dataset`; the COLUMNS of its metrics.json."""
    cmd = [
        str(ROOT / ".venv/bin/pathrl-eval"),
        f"run_dir={run}",
        f"dataset.path={dataset}",
        "segments=full",
        "workers=1",
        f"backend={backend}",
        "record=false",
        f"out={out}",
    ]
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL, env={**os.environ, "OMP_NUM_THREADS": "1"})
    metrics = json.loads((out / "metrics.json").read_text())
    return {c: float(metrics[c]) for c in COLUMNS}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="run or model directories")
    ap.add_argument("--checkout", type=Path, required=True, help="the authors' pathTracking checkout")
    ap.add_argument("--backend", default="pybullet", choices=("pybullet", "analytic"))
    ap.add_argument("--work", type=Path, default=None, help="directory for the imported sets (default: a temp dir)")
    args = ap.parse_args()
    if not (args.checkout / SOURCE).is_dir():
        sys.exit(f"error: {args.checkout / SOURCE}: not found (pass the root of the authors' checkout)")
    work = args.work or Path(tempfile.mkdtemp(prefix="authors_ball_"))
    sets = reflected_sets(args.checkout, work)
    print(f"{'run':60s} {'reflection':>10s} " + " ".join(f"{c:>22s}" for c in COLUMNS))
    for run in args.runs:
        rows = [evaluate(run, d, args.backend, work / f"eval_{Path(run).name}_{i}") for i, d in enumerate(sets)]
        for i, r in enumerate(rows):
            print(f"{run:60s} {i:>10d} " + " ".join(f"{r[c]:22.3f}" for c in COLUMNS))
        mean = {c: float(np.mean([r[c] for r in rows])) for c in COLUMNS}
        print(f"{run:60s} {'mean':>10s} " + " ".join(f"{mean[c]:22.3f}" for c in COLUMNS))


if __name__ == "__main__":
    main()
