"""Turn a training run into a shipped model directory (config, slim weights, training summary, learning curve)."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pathrl.storage import atomic_write, latest_valid_checkpoint, load_checkpoint, save_checkpoint, write_json_atomic

__all__ = ["CURVE_PREFIXES", "curve_csv", "read_curve", "read_training_log", "ship", "training_curve", "training_stats"]


def read_training_log(run_dir: Path, last_iter: int) -> tuple[int, list[dict[str, Any]]]:
    """Env steps per iteration (from the config) and the ``/train/scalars`` messages of run.mcap up to checkpoint
    `last_iter`."""
    from pathrl.logging.mcap_io import read_messages
    from pathrl.logging.schema import TRAIN_SCALARS

    cfg = yaml.safe_load((run_dir / "config.yaml").read_text())
    per_iter = int(cfg["agent"]["num_steps_per_env"]) * int(cfg["env"]["num_envs"])
    msgs = [m for t, _, m in read_messages(run_dir / "run.mcap") if t == TRAIN_SCALARS]
    return per_iter, [m for m in msgs if m["iteration"] <= last_iter]


def training_stats(per_iter: int, msgs: list[dict[str, Any]], last_iter: int) -> dict[str, Any]:
    """Iterations, env steps and wall time up to checkpoint `last_iter` (`read_training_log`'s output)."""
    wall = sum(m["values"].get("Perf/collection_time", 0.0) + m["values"].get("Perf/learning_time", 0.0) for m in msgs)
    last = msgs[-1]["values"] if msgs else {}
    return {"checkpoint_iteration": last_iter, "iterations": last_iter + 1, "env_steps": (last_iter + 1) * per_iter,
            "steps_per_iteration": per_iter, "wall_time_s": round(wall, 1),
            "final_train_metrics": {k: v for k, v in last.items()
                                    if k.startswith(("Metrics/", "Episode_Termination/"))}}


#: Per-iteration scalars of run.mcap kept in a shipped model's ``curve.csv`` (prefixes of the rsl-rl log keys).
CURVE_PREFIXES = ("Episode_Reward/", "Episode_Termination/", "Metrics/", "Policy/mean_std", "Train/mean_reward",
                  "Loss/learning_rate", "Loss/behavior")


def training_curve(per_iter: int, msgs: list[dict[str, Any]]) -> list[dict[str, float]]:
    """One row per iteration (`read_training_log`'s output): ``iteration``, ``env_steps`` and ``wall_time_s``
    (cumulative) and the logged scalars named by `CURVE_PREFIXES` (falls, reward terms, duration, noise)."""
    out, wall = [], 0.0
    for m in msgs:
        v = m["values"]
        wall += v.get("Perf/collection_time", 0.0) + v.get("Perf/learning_time", 0.0)
        row = {"iteration": m["iteration"], "env_steps": (m["iteration"] + 1) * per_iter, "wall_time_s": round(wall, 2)}
        row.update({k: v[k] for k in sorted(v) if k.startswith(CURVE_PREFIXES) and not k.endswith("/time")})
        out.append(row)
    return out


def curve_csv(rows: list[dict[str, float]]) -> str:
    """CSV text of `training_curve` rows (columns: the union of their keys; a key an iteration lacks is empty)."""
    cols = list(dict.fromkeys(k for r in rows for k in r))
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{x:.6g}" if isinstance(x, float) else x) for k, x in r.items()})
    return buf.getvalue()


def read_curve(path: Path) -> dict[str, np.ndarray]:
    """A shipped ``curve.csv`` as columns of floats (NaN where empty)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{path}: no rows")
    return {k: np.array([float(r[k]) if r[k] not in ("", None) else np.nan for r in rows]) for k in rows[0]}


def ship(run_dir: Path, dest: Path) -> Path:
    """Copy the run's config and last checkpoint (actor + critic weights, or a distilled student; no optimizer)
    to `dest`, with its training summary and (from run.mcap) its learning curve, ``curve.csv``."""
    run_dir, dest = Path(run_dir), Path(dest)
    ckpt = latest_valid_checkpoint(run_dir)
    if ckpt is None or not (run_dir / "config.yaml").is_file():
        raise FileNotFoundError(f"{run_dir} has no config.yaml or checkpoint")
    state = load_checkpoint(ckpt)
    keys = ("student_state_dict",) if "student_state_dict" in state else ("actor_state_dict", "critic_state_dict")
    slim = {k: state[k] for k in (*keys, "iter")}  # a distillation run ships its student (no teacher: a controller)
    slim["infos"] = {"source_checkpoint": ckpt.name}
    dest.mkdir(parents=True, exist_ok=True)
    save_checkpoint(slim, dest / "model.pt")
    atomic_write(dest / "config.yaml", (run_dir / "config.yaml").read_bytes())
    summary = json.loads((run_dir / "summary.json").read_text()) if (run_dir / "summary.json").is_file() else {}
    per_iter, msgs = read_training_log(run_dir, int(state["iter"]))
    summary.update(training_stats(per_iter, msgs, int(state["iter"])))
    if summary.get("bias_search"):  # the output-bias search before PPO is training too (pathrl.train.bias_search)
        bs = summary["bias_search"]
        summary["env_steps"] += int(bs.get("env_steps", 0))
        summary["wall_time_s"] = round(summary["wall_time_s"] + float(bs.get("wall_time_s", 0.0)), 1)
    summary["shipped_from"] = str(run_dir)
    write_json_atomic(dest / "summary.json", summary)
    if msgs:
        atomic_write(dest / "curve.csv", curve_csv(training_curve(per_iter, msgs)))
    return dest
