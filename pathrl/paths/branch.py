"""Branched paths for many envs at once (torch, float64): the knots of :func:`pathrl.eval.path_change.branch` and the
tables of :func:`pathrl.paths.pathset.build_pathset`, batched over B paths without a loop over them.

A batch of paths is padded knots ``(B, K, M)`` with a count ``(B,)`` per path; rows past the count repeat the last
knot (the padding of :class:`~pathrl.paths.pathset.PathSet`). The spline is the natural cubic through the knots over
the chord-length parameter (the interpolant :func:`pathrl.paths.spline.fit_spline` builds with scipy; it is unique,
so both agree to rounding), solved with a batched tridiagonal sweep (a loop over knot rows, not over paths).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from pathrl.paths.spline import ARC_LENGTH_STEP

__all__ = ["BranchShape", "BranchStart", "branch_knots", "dedupe_padded", "spline_eval", "spline_moments",
           "tabulate_batch"]


@dataclass(frozen=True)
class BranchStart:
    """Where a branch starts: the robot at arc length `s` (rad) along its path, at joint positions `q` (rad), moving
    at `v` (rad/s). One path (numpy): a float, (M,), (M,); B paths (torch): (B,), (B, M), (B, M)."""

    s: float | Tensor
    q: np.ndarray | Tensor
    v: np.ndarray | Tensor


@dataclass(frozen=True)
class BranchShape:
    """How a branch leaves its path: the remaining knots shifted by smoothstep((s - s_now) / `ramp`) `offset` (rad;
    `ramp` in rad of arc length) and kept `margin` (rad) inside `pos_limits` (M, 2); a lead knot `lead_s` seconds of
    the robot's motion ahead. One path (numpy): offset (M,), ramp a float; B paths (torch): (B, M), (B,)."""

    offset: np.ndarray | Tensor
    ramp: float | Tensor
    pos_limits: np.ndarray | Tensor
    lead_s: float = 0.1
    margin: float = 0.02


def branch_knots(knots: Tensor, knot_s: Tensor, end_knot: Tensor, start: BranchStart,
                 shape: BranchShape) -> tuple[Tensor, Tensor]:
    """The branch of B paths (:func:`pathrl.eval.path_change.branch` per row): from ``start.q`` (plus a knot at
    q + lead_s v when that is more than 1e-6 rad away) along the path's knots past arc length s + lead_s |v| up to
    `end_knot`, shifted and kept inside the position limits as `shape` says.

    knots (B, K, M), knot_s (B, K) their arc lengths (rad) along the path, end_knot (B,) long; `start` and `shape`
    of B paths (torch). Returns padded knots (B, K + 2, M) and their count (B,) (1 + lead knot + kept knots; may be
    1 when no knot is left).
    """
    s_now, q_now, v_now = start.s, start.q, start.v
    offset, ramp, pos_limits = shape.offset, shape.ramp, shape.pos_limits
    lead_s, margin = shape.lead_s, shape.margin
    b, k, _ = knots.shape
    lead = lead_s * v_now.norm(dim=1)
    has_lead = lead > 1e-6
    first = torch.searchsorted(knot_s.contiguous(), (s_now + lead + 1e-6).unsqueeze(1), right=True).squeeze(1)
    n_start = 1 + has_lead.long()
    kept = (end_knot + 1 - first).clamp(min=0)
    count = n_start + kept
    j = torch.arange(k + 2, device=knots.device).unsqueeze(0)  # output rows
    src = (first.unsqueeze(1) + j - n_start.unsqueeze(1)).clamp(0, k - 1)
    src = torch.minimum(src, end_knot.unsqueeze(1))
    rows = knots.gather(1, src.unsqueeze(2).expand(-1, -1, knots.shape[2]))
    x = ((knot_s.gather(1, src) - s_now.unsqueeze(1)) / ramp.unsqueeze(1)).clamp(0.0, 1.0)
    w = x * x * (3.0 - 2.0 * x)
    moved = torch.clamp(rows + w.unsqueeze(2) * offset.unsqueeze(1), pos_limits[:, 0] + margin,
                        pos_limits[:, 1] - margin)
    out = moved.clone()
    out[:, 0] = q_now
    lead_q = q_now + lead_s * v_now
    out[:, 1] = torch.where(has_lead.unsqueeze(1), lead_q, moved[:, 1])
    last = (count - 1).clamp(min=0)
    pad = j >= count.unsqueeze(1)
    tail = out.gather(1, last.view(b, 1, 1).expand(-1, 1, out.shape[2]))
    return torch.where(pad.unsqueeze(2), tail, out), count


