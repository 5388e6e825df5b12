"""The students of robots pathrl was not built for (docs/your_robot.md) against TOPP-RA: a Markdown table from the
committed evaluations in results/your_robot/ (``<robot>_student.json`` from pathrl-eval, ``<robot>_toppra.json``
from pathrl-toppra, ``<robot>_training.json`` the shipped run's summary.json), written to results/your_robot/table.md.

    tools/lab/your_robot_table.py [--check]     # --check: exit 1 if table.md is not what the files give
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from pathrl.repro.render import time_out_pct

ROOT = Path(__file__).resolve().parents[2]
DIR = ROOT / "results" / "your_robot"
#: The issue's bars for a student trained in <= 15 min: duration / TOPP-RA and mean Cartesian deviation.
BAR_RATIO, BAR_CM, BAR_MIN = 1.15, 2.0, 15.0


def rows(folder: Path) -> list[dict[str, float | str | int]]:
    """One row per robot with a student, TOPP-RA and training record in `folder`, in name order."""
    out = []
    for student in sorted(folder.glob("*_student.json")):
        robot = student.name.removesuffix("_student.json")
        m = json.loads(student.read_text())
        tp = json.loads((folder / f"{robot}_toppra.json").read_text())
        tr = json.loads((folder / f"{robot}_training.json").read_text())
        out.append({"robot": robot, "trained_on": tr.get("dataset", "random"), "episodes": m["episodes"],
                    "duration_s": m["duration_s"],
                    "toppra_s": tp["toppra_duration_s"], "ratio": m["duration_s"] / tp["toppra_duration_s"],
                    "cm": m["cart_pos_dev_mean_cm"], "cm_max": m["cart_pos_dev_max_cm"],
                    "timeouts": time_out_pct(m),
                    "violations": m["limit_violations"], "minutes": tr["wall_time_s"] / 60.0,
                    "iterations": tr["iterations"], "env_steps_m": tr["env_steps"] / 1e6})
    return out


def markdown(rs: list[dict[str, float | str | int]]) -> str:
    """The table with the bars beside it."""
    lines = ["# Students of new robots against TOPP-RA", "",
             "Written by `tools/lab/your_robot_table.py` from the files beside it. The student recipe "
             "(`+experiment=robot_track_distill`, DAgger from the law tracker) trained on each robot's "
             "generated paths (*trained on*: `pathrl-dataset generate robot=<robot> dataset=<it>`), evaluated "
             "on the 1200 paper segments of the test split of its `dataset=random` paths (deterministic, 240 Hz limit "
             "check) and TOPP-RA on the same segments. "
             f"Bars: <= {BAR_RATIO}x TOPP-RA, <= {BAR_CM} cm mean deviation, trained in <= {BAR_MIN:.0f} min.", "",
             "| robot | trained on | episodes | duration (s) | TOPP-RA (s) | x TOPP-RA | mean / max deviation (cm) | "
             "time-outs (%) | limit violations | training (min, iterations, M steps) | bars met |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rs:
        ok = r["ratio"] <= BAR_RATIO and r["cm"] <= BAR_CM and r["minutes"] <= BAR_MIN and r["violations"] == 0
        lines.append(f"| {r['robot']} | {r['trained_on']} | {r['episodes']} | {r['duration_s']:.2f} | "
                     f"{r['toppra_s']:.2f} | "
                     f"{r['ratio']:.3f} | {r['cm']:.2f} / {r['cm_max']:.2f} | {r['timeouts']:.1f} | "
                     f"{r['violations']} | {r['minutes']:.1f}, {r['iterations']}, {r['env_steps_m']:.1f} | "
                     f"{'yes' if ok else 'no'} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="compare with the committed table.md instead of writing")
    args = ap.parse_args(argv)
    text = markdown(rows(DIR))
    target = DIR / "table.md"
    if args.check:
        same = target.is_file() and target.read_text() == text
        print("table.md is current" if same else "table.md differs from the results", file=sys.stderr)
        return 0 if same else 1
    tmp = target.with_suffix(".tmp")
    tmp.write_text(text)
    tmp.replace(target)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
