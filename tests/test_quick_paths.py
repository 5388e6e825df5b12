"""The follower's fast path tables (pathrl.paths.quick) are the dataset pipeline's, computed with less work: the
natural spline by one tridiagonal solve equals scipy's CubicSpline, the arc-length table by per-piece quartics equals
the polyline through the spline's values, the in-place curvature integral equals its plain formula bit for bit, and
the knots and tables of 17-joint ARMAR-6 test paths equal the pipeline's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from pathrl.dataset.io import load_dataset
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.pathset import build_pathset
from pathrl.paths.quick import (
    PADDING,
    _piece_slots,
    arc_table,
    evaluate_sorted,
    natural_spline,
    quick_knots,
    quick_pathset,
)
from pathrl.paths.spline import chord_params, curvature_integral
from pathrl.robot.external import load_robot_by_name

ROOT = Path(__file__).resolve().parents[1]


def _walk(k: int, m: int, seed: int) -> np.ndarray:
    """A random walk of `k` knots in `m` joints (rad), steps of ~0.3 rad."""
    return np.cumsum(np.random.default_rng(seed).normal(0.0, 0.3, (k, m)), axis=0)


@pytest.mark.parametrize(("k", "m"), [(3, 2), (4, 7), (40, 7), (300, 17)])
def test_natural_spline_is_scipys_and_its_arc_table_the_polyline(k, m):
    knots = _walk(k, m, k)
    u = chord_params(knots)
    mine, ref = natural_spline(u, knots), CubicSpline(u, knots, bc_type="natural")
    x = np.linspace(0.0, 1.0, 5001)
    assert np.abs(mine(x) - ref(x)).max() < 1e-12 * max(1.0, np.abs(knots).max())
    n = 20_000 + k  # pieces get a few samples each, and steps across every piece boundary
    u_grid, s = arc_table(mine, n)
    dq = np.diff(ref(u_grid), axis=0)
    direct = np.r_[0.0, np.cumsum(np.linalg.norm(dq, axis=1))]
    assert np.array_equal(u_grid, np.linspace(0.0, 1.0, n))
    assert np.abs(s - direct).max() < 1e-11 * direct[-1]


def test_arc_table_with_pieces_shorter_than_a_sample_step():
    knots = np.array([[0.0, 0.0], [1e-7, 0.0], [1.0, 1.0], [1.0 + 1e-7, 1.0], [2.0, 0.0]])
    spline = natural_spline(chord_params(knots), knots)
    u, s = arc_table(spline, 11)
    direct = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(spline(u), axis=0), axis=1))]
    assert np.abs(s - direct).max() < 1e-12


@pytest.mark.parametrize("even", [True, False])
def test_evaluate_sorted_is_scipys(even):
    """Samples spread evenly over the pieces take the per-piece matrix products, uneven ones scipy's evaluation."""
    knots = _walk(60, 17, 3) if even else np.r_[_walk(59, 17, 3), [[40.0] * 17]]  # one piece far longer
    spline = natural_spline(chord_params(knots), knots)
    x = np.linspace(0.0, 1.0, 7001)
    _, count = _piece_slots(x, spline.x)
    assert (count.max() * len(count) <= PADDING * len(x)) == even
    assert np.abs(evaluate_sorted(spline, x) - spline(x)).max() < 1e-13 * np.abs(knots).max()


def test_curvature_integral_is_its_plain_formula_bit_for_bit():
    grid = np.r_[np.arange(0.0, 3.9995, 2e-3), 3.9995]  # the last step shorter
    q = _walk(len(grid), 17, 1) * 1e-2
    ds = np.diff(grid)
    tangent = np.diff(q, axis=0) / ds[:, None]
    mid = 0.5 * (grid[1:] + grid[:-1])
    kappa = np.linalg.norm(np.diff(tangent, axis=0), axis=1) / np.diff(mid)
    kappa = np.r_[kappa[0], kappa, kappa[-1]]
    plain = np.r_[0.0, np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * ds)]
    assert np.array_equal(curvature_integral(grid, q), plain)


def test_armar6_knots_and_tables_are_the_pipelines():
    robot = load_robot_by_name("armar6")
    strategy = KnotStrategy("curvature", 0.3, 0.1, 9)
    for k in load_dataset(ROOT / "datasets" / "armar6" / "random", robot).splits["test"].knots[:3]:
        ref = build_pathset([strategy.apply(k)], ["p"])
        new = quick_pathset(quick_knots(strategy, k))
        for x, y in ((ref.knots, new.knots), (ref.knot_s, new.knot_s), (ref.table, new.table),
                     (ref.length, new.length)):
            assert x.shape == y.shape and float((x - y).abs().max()) < 1e-9