def dedupe_padded(knots: Tensor, count: Tensor, tol: float = 1e-9) -> tuple[Tensor, Tensor]:
    """Drop knots that repeat their predecessor (:func:`pathrl.paths.spline.dedupe_knots` per row): padded
    (B, K, M) and count (B,) -> the same shapes, kept knots first, padding repeating the last kept one."""
    k = knots.shape[1]
    idx = torch.arange(k, device=knots.device).unsqueeze(0)
    step = torch.cat([torch.full_like(knots[:, :1, 0], math.inf), (knots[:, 1:] - knots[:, :-1]).norm(dim=2)], 1)
    keep = (step > tol) & (idx < count.unsqueeze(1))
    new_count = keep.sum(dim=1)
    order = torch.argsort(torch.where(keep, idx, idx + k), dim=1)  # kept rows first, in order
    last = order.gather(1, (new_count - 1).clamp(min=0).unsqueeze(1))
    pos = torch.where(idx < new_count.unsqueeze(1), order, last)
    return knots.gather(1, pos.unsqueeze(2).expand(-1, -1, knots.shape[2])), new_count


def _chord_params(knots: Tensor) -> Tensor:
    """Chord-length parameter (B, K) of padded knots (padding: 1)."""
    d = torch.cat([torch.zeros_like(knots[:, :1, 0]), (knots[:, 1:] - knots[:, :-1]).norm(dim=2).cumsum(dim=1)], 1)
    return d / d[:, -1:]


def spline_moments(u: Tensor, knots: Tensor, count: Tensor) -> Tensor:
    """Second derivatives (B, K, M) at the knots of the natural cubic spline through padded `knots` (B, K, M) at
    parameters `u` (B, K): rows 0 and >= count - 1 are 0 (natural ends, padding)."""
    b, k, m = knots.shape
    h = u[:, 1:] - u[:, :-1]  # (B, K-1); 0 in the padding
    h_safe = torch.where(h > 0, h, torch.ones_like(h))
    slope = (knots[:, 1:] - knots[:, :-1]) / h_safe.unsqueeze(2)
    cp = torch.zeros(b, k, dtype=knots.dtype, device=knots.device)
    rp = torch.zeros(b, k, m, dtype=knots.dtype, device=knots.device)
    top = min(int(count.max()) - 1, k - 1)  # rows from here on are padding
    for i in range(1, top):  # forward sweep; rows outside 1..count-2 are identity rows with right side 0
        real = (i < count - 1).unsqueeze(1)
        a, c = h[:, i - 1], h[:, i]
        denom = 2.0 * (a + c) - a * cp[:, i - 1]
        denom = torch.where(real.squeeze(1), denom, torch.ones_like(denom))
        r = 6.0 * (slope[:, i] - slope[:, i - 1])
        cp[:, i] = torch.where(real.squeeze(1), c / denom, torch.zeros_like(c))
        rp[:, i] = torch.where(real, (r - a.unsqueeze(1) * rp[:, i - 1]) / denom.unsqueeze(1), torch.zeros_like(r))
    mom = torch.zeros_like(knots)
    for i in range(top - 1, 0, -1):  # back substitution
        mom[:, i] = rp[:, i] - cp[:, i].unsqueeze(1) * mom[:, i + 1]
    return mom


