"""Time-to-quality curves: evaluate a run's checkpoints on its test split and find when it met the paper's row.

    python tools/lab/time_to_quality.py --run runs/iiwa7_random/seed0 --row iiwa7/random [--run OTHER --label ...]

Each run's checkpoints (every ``--every`` iterations and the last) are evaluated with the paper's protocol
(deterministic policy, 1200 test segments of ``datasets/<robot>/<dataset>``, the committed split; whole paths with
``--segments full``, as the ball-balancing row), then
``--out`` gets ``curve.json`` (per run: the points, the target and the minutes to reach it) and ``curve.png``
(duration and mean Cartesian deviation against training wall time). The target is a Table I row of
``pathrl/config/paper/tracking.yaml``: duration <= the paper's, mean Cartesian deviation <= ``--dev-factor`` x the
paper's, no limit violation. Evaluations are cached per checkpoint under ``--out``: a rerun only adds new ones.

A feedback run (ball on a plate, standing) is evaluated in PyBullet by default; ``--backend analytic`` uses the
batched model it trained on (seconds per checkpoint). Each run's points are also written to ``<out>/<label>.csv``
(iteration, env steps, wall time, duration, time to the path end, deviation, violations, task failures):

    python tools/lab/time_to_quality.py --run runs/iiwa7_ball_balancing_reward_scratch_fixed_lr/seed0 \
        --dataset datasets/iiwa7/ball_balancing --segments full --backend analytic --out-of-limits clip --every 10 \
        --out results/ball_balancing_from_scratch/fixed_lr
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import asdict
from pathlib import Path

import yaml

from pathrl.config.paper import load as load_paper
from pathrl.eval.curve import (
    PAPER_EPISODES,
    CurveProtocol,
    Target,
    curve_record,
    evaluate_curve,
    first_reaching,
    plot_curves,
)
from pathrl.repro.tables import PATH_ROBOT, TABLE_I
from pathrl.storage import atomic_write, write_json_atomic
from pathrl.train.ship import curve_csv


def paper_target(row: str, dev_factor: float) -> Target:
    """Duration and dev_factor x mean Cartesian deviation of a Table I row (e.g. ``iiwa7/random``)."""
    table = load_paper("tracking").table(TABLE_I)
    if row not in table.rows:
        raise ValueError(f"--row: {row!r} is not a Table I row; known: {sorted(table.rows)}")
    values = table.row(row)
    return Target(float(values["duration_s"]), dev_factor * float(values["cart_pos_dev_mean_cm"]))


def default_dataset(run: Path) -> str:
    """The committed test split of the run's robot and dataset kind."""
    cfg = yaml.safe_load((run / "config.yaml").read_text())
    robot = cfg["robot"]["name"]
    return f"datasets/{PATH_ROBOT.get(robot, robot)}/{cfg['dataset']['name']}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", action="append", required=True, type=Path, help="run directory (repeat to compare)")
    ap.add_argument("--label", action="append", help="legend label per --run (default: the run directory)")
    ap.add_argument("--row", help="Table I row whose quality is the target, e.g. iiwa7/random")
    ap.add_argument("--dev-factor", type=float, default=1.0, help="allowed deviation over the paper's (default 1)")
    ap.add_argument("--dataset", help="dataset directory (default: datasets/<robot>/<dataset> of the run)")
    ap.add_argument("--every", type=int, default=50, help="evaluate checkpoints every this many iterations")
    ap.add_argument("--episodes", type=int, help="episodes per checkpoint (default: 1200 segments, or every path with "
                    "--segments full)")
    ap.add_argument("--segments", choices=("paper", "full"), default="paper",
                    help="the paper's random segments (default) or whole paths (the ball-balancing row)")
    ap.add_argument("--backend", choices=("pybullet", "analytic"), default="pybullet",
                    help="simulator of a feedback task (default pybullet; analytic: the batched training model)")
    ap.add_argument("--out-of-limits", choices=("refuse", "clip"), default="refuse",
                    help="paths of the dataset that leave the position limits: refuse (default) or clip")
    ap.add_argument("--out", type=Path, required=True,
                    help="output directory (curve.json, curve.png, <label>.csv, cache)")
    args = ap.parse_args(argv)
    labels = args.label or [str(r) for r in args.run]
    if len(labels) != len(args.run):
        ap.error(f"--label: give one per --run ({len(args.run)}), got {len(labels)}")
    try:
        target = paper_target(args.row, args.dev_factor) if args.row else None
        curves, records = {}, []
        for run, label in zip(args.run, labels, strict=True):
            if not (run / "config.yaml").is_file():
                raise ValueError(f"--run: {run} is not a run directory (no config.yaml)")
            dataset = args.dataset or default_dataset(run)
            episodes = args.episodes or (PAPER_EPISODES if args.segments == "paper" else None)
            protocol = CurveProtocol(episodes, args.segments, args.backend, args.out_of_limits)
            pts = evaluate_curve(run, dataset, args.out / label.replace("/", "_"), args.every, protocol)
            curves[label] = pts
            records.append(curve_record(pts, target, {"label": label, "run": str(run), "dataset": dataset,
                                                      "segments": args.segments, "episodes": episodes,
                                                      "backend": args.backend}))
    except (ValueError, OSError) as exc:
        print(f"error: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "curve.json", {"row": args.row, "runs": records})
    for label, pts in curves.items():
        atomic_write(args.out / f"{label.replace('/', '_')}.csv", curve_csv([asdict(p) for p in pts]))
    plot_curves(curves, target, args.out / "curve.png", title=args.row or "")
    for rec, (label, pts) in zip(records, curves.items(), strict=True):
        hit = first_reaching(pts, target) if target else None
        last = pts[-1]
        print(f"{label}: last (it. {last.iteration}) {last.duration_s:.2f} s at {last.cart_pos_dev_mean_cm:.2f} cm"
              + (f"; target reached at it. {hit.iteration}"
                 + (f", {rec['minutes_to_target']:.1f} min" if rec["minutes_to_target"] is not None else "")
                 if hit else ("; target not reached" if target else "")))
    print(f"-> {args.out / 'curve.json'}, {args.out / 'curve.png'}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    raise SystemExit(main())
