"""Joint-space reference paths: natural cubic splines through knots, arc length, knot resampling.

A path is stored as its knots ``(K, M)`` (M = path joints). Its geometry is the natural cubic
spline through the knots over the chord-length parameter u in [0, 1] (as the paper's authors built
theirs). All lengths are Euclidean arc lengths in joint space (rad; a prismatic joint contributes m).
These functions work on one path with numpy/scipy; :mod:`pathrl.paths.pathset` batches many paths.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.interpolate import BSpline, make_interp_spline

__all__ = [
    "ARC_LENGTH_STEP", "PathError", "arc_length_table", "chord_params", "curvature_along", "curvature_integral",
    "dedupe_knots", "fit_spline", "integrated_curvature", "knot_arc_lengths", "place_knots", "resample_by_curvature",
    "resample_by_distance", "sample_uniform", "tabulate",
]

#: Parameter step of the dense polyline used to measure arc length, per rad of chord length.
ARC_LENGTH_STEP = 1e-3


class PathError(ValueError):
    """A path's knots are unusable (NaN, fewer than two distinct knots, wrong shape)."""


def dedupe_knots(knots: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Drop knots that repeat their predecessor (zero chord length). (K, M) -> (K', M)."""
    knots = np.asarray(knots, dtype=np.float64)
    if knots.ndim != 2 or knots.shape[0] < 2:
        raise PathError(f"knots must have shape (K>=2, M), got {knots.shape}")
    if not np.all(np.isfinite(knots)):
        raise PathError("knots contain NaN or inf")
    keep = np.r_[True, np.linalg.norm(np.diff(knots, axis=0), axis=1) > tol]
    out = knots[keep]
    if out.shape[0] < 2:
        raise PathError("path has fewer than two distinct knots")
    return out


def chord_params(knots: np.ndarray) -> np.ndarray:
    """Chord-length parameter of each knot: cumulative knot-to-knot distance / total. (K, M) -> (K,)."""
    d = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(knots, axis=0), axis=1))]
    return d / d[-1]


def fit_spline(knots: np.ndarray) -> BSpline:
    """Natural cubic spline through the knots, parameterized by chord length u in [0, 1]."""
    knots = dedupe_knots(knots)
    u = chord_params(knots)
    if knots.shape[0] == 2:  # a straight segment: the natural cubic is linear
        return make_interp_spline(u, knots, k=1)
    return make_interp_spline(u, knots, k=3, bc_type="natural")


def arc_length_table(
    spline: BSpline, knots: np.ndarray, step: float = ARC_LENGTH_STEP
) -> tuple[np.ndarray, np.ndarray]:
    """Dense table (u, s) with s the arc length at parameter u. Polyline through ~1 sample per `step` rad."""
    chord = float(np.sum(np.linalg.norm(np.diff(knots, axis=0), axis=1)))
    n = max(int(np.ceil(chord / step)) + 1, 2)
    u = np.linspace(0.0, 1.0, n)
    q = spline(u)
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))]
    return u, s


def tabulate(knots: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray, float]:
    """One spline fit, three views: positions at arc lengths 0, step, 2 step, ... and at L ((S, M)),
    the arc length of every knot ((K,), last = L) and the length L."""
    knots = dedupe_knots(knots)
    spline = fit_spline(knots)
    u, s = arc_length_table(spline, knots)
    length = float(s[-1])
    grid = np.r_[np.arange(0.0, length, step), length]
    knot_s = np.interp(chord_params(knots), u, s)
    knot_s[-1] = length
    return spline(np.interp(grid, s, u)), knot_s, length


def knot_arc_lengths(knots: np.ndarray) -> tuple[np.ndarray, float]:
    """Arc length of every knot along the path and the total length. (K, M) -> ((K,), L)."""
    knots = dedupe_knots(knots)
    spline = fit_spline(knots)
    u, s = arc_length_table(spline, knots)
    return np.interp(chord_params(knots), u, s), float(s[-1])


def sample_uniform(knots: np.ndarray, step: float) -> tuple[np.ndarray, float]:
    """Path positions at arc lengths 0, step, 2 step, ... and at L. Returns ((S, M), L)."""
    table, _, length = tabulate(knots, step)
    return table, length


