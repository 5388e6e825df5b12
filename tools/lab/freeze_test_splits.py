"""Copy the test split of each reproduced dataset into the repository (datasets/<robot>/<name>/).

`make reproduce-tables` evaluates on these committed test paths, so every machine scores the shipped
policies on exactly the same paths (and needs no dataset generation). The meta data keeps the
generator settings and the content hash of the full dataset the split came from.

    tools/lab/freeze_test_splits.py [--src data] [--dest datasets] [--only iiwa7/target_point,...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pathrl.dataset.io import load_dataset, save_dataset

ROOT = Path(__file__).resolve().parents[2]
DATASETS = [("iiwa7", "random"), ("iiwa7", "target_point"), ("iiwa7", "ball_balancing"), ("armar6", "random"),
            ("armar4", "random"), ("armar4", "target_point"), ("iiwa7", "trueadapt_on_plate"),
            ("iiwa7", "trueadapt_in_place")]
#: Only the first N test paths are kept (the ones the tables evaluate), to keep the repository small.
FIRST = {("iiwa7", "trueadapt_on_plate"): 1000, ("iiwa7", "trueadapt_in_place"): 1000}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--src", type=Path, default=ROOT / "data")
    ap.add_argument("--dest", type=Path, default=ROOT / "datasets")
    ap.add_argument("--only", default="", help="comma-separated robot/name pairs (default: all)")
    args = ap.parse_args()
    only = {tuple(x.split("/", 1)) for x in args.only.split(",") if x}
    unknown = only - set(DATASETS)
    if unknown:
        raise SystemExit(f"--only: unknown datasets {sorted('/'.join(u) for u in unknown)}")
    for robot, name in DATASETS:
        if only and (robot, name) not in only:
            continue
        ds = load_dataset(args.src / robot / name)
        meta = {k: v for k, v in ds.meta.items() if k not in ("splits", "content_hash", "created", "stats", "format")}
        meta["frozen_from"] = {"splits": ds.meta["splits"], "content_hash": ds.meta["content_hash"],
                               "created": ds.meta.get("created")}
        stats = {"test": ds.meta["stats"]["test"]} if "test" in ds.meta.get("stats", {}) else None
        items = ds.splits["test"].items()
        if (robot, name) in FIRST:  # a subset: its statistics are recomputed
            items, stats = items[:FIRST[robot, name]], None
            meta["frozen_from"]["first_test_paths"] = len(items)
            if "trajectories" in meta:
                meta["trajectories"] = {"test": trueadapt_stats(robot, [q for _, q in items], meta["sample_dt"])}
        out = save_dataset(args.dest / robot / name, {"test": items}, meta, overwrite=True, stats=stats)
        print(f"{out.path}: {len(out.splits['test'])} test paths")


def trueadapt_stats(robot: str, trajs: list, dt: float) -> dict:
    """The TrueAdapt trajectory statistics (``trajectories`` in dataset.json) of a subset."""
    from pathrl.dataset.trueadapt import trajectory_stats
    from pathrl.robot.external import load_robot_by_name

    return trajectory_stats(trajs, load_robot_by_name(robot), dt)


if __name__ == "__main__":
    main()
