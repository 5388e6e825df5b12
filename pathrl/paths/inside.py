"""Keep a reference path inside a joint position range: what the env follows is the tabulated spline, not the knots.

A cubic spline through knots that lie inside a box can still leave it between them (overshoot near a knot at the
limit), and clipping the knots alone does not stop it. The env reads the path from its table (positions every
``step`` rad of arc length, linearly interpolated in between), so the table's samples are the reference the robot
starts from and follows: if every sample lies inside the range, so does every interpolated point.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from pathrl.paths.pathset import PathSet, build_pathset
from pathrl.paths.spline import dedupe_knots, tabulate

__all__ = ["INSIDE_TOL", "PathOutsideError", "clip_spline_into", "keep_inside", "spline_excess", "table_excess"]

#: How far (rad) a path may leave a position range and still count as inside (float rounding of data at a limit).
INSIDE_TOL = 1e-6


class PathOutsideError(ValueError):
    """A path that leaves a position range, or cannot be brought inside it (one line); `excess` (rad): how far the
    worst path leaves it, where that was measured."""

    def __init__(self, message: str, excess: float | None = None):
        super().__init__(message)
        self.excess = excess


def spline_excess(knots: np.ndarray, lo: np.ndarray, hi: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """How far the tabulated spline through `knots` (K, M) leaves [lo, hi] (M,) below and above (rad, >= 0 each).

    The samples are those of :func:`pathrl.paths.spline.tabulate` at `step` rad, the knots included. -> ((M,), (M,))
    """
    table, _, _ = tabulate(knots, step)
    samples = np.vstack([table, dedupe_knots(knots)])
    below = np.maximum(lo - samples.min(axis=0), 0.0)
    above = np.maximum(samples.max(axis=0) - hi, 0.0)
    return below, above


def clip_spline_into(knots: np.ndarray, lo: np.ndarray, hi: np.ndarray, step: float, max_iter: int = 50) -> np.ndarray:
    """Knots (K', M) clipped into [lo, hi] (M,) so that the tabulated spline through them stays inside too.

    The knots are clipped; then, while a sample of the spline is outside, the two knots around it are moved
    inward by 1.5 times its excess, joint by joint (knots far from an overshoot stay where they are). Raises
    :class:`PathOutsideError` if the spline is not inside after `max_iter` moves.
    """
    k = np.clip(dedupe_knots(np.asarray(knots, dtype=np.float64)), lo, hi)
    for _ in range(max_iter):
        table, knot_s, length = tabulate(k, step)
        below, above = np.maximum(lo - table, 0.0), np.maximum(table - hi, 0.0)  # (S, M)
        if not (below.any() or above.any()):
            return k
        s = np.r_[np.arange(0.0, length, step), length][: len(table)]
        seg = np.clip(np.searchsorted(knot_s, s, side="right") - 1, 0, len(k) - 2)  # (S,) segment of each sample
        push = np.zeros_like(k)
        for side, sign in ((below, 1.0), (above, -1.0)):
            worst = np.zeros_like(k)
            np.maximum.at(worst, seg, side)
            np.maximum.at(worst, seg + 1, side)
            push += sign * worst
        k = dedupe_knots(np.clip(k + 1.5 * push, lo, hi))
    raise PathOutsideError(f"the path's spline cannot be clipped into the position range within {max_iter} moves")


def table_excess(paths: PathSet, lo: Tensor, hi: Tensor, chunk: int = 256) -> Tensor:
    """How far each path of `paths` leaves [lo, hi] (M,) (rad, >= 0): over its tabulated samples (the padding
    past the end excluded) and its knots, `chunk` paths at a time. -> (P,)"""
    lo, hi = lo.to(paths.table), hi.to(paths.table)
    rows = torch.arange(paths.table.shape[1], device=paths.device, dtype=paths.table.dtype) * paths.table_step
    out = []
    for i in range(0, paths.num_paths, chunk):
        table, knots = paths.table[i : i + chunk], paths.knots[i : i + chunk]
        real = (rows[None] < paths.length[i : i + chunk, None])[..., None]  # (p, S, 1): samples at s < L
        out_t = torch.maximum(lo - table, table - hi).clamp(min=0.0).where(real, 0.0).amax(dim=(1, 2))
        out_k = torch.maximum(lo - knots, knots - hi).clamp(min=0.0).amax(dim=(1, 2))
        out.append(torch.maximum(out_t, out_k))
    return torch.cat(out)


def keep_inside(paths: PathSet, knots_list: list[np.ndarray], lo: np.ndarray, hi: np.ndarray, clip: bool,
                tol: float = INSIDE_TOL) -> PathSet:
    """`paths` (tabulated from `knots_list`, each (K, M)) if every one stays inside [lo, hi] (M,) within `tol`
    (rad); otherwise, with `clip`, the path set with the offending paths' knots moved by :func:`clip_spline_into`,
    and without it a :class:`PathOutsideError` that says how many paths leave the range and by how much."""
    excess = table_excess(paths, torch.as_tensor(lo), torch.as_tensor(hi))
    bad = torch.nonzero(excess > tol).flatten().tolist()
    if not bad:
        return paths
    if not clip:
        raise PathOutsideError(f"{len(bad)} of {paths.num_paths} paths leave the position range (by up to "
                               f"{1e3 * float(excess.max()):.3g} mrad, at or between their knots)", float(excess.max()))
    knots_list = list(knots_list)
    for i in bad:
        knots_list[i] = clip_spline_into(knots_list[i], lo, hi, paths.table_step)
    return build_pathset(knots_list, paths.names, table_step=paths.table_step, dtype=paths.table.dtype)