def place_knots(spline: Callable[[np.ndarray], np.ndarray], u: np.ndarray, measure: np.ndarray,
                spacing: float) -> np.ndarray:
    """Knots (K', M) where the cumulative `measure` (at parameters `u`) crosses 0, spacing, 2 spacing, ..., plus the
    path's end; `spline` maps parameters to positions."""
    total = measure[-1]
    targets = np.arange(0.0, total, spacing)
    if len(targets) > 1 and total - targets[-1] < 1e-9:
        targets = targets[:-1]
    targets = np.r_[0.0, targets[1:], total]
    # measure is non-decreasing; a negligible ramp makes it strictly increasing for np.interp.
    ramp = np.linspace(0.0, 1e-12 * max(total, 1.0), len(measure))
    at = np.interp(targets, measure + ramp, u)
    at[0], at[-1] = u[0], u[-1]  # the path's ends, also where the measure is flat (a straight path: no curvature)
    return spline(at)


def resample_by_distance(knots: np.ndarray, spacing: float) -> np.ndarray:
    """New knots at equal arc length `spacing` (rad) along the path (last gap may be shorter)."""
    if spacing <= 0:
        raise PathError(f"knot spacing must be > 0, got {spacing}")
    knots = dedupe_knots(knots)
    spline = fit_spline(knots)
    u, s = arc_length_table(spline, knots)
    return dedupe_knots(place_knots(spline, u, s, spacing))


def integrated_curvature(knots: np.ndarray, step: float = 2e-3) -> tuple[np.ndarray, np.ndarray, BSpline]:
    """Cumulative integral of |d^2 q / ds^2| over arc length s on a uniform s grid.

    Returns (u at the grid points, cumulative curvature (same length), the spline).
    """
    knots = dedupe_knots(knots)
    spline = fit_spline(knots)
    u, s = arc_length_table(spline, knots)
    grid = np.r_[np.arange(0.0, s[-1], step), s[-1]]
    ug = np.interp(grid, s, u)
    return ug, curvature_integral(grid, spline(ug)), spline


def curvature_integral(grid: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Cumulative integral of |d^2 q / ds^2| (S,) of positions `q` (S, M) at arc lengths `grid` (S,) (finite
    differences, trapezoids; zeros for fewer than three samples)."""
    ds = np.diff(grid)
    mid = 0.5 * (grid[1:] + grid[:-1])
    if len(mid) < 2:
        return np.zeros_like(grid)
    # in place, with the arithmetic of norm(diff(diff(q) / ds), axis=1): the same values, a fraction of the time
    tangent = np.subtract(q[1:], q[:-1])
    tangent /= ds[:, None]
    bend = np.subtract(tangent[1:], tangent[:-1], out=tangent[:-1])
    bend *= bend
    kappa = np.sqrt(np.add.reduce(bend, axis=1))
    kappa /= np.diff(mid)  # at interior grid points
    kappa = np.r_[kappa[0], kappa, kappa[-1]]
    return np.r_[0.0, np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * ds)]


def curvature_along(knots: np.ndarray, step: float = 2e-3) -> tuple[np.ndarray, np.ndarray]:
    """Curvature |d^2 q / ds^2| (1/rad) along the path at arc lengths s. Returns (s, kappa)."""
    ug, cum, spline = integrated_curvature(knots, step)
    u, s = arc_length_table(spline, dedupe_knots(knots))
    grid = np.interp(ug, u, s)
    kappa = np.gradient(cum, grid)
    return grid, kappa


def resample_by_curvature(knots: np.ndarray, spacing: float, base_spacing: float = 0.1) -> np.ndarray:
    """Knots at equal integrated curvature `spacing` after a distance resampling at `base_spacing`.

    As in the paper: dense, curved stretches get many knots, straight stretches few.
    """
    if spacing <= 0:
        raise PathError(f"curvature spacing must be > 0, got {spacing}")
    base = resample_by_distance(knots, base_spacing)
    ug, cum, spline = integrated_curvature(base)
    return dedupe_knots(place_knots(spline, ug, cum, spacing))
