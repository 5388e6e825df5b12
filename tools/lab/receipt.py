"""Write a receipt (results/receipts/README.md) from one pathrl-eval's metrics.json: its scalar metrics, what and
how it was measured, and the fingerprints of the model files and test split it read.

    tools/lab/receipt.py METRICS_JSON MODEL_DIR DATASET_DIR OUT_JSON --what TEXT --command TEXT --measured TEXT
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def main() -> None:
    from pathrl.repro.inputs import fingerprint
    from pathrl.storage.atomic import atomic_write

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("metrics", type=Path)
    ap.add_argument("model", type=Path)
    ap.add_argument("dataset", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--what", required=True)
    ap.add_argument("--command", required=True)
    ap.add_argument("--measured", required=True)
    args = ap.parse_args()
    metrics = json.loads(args.metrics.read_text())
    receipt = {"what": args.what, "command": args.command, "measured": args.measured,
               "metrics": {k: v for k, v in metrics.items() if not isinstance(v, (list, dict))},
               "inputs": fingerprint(ROOT, args.model, args.dataset)}
    atomic_write(args.out, json.dumps(receipt, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