def spline_eval(x: Tensor, u: Tensor, knots: Tensor, mom: Tensor, count: Tensor) -> Tensor:
    """Positions (B, Q, M) of the natural cubic splines (`u` (B, K), padded `knots` (B, K, M), moments from
    :func:`spline_moments`) at parameters `x` (B, Q) in [0, 1]."""
    i = torch.searchsorted(u.contiguous(), x.contiguous(), right=True) - 1
    i = torch.minimum(i.clamp(min=0), (count - 2).unsqueeze(1))
    h = (u[:, 1:] - u[:, :-1]).unsqueeze(2)
    h = torch.where(h > 0, h, torch.ones_like(h))
    y0, y1, m0, m1 = knots[:, :-1], knots[:, 1:], mom[:, :-1], mom[:, 1:]
    coef = torch.cat([y0, (y1 - y0) / h - h * (2.0 * m0 + m1) / 6.0, 0.5 * m0, (m1 - m0) / (6.0 * h)], dim=2)
    rows = (i + (coef.shape[1] * torch.arange(len(i), device=i.device)).unsqueeze(1)).view(-1)
    c = coef.reshape(-1, coef.shape[2]).index_select(0, rows).view(*i.shape, -1)  # (B, Q, 4 M): powers of t
    t = (x - u.gather(1, i)).unsqueeze(2)
    m = knots.shape[2]
    return c[..., :m] + t * (c[..., m:2 * m] + t * (c[..., 2 * m:3 * m] + t * c[..., 3 * m:]))


def _interp(x: Tensor, xp: Tensor, fp: Tensor) -> Tensor:
    """np.interp per row: x (B, Q), xp (B, P) non-decreasing, fp (B, P) -> (B, Q) (flat stretches: their start)."""
    i = (torch.searchsorted(xp.contiguous(), x.contiguous(), right=True) - 1).clamp(0, xp.shape[1] - 2)
    x0, x1, f0, f1 = xp.gather(1, i), xp.gather(1, i + 1), fp.gather(1, i), fp.gather(1, i + 1)
    dx = x1 - x0
    t = torch.where(dx > 0, (x - x0) / torch.where(dx > 0, dx, torch.ones_like(dx)), torch.zeros_like(dx))
    return torch.where(x >= x1, f1, f0 + t.clamp(0.0, 1.0) * (f1 - f0))


def _arc_lengths(knots: Tensor, count: Tensor, u: Tensor, mom: Tensor, arc_step: float,
                 extrapolate: bool) -> tuple[Tensor, Tensor]:
    """Parameters (B, Q) and arc lengths (B, Q) of a polyline through the splines at about one point per `arc_step`
    rad of chord (padding: u = 1, s = the length). `extrapolate`: Richardson's step on the polyline lengths at
    steps h and 2 h (error O(h^4) instead of O(h^2)), on every other point."""
    chord = (knots[:, 1:] - knots[:, :-1]).norm(dim=2).sum(dim=1)
    n = torch.clamp(torch.ceil(chord / arc_step).long() + 1, min=2)
    if extrapolate:
        n = n + (n % 2 == 0).long()  # odd: the last point is an even one
    j = torch.arange(int(n.max()), device=knots.device, dtype=knots.dtype).unsqueeze(0)
    uq = torch.clamp(j * (1.0 / (n - 1).to(knots.dtype)).unsqueeze(1), max=1.0)
    uq = torch.where(j >= (n - 1).unsqueeze(1), torch.ones_like(uq), uq)
    q = spline_eval(uq, u, knots, mom, count)
    s = torch.cat([torch.zeros_like(uq[:, :1]), (q[:, 1:] - q[:, :-1]).norm(dim=2).cumsum(dim=1)], dim=1)
    if not extrapolate:
        return uq, s
    if q.shape[1] % 2 == 0:
        q, s, uq = q[:, :-1], s[:, :-1], uq[:, :-1]  # an even width: its last column is padding
    even = q[:, ::2]
    s2 = torch.cat([torch.zeros_like(uq[:, :1]), (even[:, 1:] - even[:, :-1]).norm(dim=2).cumsum(dim=1)], dim=1)
    return uq[:, ::2], s[:, ::2] + (s[:, ::2] - s2) / 3.0


