"""``ball_balancing`` generator (iiwa7 only): paths that keep the plate on the flange horizontal and facing up
(q3 = q5 = 0, q6 = q4 - q2, |q7| <= 0.009; docs/datasets.md)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from pathrl.datagen.generators.context import GenerationError, GeneratorContext
from pathrl.datagen.generators.rollout import _cut
from pathrl.dataset.io import DatasetError
from pathrl.paths.spline import PathError, resample_by_distance, sample_uniform
from pathrl.robot.model import RobotSpec

__all__ = [
    "KIND",
    "REFLECTIONS",
    "ball_constraint_violation",
    "ball_paths",
    "check_ball_robot",
    "check_robot",
    "region_box",
    "step_weights",
    "stored_paths",
]

KIND = "ball_balancing"

#: The authors' reflection vectors of their ball set (original_pathtracking.md 8.1): each path is used with one of
#: these joint sign patterns; all keep the plate horizontal (q6 = q4 - q2 holds for every pattern).
REFLECTIONS = np.array(
    [[1, 1, 1, 1, 1, 1, 1], [-1, -1, -1, -1, -1, -1, -1], [-1, 1, -1, 1, -1, 1, -1], [1, -1, 1, -1, 1, -1, 1]],
    dtype=float,
)


def _ball_full(red: np.ndarray) -> np.ndarray:
    """Reduced (q1, q2, q4, q7) (..., 4) -> iiwa joints (..., 7) with q3 = q5 = 0, q6 = q4 - q2."""
    q = np.zeros(red.shape[:-1] + (7,))
    q[..., 0], q[..., 1], q[..., 3], q[..., 6] = red[..., 0], red[..., 1], red[..., 2], red[..., 3]
    q[..., 5] = red[..., 2] - red[..., 1]
    return q


def ball_constraint_violation(q: np.ndarray) -> np.ndarray:
    """Per sample (..., 7): max(|q3|, |q5|, |q6 - (q4 - q2)|, max(|q7| - 0.009, 0))."""
    q = np.asarray(q)
    return np.max(
        np.stack(
            [
                np.abs(q[..., 2]),
                np.abs(q[..., 4]),
                np.abs(q[..., 5] - (q[..., 3] - q[..., 1])),
                np.maximum(np.abs(q[..., 6]) - 0.009, 0.0),
            ],
            axis=-1,
        ),
        axis=-1,
    )


def check_ball_robot(spec: RobotSpec) -> None:
    """DatasetError unless `spec` is the iiwa7 (7 joints, all path joints)."""
    if spec.dof != 7 or spec.path_dof != 7 or not spec.name.startswith("iiwa"):
        raise DatasetError(
            f"dataset ball_balancing is defined for the iiwa7 only (plate-horizontal joint constraints), "
            f"not for robot {spec.name!r}"
        )


def region_box(
    pos_limits: np.ndarray, region: Sequence[Sequence[float]] | None, key: str = "start_region"
) -> np.ndarray:
    """(3, 2) [lo, hi] rad of (q1, q2, q4): `region` (three [lo, hi] pairs, the dataset parameter `key`) clipped into
    the position limits (M, 2), or the limits themselves; DatasetError for a malformed or empty region."""
    lim = np.asarray(pos_limits, dtype=float)[[0, 1, 3]]
    if region is None:
        return lim
    try:
        box = np.asarray(region, dtype=float)
    except (TypeError, ValueError):
        box = np.zeros(0)
    if box.shape != (3, 2) or not np.all(np.isfinite(box)):
        raise DatasetError(f"dataset.params.{key}: expected three [lo, hi] pairs for q1, q2, q4, got {region!r}")
    box = np.stack([np.maximum(box[:, 0], lim[:, 0]), np.minimum(box[:, 1], lim[:, 1])], axis=1)
    if np.any(box[:, 0] > box[:, 1]):
        raise DatasetError(f"dataset.params.{key}: {region!r} lies outside the position limits")
    return box


def step_weights(weights: Sequence[float] | None) -> np.ndarray:
    """(3,) positive factors on the step direction's (q1, q2, q4) components (ones by default); DatasetError for a
    malformed one."""
    if weights is None:
        return np.ones(3)
    try:
        w = np.asarray(weights, dtype=float)
    except (TypeError, ValueError):
        w = np.zeros(0)
    if w.shape != (3,) or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise DatasetError(f"dataset.params.step_weights: three positive numbers (q1, q2, q4), got {weights!r}")
    return w


def _ball_point_ok(ctx: GeneratorContext, red: np.ndarray, region: np.ndarray | None = None) -> bool:
    lim = ctx.spec.pos_limits
    if region is not None and (np.any(red[:3] < region[:, 0]) or np.any(red[:3] > region[:, 1])):
        return False
    q = _ball_full(red)
    if np.any(q < lim[:, 0]) or np.any(q > lim[:, 1]):
        return False
    return bool(ctx.in_workspace(q[None])[0]) and not bool(ctx.in_collision(q[None])[0])


def _ball_waypoints(
    ctx: GeneratorContext, p: Mapping[str, Any], rng: np.random.Generator, length: float
) -> np.ndarray | None:
    """Reduced waypoints (W, 4): a valid random start, then valid steps until the polyline is 15 % longer than
    `length`; None if the walk gets stuck before that."""
    step_lo, step_hi = (float(x) for x in p["waypoint_step"])
    q7_max = float(p["q7_max"])
    turn = float(p["waypoint_turn"])
    box = region_box(ctx.spec.pos_limits, p.get("start_region"), "start_region")
    region = None if p.get("region") is None else region_box(ctx.spec.pos_limits, p["region"], "region")
    weights = step_weights(p.get("step_weights"))
    sweep = bool(p.get("sweep", False))
    # start: uniform in the start box of (q1, q2, q4) with q6 = q4 - q2 in limits, plate in the workspace, collision
    # free
    for _ in range(10_000):
        red = np.r_[rng.uniform(box[:, 0], box[:, 1]), rng.uniform(-q7_max, q7_max)]
        if _ball_point_ok(ctx, red, region):
            break
    else:
        raise GenerationError("ball_balancing: no valid start configuration found")
    pts, poly = [red], 0.0
    heading = np.array([1.0, 0.0, 0.0]) if sweep else rng.normal(size=3)
    while poly < 1.15 * length:
        for _ in range(50):
            direction = heading / np.linalg.norm(heading) + turn * rng.normal(size=3)
            direction *= weights
            if sweep:  # q1 never turns back
                direction[0] = abs(direction[0])
            direction /= np.linalg.norm(direction)
            nxt = pts[-1].copy()
            nxt[:3] += direction * rng.uniform(step_lo, step_hi)
            if sweep and region is not None:  # the base stops at the region's end and the walk goes on
                nxt[0] = min(nxt[0], region[0, 1])
            nxt[3] = rng.uniform(-q7_max, q7_max)
            if _ball_point_ok(ctx, nxt, region):
                break
        else:
            break
        heading = direction
        poly += float(np.linalg.norm(_ball_full(nxt) - _ball_full(pts[-1])))
        pts.append(nxt)
    if poly < 1.15 * length:
        return None
    return np.asarray(pts)


def _ball_stored(
    ctx: GeneratorContext,
    p: Mapping[str, Any],
    pts: np.ndarray,
    length: float,
    stats: dict[str, int],
    sign: np.ndarray | None = None,
) -> np.ndarray | None:
    """Stored knots of the spline through the reduced waypoints `pts`, cut at `length`, each joint times `sign` (7,)
    if given; None if rejected."""
    lo, hi = p["length_range"]
    knots = _ball_full(pts)
    try:
        dense, total = sample_uniform(knots, float(p["check_spacing"]) / 4)
    except PathError:
        return None
    if total < length:
        return None
    cum = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))]
    path = _cut(dense, cum, length)
    try:
        stored = resample_by_distance(path, float(p["knot_spacing"]))
        if sign is not None:
            stored = stored * sign
        check, stored_length = sample_uniform(stored, float(p["check_spacing"]))
    except PathError:
        return None
    if not lo <= stored_length <= hi:  # sharp turns cut short by the knot spacing
        stats["rejected_length"] = stats.get("rejected_length", 0) + 1
        return None
    stats["checks"] = stats.get("checks", 0) + len(check)
    if not _ball_valid(ctx, check):
        stats["rejected"] = stats.get("rejected", 0) + 1
        return None
    return stored


def ball_paths(
    ctx: GeneratorContext,
    p: Mapping[str, Any],
    n_paths: int,
    rng: np.random.Generator,
    stats: dict[str, int] | None = None,
) -> list[np.ndarray]:
    """Plate-horizontal iiwa paths: spline through valid random (q1, q2, q4, q7) waypoints, cut, checked."""
    check_ball_robot(ctx.spec)
    stats = stats if stats is not None else {}
    lo, hi = p["length_range"]
    a_beta, b_beta = (float(x) for x in p["length_beta"])
    out: list[np.ndarray] = []
    tries = 0
    while len(out) < n_paths:
        tries += 1
        if tries > int(p["max_tries"]) * max(n_paths, 1):
            raise GenerationError(f"ball_balancing: only {len(out)} of {n_paths} valid paths in {tries} tries")
        stats["candidates"] = stats.get("candidates", 0) + 1
        length = lo + (hi - lo) * rng.beta(a_beta, b_beta)
        pts = _ball_waypoints(ctx, p, rng, length)
        sign = REFLECTIONS[rng.integers(len(REFLECTIONS))] if p.get("reflections", False) else None
        stored = None if pts is None else _ball_stored(ctx, p, pts, length, stats, sign)
        if stored is not None:
            out.append(stored)
    stats["accepted"] = stats.get("accepted", 0) + len(out)
    return out


def _ball_valid(ctx: GeneratorContext, q: np.ndarray) -> bool:
    lim = ctx.spec.pos_limits
    if np.any(q < lim[:, 0] - 1e-9) or np.any(q > lim[:, 1] + 1e-9):
        return False
    if np.any(ball_constraint_violation(q) > 1e-9):
        return False
    if not np.all(ctx.in_workspace(q)):
        return False
    return not np.any(ctx.in_collision(q))


check_robot = check_ball_robot


def stored_paths(
    ctx: GeneratorContext,
    params: Mapping[str, Any],
    n: int,
    rng: np.random.Generator,
    tgen: torch.Generator,
    stats: dict[str, int],
) -> list[np.ndarray]:
    """`n` stored paths of one chunk (:func:`ball_paths`; `tgen` is not used)."""
    return ball_paths(ctx, params, n, rng, stats)
