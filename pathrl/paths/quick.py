"""One path's knot strategy and table, fast enough for a control loop (the follower's ``replace_path``).

The same algorithm as :mod:`pathrl.paths.spline` + :func:`pathrl.paths.pathset.build_pathset` (natural cubic spline
over the chord-length parameter, arc length of a polyline through ~1 sample per ``ARC_LENGTH_STEP`` rad, knots by
distance or integrated curvature, positions every ``table_step`` rad), computed with less work, none of it changing
the result beyond float rounding:

- the spline is fitted by one LAPACK tridiagonal solve (``dgtsv``, second derivatives, natural ends) and evaluated
  in piecewise-polynomial form (scipy's ``PPoly``, Horner) instead of de Boor's recursion;
- the arc-length polyline is not evaluated joint by joint: between two samples u and u + h of one cubic piece the
  step is ``q(u + h) - q(u) = h (alpha x^2 + beta x + gamma)`` (x = u - the piece's start; alpha, beta, gamma: (M,)
  per piece), so its squared length is a quartic in x whose five coefficients are dot products per piece. The
  ~L / ARC_LENGTH_STEP steps then cost a scalar quartic each, not M cubics; the few steps across a piece boundary
  are evaluated directly;
- each dense evaluation is done once and shared: the curvature strategy's arc-length table of its base spline serves
  both the curvature integral and the knot placement.

Results agree with the dataset pipeline to float rounding (tests/test_follower_endgame.py: knots and tables to
1e-9 rad on the test paths; tests/test_quick_paths.py: the arc-length table against the direct polyline).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import PPoly
from scipy.linalg.lapack import dgtsv

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

__all__ = ["PADDING", "arc_table", "evaluate_sorted", "natural_spline", "quick_knots", "quick_pathset",
           "quick_pathsets"]


def natural_spline(u: np.ndarray, knots: np.ndarray) -> PPoly:
    """Natural cubic spline through `knots` (K, M) at increasing parameters `u` (K,), as scipy's
    ``CubicSpline(u, knots, bc_type="natural")`` (a straight segment for K = 2): coefficients (4, K-1, M)."""
    h = np.diff(u)
    slope = np.diff(knots, axis=0) / h[:, None]  # (K-1, M)
    m = np.zeros_like(knots)  # second derivatives, 0 at both ends
    diag, rhs = 2.0 * (h[:-1] + h[1:]), 6.0 * np.diff(slope, axis=0)  # the K-2 interior equations
    if len(u) == 3:  # one equation (LAPACK's wrapper takes no empty off-diagonals)
        m[1] = rhs[0] / diag[0]
    elif len(u) > 3:
        _, _, _, m[1:-1], info = dgtsv(h[1:-1], diag, h[1:-1], rhs)
        if info != 0:
            raise PathError("the path's spline cannot be fitted (singular system)")
    c = np.empty((4, len(u) - 1, knots.shape[1]))
    c[0] = (m[1:] - m[:-1]) / (6.0 * h[:, None])
    c[1] = 0.5 * m[:-1]
    c[2] = slope - h[:, None] * (2.0 * m[:-1] + m[1:]) / 6.0
    c[3] = knots[:-1]
    return PPoly.construct_fast(c, u)


def _fit(knots: np.ndarray) -> PPoly:
    """Natural cubic spline through deduplicated `knots` (K, M) over the chord-length parameter u in [0, 1]."""
    return natural_spline(chord_params(knots), knots)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (P, M) arrays. -> (P,)"""
    return np.einsum("ij,ij->i", a, b)


#: Largest padding (slots per sample) of the per-piece layout of :func:`evaluate_sorted` before it hands over to scipy.
PADDING = 2.0


