"""Figures of `make reproduce-tables`: the Table II Pareto plot, reference-vs-executed TCP paths and learning curves."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pathrl.repro.tables import ROWS, TABLE_II
from pathrl.storage import atomic_write

__all__ = ["CURVES", "learning_curves", "load_episode", "pareto_table_ii", "path_overlay"]


def _save(fig, path: Path) -> None:
    """Write a figure atomically (temp file + rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=130, bbox_inches="tight"))


def pareto_table_ii(results: dict[str, Any], paper: dict[str, Any], path: Path) -> bool:
    """Duration vs mean Cartesian deviation of the Table II policies (ours and the paper's) and TOPP-RA.

    Returns False (and writes nothing) if no Table II policy has been evaluated.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in ROWS if r.table == TABLE_II]
    cols = paper[TABLE_II]["columns"]
    ours = [(r.key, results["evaluations"].get(r.evaluation.id)) for r in rows]
    if not any(m for _, m in ours):
        return False
    fig, ax = plt.subplots(figsize=(5.5, 4.0))
    pts = [(m["cart_pos_dev_mean_cm"], m["duration_s"], k) for k, m in ours if m]
    ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", color="C0", label="pathrl (ours)")
    for x, y, k in pts:
        ax.annotate(k.replace("_deviation", "").replace("length_", "R_l "), (x, y), textcoords="offset points",
                    xytext=(5, 4), fontsize=8, color="C0")
    pp = [(dict(zip(cols, paper[TABLE_II]["rows"][r.key], strict=True)), r.key) for r in rows]
    ax.plot([p["cart_pos_dev_mean_cm"] for p, _ in pp], [p["duration_s"] for p, _ in pp], "s--", color="C1",
            label="paper")
    tp = results["baselines"].get(rows[0].evaluation.baseline.id)
    if tp and tp.get("toppra_duration_s"):
        ax.plot([0.0], [tp["toppra_duration_s"]], "*", ms=12, color="C2", label="TOPP-RA (exact path)")
    ax.set_xlabel("mean Cartesian deviation (cm)")
    ax.set_ylabel("duration (s)")
    ax.set_title("Table II: path length vs deviation reward (iiwa7, random)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    _save(fig, path)
    plt.close(fig)
    return True


def load_episode(mcap_path: Path, episode: int) -> dict[str, np.ndarray]:
    """Reference and executed TCP positions of one evaluation episode.

    Returns {"reference": (S, T, 3), "executed": (K, T, 3)} for T TCPs (m).
    """
    from pathrl.logging.mcap_io import iter_messages
    from pathrl.logging.schema import EVAL_REFERENCE, EVAL_TCP

    ref, exe = None, []
    for topic, _, m in iter_messages(mcap_path, [EVAL_REFERENCE, EVAL_TCP]):
        if m["episode"] != episode:
            continue
        if topic == EVAL_REFERENCE:
            ref = np.asarray(m["tcp_position"], dtype=float)
        else:
            exe.append(np.asarray(m["position"], dtype=float))
    if ref is None or not exe:
        raise ValueError(f"{mcap_path}: episode {episode} not found")
    return {"reference": ref, "executed": np.stack(exe)}


def path_overlay(mcap_path: Path, metrics: dict[str, Any], title: str, path: Path) -> int:
    """Top and side view of the reference and executed TCP path(s) of the median-deviation episode.

    Returns the episode shown.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    per = metrics["per_episode"]
    order = np.argsort([p["cart_pos_dev_mean_cm"] for p in per])
    pick = per[int(order[len(order) // 2])]
    ep = load_episode(mcap_path, int(pick["episode"]))
    fig, axes = plt.subplots(1, 2, figsize=(9, 4))
    for ax, (i, j, name) in zip(axes, ((0, 1, "top view (x-y)"), (0, 2, "side view (x-z)")), strict=True):
        for t in range(ep["reference"].shape[1]):
            lbl = t == 0
            ax.plot(ep["reference"][:, t, i], ep["reference"][:, t, j], "--", color="k", lw=1.2,
                    label="reference" if lbl else None)
            ax.plot(ep["executed"][:, t, i], ep["executed"][:, t, j], ".-", color="C0", ms=3, lw=1,
                    label="executed (every 0.1 s)" if lbl else None)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("xyz"[i] + " (m)")
        ax.set_ylabel("xyz"[j] + " (m)")
        ax.set_title(name, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{title}: episode {pick['episode']} (median deviation {pick['cart_pos_dev_mean_cm']:.1f} cm, "
                 f"{pick['duration_s']:.2f} s)", fontsize=10)
    _save(fig, path)
    plt.close(fig)
    return int(pick["episode"])


#: Learning-curve figures: name -> (title, the shipped models of one training chain in order, each warm-started
#: from the one before).
CURVES = {"ball": ("iiwa7 ball on a plate: controller distilled (DAgger), then PPO",
                   ("iiwa7_ball_balancing_distill", "iiwa7_ball_balancing_finetune")),
          "ball_path_law": ("iiwa7 ball on a plate: path-law controller distilled (DAgger), then PPO",
                            ("iiwa7_ball_balancing_distill_law", "iiwa7_ball_balancing_finetune_law")),
          "ball_residual": ("iiwa7 ball on a plate: PPO on a residual over the path-law controller",
                            ("iiwa7_ball_balancing_residual",))}


def learning_curves(curves: dict[str, dict[str, np.ndarray]], title: str, path: Path,
                    fall_key: str = "Episode_Termination/task_failed") -> bool:
    """Training falls, end-of-path duration and action noise against env steps of one training chain.

    `curves`: model -> columns of its ``curve.csv`` (:func:`pathrl.train.ship.read_curve`), in training order;
    each model's steps continue the one before. Duration is left out where no training episode reached the end.
    Returns False (and writes nothing) if `curves` is empty.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not curves:
        return False
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    offset = 0.0
    for i, (model, c) in enumerate(curves.items()):
        steps = (c["env_steps"] + offset) / 1e6
        stopped = c.get("Episode_Termination/robot_stopped", np.ones_like(steps))
        duration = np.where(stopped > 0, c.get("Metrics/duration_s", np.full_like(steps, np.nan)), np.nan)
        for ax, y in zip(axes, (100.0 * c.get(fall_key, np.full_like(steps, np.nan)), duration,
                                c.get("Policy/mean_std", np.full_like(steps, np.nan))), strict=True):
            ax.plot(steps, y, color=f"C{i}", lw=1, label=model)
        if i:
            for ax in axes:
                ax.axvline(offset / 1e6, color="0.5", ls=":", lw=1)
        offset += float(c["env_steps"][-1])
    axes[0].set_ylabel("training episodes\nfailed (%)")
    axes[0].set_yscale("symlog", linthresh=1.0)
    axes[0].set_ylim(0.0, 100.0)
    axes[1].set_ylabel("end of path (s)")
    axes[2].set_ylabel("action noise (std)")
    axes[2].set_xlabel("env steps (millions)")
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    _save(fig, path)
    plt.close(fig)
    return True
