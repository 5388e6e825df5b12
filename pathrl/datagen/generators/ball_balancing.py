"""``ball_balancing`` generator (iiwa7 only): paths that keep the plate on the flange horizontal and facing up
(q3 = q5 = 0, q6 = q4 - q2, |q7| <= 0.009; docs/datasets.md)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from pathrl.datagen.generators.context import GenerationError, GeneratorContext
from pathrl.datagen.generators.rollout import _cut
from pathrl.dataset.io import DatasetError
from pathrl.paths.spline import PathError, resample_by_distance, sample_uniform
from pathrl.robot.model import RobotSpec

__all__ = ["KIND", "ball_constraint_violation", "ball_paths", "check_ball_robot", "check_robot", "stored_paths"]

KIND = "ball_balancing"


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


def _ball_point_ok(ctx: GeneratorContext, red: np.ndarray) -> bool:
    lim = ctx.spec.pos_limits
    q = _ball_full(red)
    if np.any(q < lim[:, 0]) or np.any(q > lim[:, 1]):
        return False
    return bool(ctx.in_workspace(q[None])[0]) and not bool(ctx.in_collision(q[None])[0])


def _ball_waypoints(
    ctx: GeneratorContext, p: Mapping[str, Any], rng: np.random.Generator, length: float
) -> np.ndarray | None:
    """Reduced waypoints (W, 4): a valid random start, then valid steps until the polyline is 15 % longer than
    `length`; None if the walk gets stuck before that."""
    lim = ctx.spec.pos_limits
    step_lo, step_hi = (float(x) for x in p["waypoint_step"])
    q7_max = float(p["q7_max"])
    turn = float(p["waypoint_turn"])
    # start: uniform in (q1, q2, q4) with q6 = q4 - q2 in limits, plate in the workspace, collision free
    for _ in range(10_000):
        red = np.array(
            [
                rng.uniform(*lim[0]),
                rng.uniform(*lim[1]),
                rng.uniform(*lim[3]),
                rng.uniform(-q7_max, q7_max),
            ]
        )
        if _ball_point_ok(ctx, red):
            break
    else:
        raise GenerationError("ball_balancing: no valid start configuration found")
    pts, poly = [red], 0.0
    heading = rng.normal(size=3)
    while poly < 1.15 * length:
        for _ in range(50):
            direction = heading / np.linalg.norm(heading) + turn * rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            nxt = pts[-1].copy()
            nxt[:3] += direction * rng.uniform(step_lo, step_hi)
            nxt[3] = rng.uniform(-q7_max, q7_max)
            if _ball_point_ok(ctx, nxt):
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
    ctx: GeneratorContext, p: Mapping[str, Any], pts: np.ndarray, length: float, stats: dict[str, int]
) -> np.ndarray | None:
    """Stored knots of the spline through the reduced waypoints `pts`, cut at `length`; None if rejected."""
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
        stored = None if pts is None else _ball_stored(ctx, p, pts, length, stats)
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

