"""Turn a training run into a shipped model directory (models/<family>/<experiment>/).

Copies the resolved config and training summary and the last checkpoint without its optimizer
state (actor + critic weights only). Evaluate it afterwards with
`pathrl-eval run_dir=models/<family>/<name>` (writes runs/eval/<name>/metrics.json; into the model's folder only with
`out=models/<family>/<name> write_models=true`).

    tools/ship_model.py runs/<experiment>/seed0 models/<family>/<experiment>
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pathrl.train.ship import ship


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("dest", type=Path)
    args = ap.parse_args()
    try:
        ship(args.run_dir, args.dest)
    except FileNotFoundError as exc:
        raise SystemExit(f"error: {exc}") from None
    print(f"shipped {args.run_dir} -> {args.dest}")


if __name__ == "__main__":
    main()
