"""Summary statistics of a path set: knots per path, arc lengths, largest knot gaps (pure numpy)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from pathrl.paths.spline import dedupe_knots, knot_arc_lengths

__all__ = ["dataset_stats", "path_lengths_and_gaps"]


def path_lengths_and_gaps(knots_list: Iterable[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per path: number of knots, arc length, largest arc length between consecutive knots."""
    counts, lengths, gaps = [], [], []
    for k in knots_list:
        k = dedupe_knots(k)
        s, length = knot_arc_lengths(k)
        s[-1] = length
        counts.append(k.shape[0])
        lengths.append(length)
        gaps.append(float(np.max(np.diff(s))))
    return np.asarray(counts), np.asarray(lengths), np.asarray(gaps)


def dataset_stats(knots_list: Sequence[np.ndarray]) -> dict[str, Any]:
    """count, knots min/mean/max, length (rad) min/mean/max, largest knot gap (rad, arc length)."""
    if not len(knots_list):
        return {"count": 0}
    counts, lengths, gaps = path_lengths_and_gaps(knots_list)
    return {
        "count": len(counts),
        "knots": {"min": int(counts.min()), "mean": float(counts.mean()), "max": int(counts.max())},
        "length": {"min": float(lengths.min()), "mean": float(lengths.mean()), "max": float(lengths.max())},
        "max_knot_gap": float(gaps.max()),
    }
