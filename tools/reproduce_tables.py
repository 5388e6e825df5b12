"""`make reproduce-tables`: the paper's tables from shipped policies and TOPP-RA, next to the published values.

For every table row whose model directory exists under models/, the policy is evaluated on the row's
test split with the paper's episode protocol (random segments, fixed seed) and TOPP-RA solves exactly the
same segments. Missing test datasets are generated first (seeded, so the same paths every time).
Outputs: results/tables.md, results/tables.csv, results/raw/<row>/{metrics.json, toppra.json}.

    tools/reproduce_tables.py [--profile full|quick] [--train]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
PAPER = yaml.safe_load((ROOT / "tools" / "paper_tables.yaml").read_text())


@dataclass(frozen=True)
class Row:
    key: str  # row name in paper_tables.yaml
    robot: str
    dataset: str
    model: str  # models/<dir>
    knots: str = "curvature_9"


TABLE_I = [
    Row("iiwa7/random", "iiwa7", "random", "iiwa7_random"),
    Row("iiwa7/target_point", "iiwa7", "target_point", "iiwa7_target_point"),
    Row("iiwa7/ball_balancing", "iiwa7", "ball_balancing", "iiwa7_ball_balancing", "distance_5"),
    Row("armar6/random", "armar6", "random", "armar6_random"),
    Row("armar4_fixed/random", "armar4", "random", "armar4_random"),
    Row("armar4_fixed/target_point", "armar4", "target_point", "armar4_target_point"),
]
PROFILES = {"full": {"episodes": 1200, "num_test": 200}, "quick": {"episodes": 12, "num_test": 200}}


def sh(cmd: list[str]) -> None:
    print("$", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, cwd=ROOT, env=dict(os.environ, OMP_NUM_THREADS="1"))


def ensure_dataset(row: Row, num_test: int) -> Path:
    path = ROOT / "data" / row.robot / row.dataset
    if not (path / "dataset.json").is_file():
        sh([str(BIN / "pathrl-dataset"), "generate", f"robot={row.robot}", f"dataset={row.dataset}",
            f"dataset.num_test={num_test}", "dataset.num_train=0"])
    return path


def run_row(row: Row, profile: dict, out: Path) -> dict | None:
    model = ROOT / "models" / row.model
    if not (model / "config.yaml").is_file():
        print(f"-- {row.key}: no shipped policy at {model.relative_to(ROOT)}; skipped")
        return None
    data = ensure_dataset(row, profile["num_test"])
    raw = out / "raw" / row.model
    raw.mkdir(parents=True, exist_ok=True)
    eps = profile["episodes"]
    sh([str(BIN / "pathrl-eval"), f"run_dir={model}", f"dataset.path={data}", f"episodes={eps}",
        "segments=paper", "seed=0", f"out={raw}"])
    sh([str(BIN / "pathrl-toppra"), f"robot={row.robot}", f"dataset.path={data}", f"knots={row.knots}",
        "segments=paper", f"episodes={eps}", "seed=0", "workers=2", f"out={raw / 'toppra.json'}"])
    return {"metrics": json.loads((raw / "metrics.json").read_text()),
            "toppra": json.loads((raw / "toppra.json").read_text())}


def fmt(x: float | None, nd: int = 2) -> str:
    return "–" if x is None else f"{x:.{nd}f}"


def render(results: dict[str, dict], profile_name: str) -> tuple[str, list[list[str]]]:
    t1 = PAPER["table_I_tracking_no_feedback"]
    cols = t1["columns"]
    lines = [f"# pathrl: the paper's tables reproduced (profile `{profile_name}`)", "",
             "Each cell: **ours** / paper (ratio ours/paper). Episodes: random path segments of the test split "
             "(start U(0,0.8), end U(start+0.2,1) snapped to a knot), fixed seed; TOPP-RA solves the same "
             "segments under the same velocity/acceleration limits.", ""]
    csv_rows = [["table", "row", "metric", "ours", "paper"]]
    lines += ["## Table I: tracking without sensory feedback", "",
              "| row | " + " | ".join(cols) + " | episodes | limit violations |",
              "|---|" + "---|" * (len(cols) + 2)]
    for key, paper in t1["rows"].items():
        if key not in results:
            lines.append(f"| {key} | " + " | ".join(f"– / {p}" for p in paper) + " | – | – |")
            continue
        m = results[key]["metrics"]
        cells = []
        for c, p in zip(cols, paper, strict=True):
            cells.append(f"**{fmt(m[c])}** / {p} ({m[c] / p:.2f})")
            csv_rows.append(["I", key, c, fmt(m[c], 4), str(p)])
        lines.append(f"| {key} | " + " | ".join(cells) + f" | {m['episodes']} | {m['limit_violations']} |")
    t6 = PAPER["table_VI_toppra_timing"]
    lines += ["", "## Table VI: TOPP-RA on the same segments", "",
              "Relative duration = TOPP-RA duration / learned duration (%). Our TOPP-RA honours the limits "
              "exactly (checked at 240 Hz).", "",
              "| row | TOPP-RA duration (s) | relative duration (%) | TOPP-RA max joint dev (rad) | learned / TOPP-RA |",
              "|---|---|---|---|---|"]
    for key, paper in t6["rows"].items():
        if key not in results:
            lines.append(f"| {key} | – / {paper[0]} | – / {paper[1]} | – / {paper[2]} | – |")
            continue
        m, tp = results[key]["metrics"], results[key]["toppra"]
        td = tp["toppra_duration_s"]
        rel = 100.0 * td / m["duration_s"]
        lines.append(f"| {key} | **{fmt(td)}** / {paper[0]} | **{fmt(rel, 1)}** / {paper[1]} | "
                     f"**{fmt(tp['toppra_max_joint_dev_rad'], 4)}** / {paper[2]} | **{fmt(m['duration_s'] / td)}** / "
                     f"{100.0 / paper[1]:.2f} |")
        csv_rows += [["VI", key, "toppra_duration_s", fmt(td, 4), str(paper[0])],
                     ["VI", key, "toppra_relative_duration_pct", fmt(rel, 2), str(paper[1])],
                     ["VI", key, "toppra_max_joint_dev_rad", fmt(tp["toppra_max_joint_dev_rad"], 5), str(paper[2])]]
    t5 = PAPER["table_V_features_vs_toppra"]
    lines += ["", "## Table V: features (TOPP-RA vs learned)", "", "| feature | TOPP-RA | ours |", "|---|---|---|"]
    for k, (a, b) in t5["rows"].items():
        lines.append(f"| {k.replace('_', ' ')} | {'yes' if a else 'no'} | {'yes' if b else 'no'} |")
    missing = [r.key for r in TABLE_I if r.key not in results]
    if missing:
        lines += ["", "Rows without a shipped policy yet: " + ", ".join(missing) + "."]
    return "\n".join(lines) + "\n", csv_rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--profile", choices=sorted(PROFILES), default="full")
    ap.add_argument("--train", action="store_true", help="retrain every policy first (not available yet)")
    ap.add_argument("--out", default=str(ROOT / "results"))
    args = ap.parse_args()
    if args.train:
        sys.exit("error: --train (TRAIN=1) is not implemented yet; train with pathrl-train and copy the run to models/")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    results = {}
    for row in TABLE_I:
        r = run_row(row, PROFILES[args.profile], out)
        if r is not None:
            results[row.key] = r
    md, rows = render(results, args.profile)
    for name, text in (("tables.md", md),):
        tmp = out / f".{name}.tmp"
        tmp.write_text(text)
        os.replace(tmp, out / name)
    tmp = out / ".tables.csv.tmp"
    with open(tmp, "w", newline="") as f:
        csv.writer(f).writerows(rows)
    os.replace(tmp, out / "tables.csv")
    print(md)
    print(f"wrote {out / 'tables.md'} and {out / 'tables.csv'} in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
