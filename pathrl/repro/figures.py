"""Figures of `make reproduce-tables`: the Table II Pareto plot and reference-vs-executed TCP paths."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from pathrl.repro.tables import ROWS, TABLE_II


def _save(fig, path: Path) -> None:
    """Write a figure atomically (temp file + rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    fig.savefig(tmp, dpi=130, bbox_inches="tight")
    os.replace(tmp, path)


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

    ref, exe = None, []
    for topic, _, m in iter_messages(mcap_path, ["/eval/reference", "/eval/tcp"]):
        if m["episode"] != episode:
            continue
        if topic == "/eval/reference":
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
