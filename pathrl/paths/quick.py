"""One path's knot strategy and table, fast enough for a control loop (the follower's ``replace_path``).

The same algorithm as :mod:`pathrl.paths.spline` + :func:`pathrl.paths.pathset.build_pathset` (natural cubic spline
over the chord-length parameter, arc length of a polyline through ~1 sample per ``ARC_LENGTH_STEP`` rad, knots by
distance or integrated curvature, positions every ``table_step`` rad), with two changes that cost nothing in
accuracy: the spline is evaluated in its piecewise-polynomial form (scipy's ``CubicSpline``, Horner) instead of
de Boor's recursion, and each dense evaluation is done once and shared: the curvature strategy's arc-length table
of its base spline serves both the curvature integral and the knot placement. Results agree with the dataset
pipeline to float rounding (tests/test_follower_endgame.py: knots and tables to 1e-9 rad on the test paths).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline, PPoly

from pathrl.paths.knots import KnotStrategy
from pathrl.paths.pathset import PathSet
from pathrl.paths.spline import (
    ARC_LENGTH_STEP,
    PathError,
    chord_params,
    curvature_integral,
    dedupe_knots,
    place_knots,
)

__all__ = ["quick_knots", "quick_pathset", "quick_pathsets"]


def _fit(knots: np.ndarray) -> PPoly:
    """Natural cubic spline through deduplicated `knots` (K, M) over the chord-length parameter u in [0, 1]."""
    u = chord_params(knots)
    if len(knots) == 2:  # a straight segment
        slope = (knots[1] - knots[0])[None, None]
        return PPoly(np.concatenate([slope, knots[:1][None]], axis=0), u)
    return CubicSpline(u, knots, bc_type="natural")


def _arc(spline: PPoly, knots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u, s): arc length s at parameters u of the polyline through ~1 sample per ARC_LENGTH_STEP rad."""
    d = np.diff(knots, axis=0)
    chord = float(np.sqrt(np.einsum("ij,ij->i", d, d)).sum())
    n = max(int(np.ceil(chord / ARC_LENGTH_STEP)) + 1, 2)
    u = np.linspace(0.0, 1.0, n)
    dq = np.diff(spline(u), axis=0)
    return u, np.r_[0.0, np.cumsum(np.sqrt(np.einsum("ij,ij->i", dq, dq)))]


def _by_distance(knots: np.ndarray, spacing: float) -> np.ndarray:
    """Knots every `spacing` rad of arc length along the spline through `knots` (K, M). -> (K', M)"""
    knots = dedupe_knots(knots)
    spline = _fit(knots)
    u, s = _arc(spline, knots)
    return dedupe_knots(place_knots(spline, u, s, spacing))


def _by_curvature(knots: np.ndarray, spacing: float, base_spacing: float, step: float = 2e-3) -> np.ndarray:
    """Knots at equal integrated curvature `spacing` after a distance resampling at `base_spacing`."""
    base = dedupe_knots(_by_distance(knots, base_spacing))
    spline = _fit(base)
    u, s = _arc(spline, base)
    grid = np.r_[np.arange(0.0, s[-1], step), s[-1]]
    ug = np.interp(grid, s, u)
    return dedupe_knots(place_knots(spline, ug, curvature_integral(grid, spline(ug)), spacing))


def quick_knots(strategy: KnotStrategy, knots: np.ndarray) -> np.ndarray:
    """`strategy` applied to one path's knots (K, M) -> (K', M), as :meth:`KnotStrategy.apply`."""
    if strategy.strategy == "file":
        return dedupe_knots(knots)
    if strategy.strategy == "distance":
        if strategy.spacing <= 0:
            raise PathError(f"knot spacing must be > 0, got {strategy.spacing}")
        return _by_distance(knots, strategy.spacing)
    return _by_curvature(knots, strategy.spacing, strategy.base_spacing)


def _table(knots: np.ndarray, table_step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Deduplicated knots (K, M), their arc lengths (K,), the table (S, M) laid out as build_pathset stores it
    (the last rows make linear interpolation hit the end at s = L), and the length L (rad)."""
    knots = dedupe_knots(knots)
    spline = _fit(knots)
    u, s = _arc(spline, knots)
    length = float(s[-1])
    grid = np.r_[np.arange(0.0, length, table_step), length]
    knot_s = np.interp(chord_params(knots), u, s)
    knot_s[-1] = length
    t = spline(np.interp(grid, s, u))
    j = t.shape[0] - 1
    table = np.empty((j + 2, knots.shape[1]))
    rest = length - (j - 1) * table_step
    table[:j] = t[:-1]
    if rest > 1e-9:
        table[j:] = t[-2] + (t[-1] - t[-2]) * (table_step / rest)
    else:
        table[j - 1 :] = t[-1]
    return knots, knot_s, table, length


def quick_pathset(knots: np.ndarray, table_step: float = 0.01, name: str = "path") -> PathSet:
    """The one-path :class:`PathSet` of `knots` (K, M), as ``build_pathset([knots], [name], table_step)``."""
    return quick_pathsets([knots], [name], table_step)


def quick_pathsets(knots_list: list[np.ndarray], names: list[str], table_step: float = 0.01) -> PathSet:
    """The :class:`PathSet` of several paths (each (K_i, M)), padded as :func:`build_pathset` pads them."""
    import torch

    parts = [_table(k, table_step) for k in knots_list]
    kmax, smax = max(len(p[0]) for p in parts), max(len(p[2]) for p in parts)
    m = parts[0][0].shape[1]
    knots, knot_s = np.empty((len(parts), kmax, m)), np.empty((len(parts), kmax))
    table = np.empty((len(parts), smax, m))
    for i, (k, ks, t, length) in enumerate(parts):
        knots[i, : len(k)], knots[i, len(k) :] = k, k[-1]
        knot_s[i, : len(k)], knot_s[i, len(k) :] = ks, length
        table[i, : len(t)], table[i, len(t) :] = t, t[-1]
    f64 = dict(dtype=torch.float64)
    return PathSet(names=tuple(str(n) for n in names), knots=torch.as_tensor(knots, **f64),
                   knot_s=torch.as_tensor(knot_s, **f64), num_knots=torch.tensor([len(p[0]) for p in parts]),
                   length=torch.tensor([p[3] for p in parts], **f64), table=torch.as_tensor(table, **f64),
                   table_step=float(table_step))