def tabulate_batch(knots: Tensor, count: Tensor, table_step: float, width: int, arc_step: float = ARC_LENGTH_STEP,
                   extrapolate: bool = False, chunk: int = 16) -> dict[str, Tensor]:
    """:func:`pathrl.paths.pathset.build_pathset`'s rows for B paths of distinct consecutive knots (padded (B, K, M),
    count (B,) >= 2): ``knot_s`` (B, K) (padding: the length), ``length`` (B,), ``table`` (B, width, M) (positions
    at s = j table_step, padded as build_pathset pads) and ``fits`` (B,): the table has room for the path (else
    its rows are cut off). Arc lengths: :func:`_arc_lengths` (build_pathset's with the defaults; training uses a
    coarser `arc_step` with `extrapolate`, which is faster and about as accurate). Paths are tabulated `chunk` at a
    time, sorted by length."""
    u = _chord_params(knots)
    mom = spline_moments(u, knots, count)
    b = knots.shape[0]
    out = {"knot_s": torch.empty_like(u), "length": torch.empty_like(u[:, 0]),
           "table": torch.empty(b, width, knots.shape[2], dtype=knots.dtype, device=knots.device),
           "fits": torch.empty(b, dtype=torch.bool, device=knots.device)}
    order = torch.argsort(u.new_tensor(0.0) + (knots[:, 1:] - knots[:, :-1]).norm(dim=2).sum(dim=1))
    for part in order.split(chunk):  # paths of similar length together: less padding
        rows = _tabulate_rows(knots[part], count[part], u[part], mom[part], table_step, width, arc_step, extrapolate)
        for key, value in rows.items():
            out[key][part] = value
    return out


def _tabulate_rows(knots: Tensor, count: Tensor, u: Tensor, mom: Tensor, table_step: float, width: int,
                   arc_step: float, extrapolate: bool) -> dict[str, Tensor]:
    """:func:`tabulate_batch` for some paths, given their parameters `u` and moments `mom`."""
    uq, s = _arc_lengths(knots, count, u, mom, arc_step, extrapolate)
    length = s[:, -1]
    knot_s = _interp(u, uq, s)
    knot_s = torch.where(torch.arange(knots.shape[1], device=knots.device) >= (count - 1).unsqueeze(1),
                         length.unsqueeze(1), knot_s)
    g = torch.ceil(length / table_step).long()  # grid points below the length (np.arange)
    cols = min(int(g.max()) + 1, width)
    rows = torch.arange(cols, device=knots.device).unsqueeze(0)
    grid = torch.minimum(rows.to(knots.dtype) * table_step, length.unsqueeze(1))
    grid = torch.where(rows >= g.unsqueeze(1), length.unsqueeze(1), grid)
    t = spline_eval(_interp(grid, s, uq), u, knots, mom, count)  # column g: the end
    last = torch.minimum((g - 1).clamp(min=0), torch.full_like(g, cols - 1))
    pick = lambda idx: t.gather(1, idx.view(-1, 1, 1).expand(-1, 1, t.shape[2]))  # noqa: E731
    t_prev, t_end = pick(last), pick(g.clamp(max=cols - 1))
    rest = (length - last.to(knots.dtype) * table_step).view(-1, 1, 1)
    ext = t_prev + (t_end - t_prev) * (table_step / torch.where(rest > 1e-9, rest, torch.ones_like(rest)))
    tail = torch.where(rest > 1e-9, ext, t_end)
    from_row = torch.where(rest.view(-1) > 1e-9, g, g - 1).unsqueeze(1)
    table = tail.expand(-1, width, -1).clone()
    table[:, :cols] = torch.where((rows >= from_row).unsqueeze(2), tail, t)
    return {"knot_s": knot_s, "length": length, "table": table, "fits": g + 1 < width}
