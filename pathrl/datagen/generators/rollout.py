"""Batched limit-respecting rollouts shared by the ``random`` and ``target_point`` generators.

A motion policy (:class:`MotionPolicy`) picks normalised actions; they are mapped into the valid acceleration
range of :mod:`pathrl.limits`, integrated with linear acceleration interpolation, recorded and collision checked
``substeps`` times per decision step; collisions rewind a candidate to its last checkpoint (docs/datasets.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import torch

from pathrl.datagen.generators.context import GeneratorContext
from pathrl.datagen.generators.ik import sample_starts
from pathrl.paths.spline import dedupe_knots, resample_by_distance, sample_uniform

__all__ = ["MotionPolicy", "path_valid", "rollout_paths", "stored_rollout_paths"]


class MotionPolicy(Protocol):
    """Actions of b candidate motions; `rows` index the candidates a call is about."""

    def reset(self, q0: torch.Tensor) -> torch.Tensor:
        """Start at q0 (b, D) -> mask (b,) of candidates that cannot start."""

    def action(self, rows, p, v, a, a_min, a_max) -> torch.Tensor:
        """Normalised actions in [-1, 1] (n, D) for the state (p, v, a) of `rows` and their valid range."""

    def after_step(self, rows, p, steps) -> tuple[torch.Tensor, torch.Tensor]:
        """-> (checkpoint mask, reject mask) for `rows`."""

    def finished(self, rows: torch.Tensor) -> None:
        """Rows that no longer move (done or dropped)."""

    def on_rewind(self, rows, p) -> torch.Tensor:
        """Rows rewound to their checkpoint at p -> mask of rows to drop."""


@dataclass
class _Candidates:
    """State of b candidate motions: pos/vel/acc (b, D), recorded path joints rec (b, cap, M) with their
    cumulative arc lengths s (b, cap) and counts n_rec (b,), the last checkpoint ck, target lengths (b,)."""

    pos: torch.Tensor
    vel: torch.Tensor
    acc: torch.Tensor
    rec: torch.Tensor
    s: torch.Tensor
    n_rec: torch.Tensor
    steps: torch.Tensor
    rewinds: torch.Tensor
    ck: dict[str, torch.Tensor]
    target: torch.Tensor
    active: torch.Tensor
    done: torch.Tensor

    @classmethod
    def start(cls, ctx: GeneratorContext, q0: torch.Tensor, target: torch.Tensor, cap: int) -> _Candidates:
        b, d, m = len(q0), ctx.spec.dof, len(ctx.pidx)
        pos, vel, acc = (
            q0.clone(),
            torch.zeros(b, d, dtype=torch.float64),
            torch.zeros(b, d, dtype=torch.float64),
        )
        rec = torch.zeros(b, cap, m, dtype=torch.float64)
        s = torch.zeros(b, cap, dtype=torch.float64)
        rec[:, 0] = q0[:, ctx.pidx]
        n_rec = torch.ones(b, dtype=torch.long)
        steps = torch.zeros(b, dtype=torch.long)
        rewinds = torch.zeros(b, dtype=torch.long)
        ck = {
            "pos": pos.clone(),
            "vel": vel.clone(),
            "acc": acc.clone(),
            "n": n_rec.clone(),
            "steps": steps.clone(),
        }
        active = torch.ones(b, dtype=torch.bool)
        done = torch.zeros(b, dtype=torch.bool)
        return cls(pos, vel, acc, rec, s, n_rec, steps, rewinds, ck, target, active, done)

    def checkpoint(self, c: torch.Tensor) -> None:
        """Save the state of rows `c` as their checkpoint."""
        for key, val in (
            ("pos", self.pos),
            ("vel", self.vel),
            ("acc", self.acc),
            ("n", self.n_rec),
            ("steps", self.steps),
        ):
            self.ck[key][c] = val[c]
        self.rewinds[c] = 0


def _cut(rec: np.ndarray, s: np.ndarray, length: float) -> np.ndarray:
    """Recorded polyline (S, M) with cumulative lengths s, cut at arc length `length`."""
    j = int(np.searchsorted(s, length))
    if j >= len(s):
        return rec
    seg = s[j] - s[j - 1]
    w = (length - s[j - 1]) / seg if seg > 0 else 1.0
    out = rec[: j + 1].copy()
    out[j] = rec[j - 1] + w * (rec[j] - rec[j - 1])
    return out


def _accept(
    ctx: GeneratorContext,
    pol: MotionPolicy,
    st: _Candidates,
    r: torch.Tensor,
    step: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    n_sub: int,
    stats: dict[str, int],
) -> None:
    """Record the collision-free step (ps, vs, a1) of rows `r`; finish, drop or checkpoint them."""
    ps, vs, a1 = step
    cap = st.rec.shape[1]
    new = ps[:, :, ctx.pidx]  # (k, n_sub, M)
    cols = st.n_rec[r][:, None] + torch.arange(n_sub)
    prev = st.rec[r, st.n_rec[r] - 1]
    seg = torch.diff(torch.cat([prev[:, None], new], dim=1), dim=1).norm(dim=-1)
    st.rec[r[:, None], cols] = new
    st.s[r[:, None], cols] = st.s[r, st.n_rec[r] - 1][:, None] + torch.cumsum(seg, dim=1)
    st.n_rec[r] += n_sub
    st.pos[r], st.vel[r], st.acc[r] = ps[:, -1], vs[:, -1], a1
    st.steps[r] += 1
    fin = st.s[r, st.n_rec[r] - 1] >= st.target[r]
    st.done[r[fin]] = True
    st.active[r[fin]] = False
    rest = ~fin
    r2 = r[rest]
    if len(r2):
        ckm, rej = pol.after_step(r2, st.pos[r2], st.steps)
        timeout = st.n_rec[r2] + n_sub > cap
        stats["dropped_timeout"] = stats.get("dropped_timeout", 0) + int(timeout.sum())
        stats["dropped_goal"] = stats.get("dropped_goal", 0) + int((rej & ~timeout).sum())
        rej = rej | timeout
        st.active[r2[rej]] = False
        st.checkpoint(r2[ckm & ~rej])


def _rewind(pol: MotionPolicy, st: _Candidates, r: torch.Tensor, max_rewinds: int, stats: dict[str, int]) -> None:
    """Rows `r` collided: back to their checkpoint, or dropped after `max_rewinds` rewinds in a row."""
    st.rewinds[r] += 1
    stats["rewinds"] = stats.get("rewinds", 0) + len(r)
    give_up = st.rewinds[r] > max_rewinds
    stats["dropped_collision"] = stats.get("dropped_collision", 0) + int(give_up.sum())
    st.active[r[give_up]] = False
    r = r[~give_up]
    if len(r):
        st.pos[r], st.vel[r], st.acc[r] = st.ck["pos"][r], st.ck["vel"][r], st.ck["acc"][r]
        st.n_rec[r], st.steps[r] = st.ck["n"][r], st.ck["steps"][r]
        fail = pol.on_rewind(r, st.pos[r])
        st.active[r[fail]] = False


def _simulate(
    ctx: GeneratorContext,
    pol: MotionPolicy,
    st: _Candidates,
    p: Mapping[str, Any],
    max_steps: int,
    stats: dict[str, int],
) -> None:
    """Step every active candidate until each is done or dropped (at most 4 x max_steps rounds)."""
    from pathrl.limits.feasible import action_to_acceleration, valid_acceleration_range
    from pathrl.limits.integrate import interpolate_step

    dt, n_sub = float(p["dt"]), int(p["substeps"])
    d = ctx.spec.dof
    was_active = st.active.clone()
    for _ in range(max_steps * 4):
        ended = (was_active & ~st.active).nonzero().squeeze(1)
        if len(ended):
            pol.finished(ended)
        was_active = st.active.clone()
        rows = st.active.nonzero().squeeze(1)
        if len(rows) == 0:
            break
        p0, v0, a0 = st.pos[rows], st.vel[rows], st.acc[rows]
        a_min, a_max = valid_acceleration_range(p0, v0, a0, ctx.limits, dt)
        act = pol.action(rows, p0, v0, a0, a_min, a_max)
        a1 = action_to_acceleration(act, a_min, a_max)
        ps, vs, _ = interpolate_step(p0, v0, a0, a1, dt, n_sub)  # (n, n_sub, D)
        coll = torch.as_tensor(ctx.in_collision(ps.reshape(-1, d)).reshape(len(rows), n_sub).any(axis=1))
        stats["checks"] = stats.get("checks", 0) + len(rows) * n_sub
        ok = ~coll
        if ok.any():
            _accept(ctx, pol, st, rows[ok], (ps[ok], vs[ok], a1[ok]), n_sub, stats)
        if coll.any():
            _rewind(pol, st, rows[coll], int(p["max_rewinds"]), stats)


def rollout_paths(
    ctx: GeneratorContext,
    make_policy: Callable[[int], MotionPolicy],
    p: Mapping[str, Any],
    n_paths: int,
    rng: np.random.Generator,
    stats: dict[str, int] | None = None,
) -> list[np.ndarray]:
    """Recorded polylines (path joints) of `n_paths` accepted limit-respecting motions.

    make_policy(b) gives the motion policy of a batch of b candidates.
    """
    stats = stats if stats is not None else {}
    dt, n_sub = float(p["dt"]), int(p["substeps"])
    lo_len, hi_len = p["length_range"]
    max_steps = int(math.ceil(float(p["max_duration"]) / dt))
    cap = max_steps * n_sub + 1
    out: list[np.ndarray] = []
    while len(out) < n_paths:
        # enough candidates for the missing paths (some get dropped), at most batch_size
        b = min(int(p["batch_size"]), math.ceil(float(p["oversample"]) * (n_paths - len(out))) + 1)
        q0 = torch.as_tensor(sample_starts(ctx, rng, b))
        target = torch.as_tensor(rng.uniform(lo_len, hi_len, size=b))
        pol = make_policy(b)
        st = _Candidates.start(ctx, q0, target, cap)
        st.active = ~pol.reset(q0)
        stats["candidates"] = stats.get("candidates", 0) + b
        _simulate(ctx, pol, st, p, max_steps, stats)
        for i in st.done.nonzero().squeeze(1).tolist():
            n_i = int(st.n_rec[i])
            out.append(_cut(st.rec[i, :n_i].numpy(), st.s[i, :n_i].numpy(), float(st.target[i])))
            if len(out) == n_paths:
                break
    stats["accepted"] = stats.get("accepted", 0) + len(out)
    return out


def path_valid(ctx: GeneratorContext, knots: np.ndarray, spacing: float) -> bool:
    """The stored path (spline through `knots`) within the position limits (dense samples, 0.01 rad)
    and collision free (samples every `spacing` rad)."""
    lim = ctx.spec.pos_limits
    q, _ = sample_uniform(knots, 0.01)
    if np.any(q < lim[:, 0]) or np.any(q > lim[:, 1]):
        return False
    qc, _ = sample_uniform(knots, spacing)
    return not np.any(ctx.in_collision(qc))


def stored_rollout_paths(
    ctx: GeneratorContext,
    make_policy: Callable[[int], MotionPolicy],
    params: Mapping[str, Any],
    n: int,
    rng: np.random.Generator,
    stats: dict[str, int],
) -> list[np.ndarray]:
    """`n` stored paths: rollouts within the position limits shrunk by ``limit_margin``, resampled every
    ``knot_spacing`` rad and checked (:func:`path_valid`); rejected ones are replaced."""
    ctx.set_margin(float(params["limit_margin"]))
    stored: list[np.ndarray] = []
    while len(stored) < n:
        polys = rollout_paths(ctx, make_policy, params, n - len(stored), rng, stats)
        for pl in polys:
            k = resample_by_distance(dedupe_knots(pl), float(params["knot_spacing"]))
            if path_valid(ctx, k, float(params["check_spacing"])):
                stored.append(k)
            else:
                stats["rejected_final"] = stats.get("rejected_final", 0) + 1
    return stored
