"""`make reproduce-tables`: the paper's Tables I-VI from shipped policies and TOPP-RA, next to the published values.

Every evaluation (a shipped policy on a test split) and every TOPP-RA baseline runs once, even when several table
rows use it; the TrueAdapt paper's Table I, its limit validation and time per decision run through the TrueAdapt
family's registry steps. Outputs (atomic): results/tables.md, tables.csv, tables.tex, figures/*.png, raw/<evaluation>/
metrics.json (with inputs.json: the SHA-256 of its model and test split; --reuse re-evaluates a result whose inputs
changed), raw/<toppra>.json; each step's console output in results/logs/<step>.log. The rows are sweeps/<table>.yaml;
--only takes models, TrueAdapt evaluations (e.g. trueadapt_validation) and table file names (`make table T=II` is
--only table_II): their rows are evaluated, every table is rendered from the results in --out.
The plan, its steps and the rendering: pathrl/repro/ (plan.py, steps.py, run.py, outputs.py; docs/reproducing.md).

Profiles: full (1200 paper segments per evaluation, the committed test splits and models/); quick (12 episodes;
with --train tiny datasets and trainings under results/quick/: the whole pipeline in minutes, meaningless numbers).
--train (TRAIN=1) trains (resumes) every policy first and ships it to models/<family>/<model>. Evaluations run
--jobs at a
time (JOBS=N; default the CPU count, at most 8); the real-time measurements run last, one at a time.

    tools/reproduce_tables.py [--profile full|quick] [--train] [--only MODEL,...] [--reuse] [--out DIR] [--jobs N]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from pathrl.repro.sweeps import SweepsError  # noqa: E402


def main() -> int:
    """Parse the command line and run :func:`pathrl.repro.run.reproduce`; a bad argument or sweeps/ file is one
    line on stderr."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--profile", choices=["full", "quick"], default="full")
    ap.add_argument("--train", action="store_true", help="train (resume) every policy first, then ship it")
    ap.add_argument("--only", default="", help="comma-separated model or sweeps/ table names (table_II): only their "
                    "rows (the other tables render from the results already in --out)")
    ap.add_argument("--reuse", action="store_true", help="keep evaluation / TOPP-RA results already in --out")
    ap.add_argument("--out", default=None, help="output dir (default results/, quick: results/quick/)")
    ap.add_argument("--jobs", type=int, default=min(os.cpu_count() or 1, 8),
                    help="evaluations run at a time (default: the CPU count, at most 8)")
    args = ap.parse_args()
    try:  # the rows are read from sweeps/<table>.yaml at import: a broken file is its one-line error
        from pathrl.repro.run import check, reproduce

        check(args.profile, args.only, args.jobs)
    except (SweepsError, ValueError) as exc:
        sys.exit(f"error: {exc}")
    return reproduce(args.profile, args.only, args.train, args.reuse, args.out and Path(args.out), args.jobs)

if __name__ == "__main__":
    sys.exit(main())
