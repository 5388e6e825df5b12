"""Copy the test split of each reproduced dataset into the repository (datasets/<robot>/<name>/).

`make reproduce-tables` evaluates on these committed test paths, so every machine scores the shipped
policies on exactly the same paths (and needs no dataset generation). The meta data keeps the
generator settings and the content hash of the full dataset the split came from.

    tools/freeze_test_splits.py [--src data] [--dest datasets] [--only iiwa7/target_point,...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pathrl.dataset.io import load_dataset, save_dataset

ROOT = Path(__file__).resolve().parents[1]
DATASETS = [("iiwa7", "random"), ("iiwa7", "target_point"), ("iiwa7", "ball_balancing"), ("armar6", "random"),
            ("armar4", "random"), ("armar4", "target_point")]


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
        out = save_dataset(args.dest / robot / name, {"test": ds.splits["test"].items()}, meta, overwrite=True,
                           stats=stats)
        print(f"{out.path}: {len(ds.splits['test'])} test paths")


if __name__ == "__main__":
    main()
