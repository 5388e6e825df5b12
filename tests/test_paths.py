"""Reference paths: splines, arc length, knot strategies, batched lookup, the segment protocol."""

import numpy as np
import pytest
import torch

from pathrl.paths.knots import KnotStrategy
from pathrl.paths.pathset import build_pathset
from pathrl.paths.segments import evaluation_plan, full_segments, sample_segments
from pathrl.paths.spline import (
    PathError,
    curvature_along,
    fit_spline,
    knot_arc_lengths,
    resample_by_curvature,
    resample_by_distance,
)


def wavy(n=60, m=7, seed=0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, n)
    return np.stack([a * np.sin(2 * np.pi * f * t + p) for f, p, a in
                     zip(rng.uniform(0.5, 2, m), rng.uniform(0, 6, m), rng.uniform(0.5, 1.5, m), strict=True)], 1)


def test_straight_line_length_and_knots():
    knots = np.array([[0.0, 0.0], [0.3, 0.4], [0.6, 0.8], [1.5, 2.0]])  # collinear, total length 2.5
    s, length = knot_arc_lengths(knots)
    assert length == pytest.approx(2.5, abs=1e-9)
    np.testing.assert_allclose(s, [0, 0.5, 1.0, 2.5], atol=1e-6)


def test_circle_arc_length_and_curvature():
    th = np.linspace(0, np.pi, 200)
    knots = np.stack([np.cos(th), np.sin(th)], 1)  # half unit circle: length pi, curvature 1
    _, length = knot_arc_lengths(knots)
    assert length == pytest.approx(np.pi, rel=1e-4)
    s, kappa = curvature_along(knots)
    inner = (s > 0.3) & (s < length - 0.3)
    np.testing.assert_allclose(kappa[inner], 1.0, rtol=0.02)


def test_distance_resampling_gaps():
    knots = wavy()
    new = resample_by_distance(knots, 0.1)
    s, _ = knot_arc_lengths(new)
    gaps = np.diff(s)
    assert np.all(gaps[:-1] == pytest.approx(0.1, abs=2e-3))
    assert gaps[-1] <= 0.1 + 2e-3


def test_curvature_resampling_puts_more_knots_where_curved():
    th = np.linspace(0, np.pi / 2, 50)
    arc = np.stack([1 - np.cos(th), np.sin(th)], 1) * 0.5  # radius 0.5: curvature 2
    line = np.stack([np.linspace(0.5, 0.5, 50), np.linspace(0.5, 5.5, 50)], 1)[1:]  # straight, length 5
    knots = np.concatenate([arc, line])
    new = resample_by_curvature(knots, 0.3)
    s, length = knot_arc_lengths(new)
    arc_len = np.pi / 4
    assert np.sum(s < arc_len) > np.sum(s > arc_len + 0.5)  # dense on the arc, sparse on the line
    assert s[-1] == pytest.approx(length)


def test_bad_knots_raise():
    with pytest.raises(PathError):
        fit_spline(np.array([[0.0, 1.0], [0.0, 1.0]]))
    with pytest.raises(PathError):
        fit_spline(np.array([[0.0, np.nan], [1.0, 1.0], [2.0, 0.0]]))
    with pytest.raises(ValueError):
        KnotStrategy(strategy="bogus")


def test_pathset_lookup_matches_spline():
    paths = [wavy(seed=0), wavy(n=30, seed=1)]
    ps = build_pathset(paths, ["a", "b"], table_step=0.01)
    for i, k in enumerate(paths):
        spline = fit_spline(k)
        from pathrl.paths.spline import arc_length_table

        u, s = arc_length_table(spline, k)
        q_s = np.linspace(0, s[-1], 37)
        expect = spline(np.interp(q_s, s, u))
        got = ps.position_at(torch.full((37,), i), torch.as_tensor(q_s)).numpy()
        np.testing.assert_allclose(got, expect, atol=5e-5)
        # ends are exact
        np.testing.assert_allclose(got[-1], k[-1], atol=1e-9)
        np.testing.assert_allclose(got[0], k[0], atol=1e-9)


def test_window_repeats_end_knot():
    knots = np.stack([np.arange(6.0), np.zeros(6)], 1)  # knots every 1 rad
    ps = build_pathset([knots], ["line"])
    idx = torch.tensor([0, 0])
    s = torch.tensor([0.5, 3.2], dtype=torch.float64)
    end = torch.tensor([4, 4])
    k, ks = ps.window(idx, s, end, 4)
    np.testing.assert_allclose(ks[0].numpy(), [0, 1, 2, 3], atol=1e-6)
    np.testing.assert_allclose(ks[1].numpy(), [3, 4, 4, 4], atol=1e-6)
    np.testing.assert_allclose(k[1, :, 0].numpy(), [3, 4, 4, 4], atol=1e-6)


def test_segments_protocol():
    ps = build_pathset([wavy(seed=i) for i in range(3)], ["a", "b", "c"])
    gen = torch.Generator().manual_seed(0)
    seg = sample_segments(ps, torch.zeros(2000, dtype=torch.long), gen)
    length = float(ps.length[0])
    frac_start = seg.start_s / length
    assert float(frac_start.min()) >= 0 and float(frac_start.max()) <= 0.8
    assert bool((seg.end_s - seg.start_s >= 0.2 * length - 1e-9).all())
    ks = ps.knot_s[0]
    assert bool(torch.isin(seg.end_s, ks).all())  # ends snapped to knots
    full = full_segments(ps, torch.arange(3))
    assert torch.equal(full.end_knot, ps.num_knots - 1)
    a = evaluation_plan(ps, 10, "paper", seed=3)
    b = evaluation_plan(ps, 10, "paper", seed=3)
    assert torch.equal(a.start_s, b.start_s) and a.path.tolist() == [0, 1, 2, 0, 1, 2, 0, 1, 2, 0]
    with pytest.raises(ValueError):
        evaluation_plan(ps, 10, "bogus")