def _piece_slots(x: np.ndarray, breaks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the first sample (n,) sorted `x` in each piece of `breaks` (K,) (x in [breaks[j], breaks[j + 1]), the
    last piece closed) and how many samples each holds. -> ((K-1,), (K-1,))"""
    first = np.empty(len(breaks) - 1, dtype=np.int64)
    first[0] = 0
    first[1:] = np.searchsorted(x, breaks[1:-1], side="left")
    count = np.empty_like(first)
    count[:-1] = first[1:] - first[:-1]
    count[-1] = len(x) - first[-1]
    return first, count


def evaluate_sorted(spline: PPoly, x: np.ndarray) -> np.ndarray:
    """``spline(x)`` (n, M) of a cubic piecewise polynomial at sorted parameters `x` (n,) inside its breaks.

    Where the samples spread evenly enough over the pieces (at most PADDING slots per sample), the pieces are laid
    out as rows of a (pieces, most samples per piece) table and each row is one small matrix product of the powers of
    its local parameter (P, 4) with its coefficients (4, M): a third faster than scipy's point-by-point Horner, equal
    to float rounding. Otherwise scipy evaluates."""
    breaks = spline.x
    first, count = _piece_slots(x, breaks)
    width = int(count.max())
    if width * len(count) > PADDING * len(x) + 64:
        return spline(x)
    slot = np.minimum(first[:, None] + np.arange(width), len(x) - 1)  # (K-1, P); padding repeats the last sample
    dx = x[slot] - breaks[:-1, None]
    powers = np.empty(dx.shape + (4,))
    powers[..., 3] = 1.0
    powers[..., 2] = dx
    np.multiply(dx, dx, out=powers[..., 1])
    np.multiply(powers[..., 1], dx, out=powers[..., 0])
    values = np.matmul(powers, np.ascontiguousarray(spline.c.transpose(1, 0, 2)))  # (K-1, P, M)
    return values[np.arange(width) < count[:, None]]


def arc_table(spline: PPoly, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, s): parameters ``linspace(0, 1, n)`` (n >= 2) of the cubic piecewise polynomial `spline` over [0, 1] and
    the arc length (same units as the spline's values) of the polyline through its values there, both (n,).

    Equal to ``cumsum(|diff(spline(u))|)`` up to float rounding: steps inside one piece come from the quartic of the
    module docstring, steps across a piece boundary from the spline's values."""
    c, breaks = spline.c, spline.x
    u = np.linspace(0.0, 1.0, n)
    h = 1.0 / (n - 1)
    first, count = _piece_slots(u[:-1], breaks)  # the steps starting in each piece
    alpha = 3.0 * c[0]
    beta = 3.0 * h * c[0] + 2.0 * c[1]
    gamma = (h * c[0] + c[1]) * h + c[2]
    quartic = np.stack([_dot(alpha, alpha), 2.0 * _dot(alpha, beta), _dot(beta, beta) + 2.0 * _dot(alpha, gamma),
                        2.0 * _dot(beta, gamma), _dot(gamma, gamma)]) * (h * h)  # (5, K-1): x^4 ... x^0
    width = int(count.max())
    if width * len(count) <= PADDING * (n - 1) + 64:  # one row per piece: no per-step copies of its coefficients
        keep = np.arange(width) < count[:, None]
        x = u[np.minimum(first[:, None] + np.arange(width), n - 2)] - breaks[:-1, None]  # (K-1, P)
        quartic = quartic[..., None]
    else:
        keep = None
        x = u[:-1] - np.repeat(breaks[:-1], count)
        quartic = np.repeat(quartic, count, axis=1)  # (5, n-1)
    sq = quartic[0] * x
    for i in range(1, 5):
        sq += quartic[i]
        if i < 4:
            sq *= x
    np.maximum(sq, 0.0, out=sq)
    step = np.sqrt(sq if keep is None else sq[keep])  # (n-1,)
    across = first[1:][first[1:] > 0] - 1  # steps from one piece into a later one
    if len(across):
        d = spline(u[across + 1]) - spline(u[across])
        step[across] = np.sqrt(_dot(d, d))
    s = np.empty(n)
    s[0] = 0.0
    np.cumsum(step, out=s[1:])
    return u, s


def _arc(spline: PPoly, knots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u, s): arc length s at parameters u of the polyline through ~1 sample per ARC_LENGTH_STEP rad."""
    d = np.diff(knots, axis=0)
    chord = float(np.sqrt(_dot(d, d)).sum())
    n = max(int(np.ceil(chord / ARC_LENGTH_STEP)) + 1, 2)
    if len(knots) == 2:  # a straight segment: its values directly (exactly the pipeline's table for a line)
        u = np.linspace(0.0, 1.0, n)
        dq = np.diff(spline(u), axis=0)
        return u, np.r_[0.0, np.cumsum(np.sqrt(_dot(dq, dq)))]
    return arc_table(spline, n)


def _by_distance(knots: np.ndarray, spacing: float) -> np.ndarray:
    """Knots every `spacing` rad of arc length along the spline through `knots` (K, M). -> (K', M)"""
    knots = dedupe_knots(knots)
    spline = _fit(knots)
    u, s = _arc(spline, knots)
    return dedupe_knots(place_knots(spline, u, s, spacing))


def _by_curvature(knots: np.ndarray, spacing: float, base_spacing: float, step: float = 2e-3) -> np.ndarray:
    """Knots at equal integrated curvature `spacing` after a distance resampling at `base_spacing`."""
    base = _by_distance(knots, base_spacing)  # deduplicated
    spline = _fit(base)
    u, s = _arc(spline, base)
    grid = np.r_[np.arange(0.0, s[-1], step), s[-1]]
    ug = np.interp(grid, s, u)
    return dedupe_knots(place_knots(spline, ug, curvature_integral(grid, evaluate_sorted(spline, ug)), spacing))


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
    t = evaluate_sorted(spline, np.interp(grid, s, u))
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
