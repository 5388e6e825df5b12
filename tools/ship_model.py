"""Turn a training run into a shipped model directory (models/<robot>_<dataset>[_<variant>]/).

Copies the resolved config and training summary and the last checkpoint without its optimizer
state (actor + critic weights only). Evaluate it afterwards with
`pathrl-eval run_dir=models/<name>` (writes metrics.json there).

    tools/ship_model.py runs/<experiment>/seed0 models/iiwa7_random
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
from pathlib import Path

import torch

from pathrl.train.runner import latest_checkpoint


def training_stats(run_dir: Path, last_iter: int) -> dict:
    """Iterations, env steps and wall time up to checkpoint `last_iter`, from run.mcap and the config."""
    import yaml

    from pathrl.logging.mcap_io import read_messages

    cfg = yaml.safe_load((run_dir / "config.yaml").read_text())
    per_iter = int(cfg["agent"]["num_steps_per_env"]) * int(cfg["env"]["num_envs"])
    rows = [m for t, _, m in read_messages(run_dir / "run.mcap") if t == "/train/scalars"]
    rows = [m for m in rows if m["iteration"] <= last_iter]
    wall = sum(m["values"].get("Perf/collection_time", 0.0) + m["values"].get("Perf/learning_time", 0.0) for m in rows)
    last = rows[-1]["values"] if rows else {}
    return {"checkpoint_iteration": last_iter, "iterations": last_iter + 1, "env_steps": (last_iter + 1) * per_iter,
            "steps_per_iteration": per_iter, "wall_time_s": round(wall, 1),
            "final_train_metrics": {k: v for k, v in last.items() if k.startswith(("Metrics/", "Episode_Termination/"))}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("dest", type=Path)
    args = ap.parse_args()
    ckpt = latest_checkpoint(args.run_dir)
    if ckpt is None or not (args.run_dir / "config.yaml").is_file():
        raise SystemExit(f"error: {args.run_dir} has no config.yaml or checkpoint")
    state = torch.load(ckpt, weights_only=True, map_location="cpu")
    slim = {k: state[k] for k in ("actor_state_dict", "critic_state_dict", "iter")}
    slim["infos"] = {"source_checkpoint": ckpt.name}
    args.dest.mkdir(parents=True, exist_ok=True)
    tmp = args.dest / "model.pt.tmp"
    torch.save(slim, tmp)
    os.replace(tmp, args.dest / "model.pt")
    shutil.copyfile(args.run_dir / "config.yaml", args.dest / "config.yaml")
    summary = json.loads((args.run_dir / "summary.json").read_text()) if (args.run_dir / "summary.json").is_file() else {}
    summary.update(training_stats(args.run_dir, int(state["iter"])))
    summary["shipped_from"] = str(args.run_dir)
    (args.dest / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"shipped {ckpt} -> {args.dest}")


if __name__ == "__main__":
    main()
