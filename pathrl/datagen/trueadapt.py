"""TrueAdapt reference trajectories: time-parameterised iiwa7 plate motions sampled every ``sample_dt`` (50 ms).

Pipeline per trajectory (TrueAdapt Sec. IV / VII-A):

1. Cartesian waypoints of the plate centre (TCP), one per sampling area (``areas``: boxes in the top view,
   x/y in metres, robot base frame), at a height drawn per trajectory from ``z_range`` plus a per-waypoint
   jitter of up to ``z_jitter``;
2. a smooth Cartesian path: a natural cubic spline through the waypoints over their chord length, sampled
   every ``cartesian_step`` metres;
3. inverse kinematics with the plate kept level and facing up: joints 3 and 5 at 0, q6 = q4 - q2 (the flange
   axis stays vertical), q7 = 0. The closed-form elbow-up solution seeds the project's damped least-squares
   IK (:func:`pathrl.datagen.generators.ik.solve_ik`), which must confirm it to ``ik_tolerance``; every sample
   must lie inside the position limits (shrunk by ``limit_margin``) and be collision free (every
   ``check_stride``-th sample);
4. time-optimal parameterisation of the joint path with TOPP-RA (:func:`pathrl.baselines.toppra.solve_segment`,
   the project's harness) under the robot's velocity and acceleration limits scaled by ``vel_scale`` /
   ``acc_scale`` (TOPP-RA knows no jerk limits; the env clips every step into the valid range anyway);
5. sampled every ``sample_dt`` seconds from rest to rest (the last sample is the end at rest).

Mirroring (``mirror: true``, the paper's x4 augmentation): each drawn set of waypoints is also mirrored
about the vertical plane y = 0 and about the vertical plane x = ``mirror_x``, and about both; every variant
goes through steps 2-5. A group is kept only if all four variants are valid, and the four stay in the same
split (no train/test leakage). ``num_train`` / ``num_test`` count the drawn (base) trajectories; with
mirroring a split stores four times as many.

Storage: the project's dataset format, read back by :mod:`pathrl.dataset.trueadapt` (``load_trajectories``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import torch
from scipy.interpolate import make_interp_spline

from pathrl.dataset.io import DatasetError, check_destination, save_dataset
from pathrl.dataset.stats import dataset_stats
from pathrl.dataset.trueadapt import KIND, trajectory_stats
from pathrl.robot.model import RobotSpec, load_robot

__all__ = [
    "DEFAULT_PARAMS", "FORE", "HAND", "SHOULDER_Z", "UPPER", "cartesian_path", "generate_chunk", "generate_trueadapt",
    "level_plate_ik", "level_plate_seed", "mirror_variants", "resolve_params", "sample_waypoints",
    "time_optimal_samples", "trajectory_from_waypoints",
]

#: iiwa7 geometry behind the closed-form seed (pathrl/assets/urdf/iiwa7.urdf): shoulder height, upper arm,
#: forearm, joint-6 axis to TCP (the plate centre).
SHOULDER_Z, UPPER, FORE, HAND = 0.34, 0.40, 0.40, 0.126

DEFAULT_PARAMS: dict[str, Any] = {
    "areas": [[[0.42, 0.52], [0.28, 0.40]], [[0.47, 0.57], [-0.10, 0.10]], [[0.42, 0.52], [-0.40, -0.28]]],
    "z_range": [0.62, 0.82],  # plate height per trajectory (m, base frame)
    "z_jitter": 0.04,  # +- per waypoint (m)
    "cartesian_step": 0.01,  # m between IK samples of the Cartesian spline
    "vel_scale": 0.5,  # TOPP-RA limits: these fractions of the robot's velocity / acceleration limits
    "acc_scale": 0.07,
    "sample_dt": 0.05,  # s between stored samples (the policy's decision step)
    "mirror": True,  # x4: mirrored about y = 0 and about x = mirror_x
    "mirror_x": 0.52,
    "limit_margin": 0.05,  # rad inside the position limits
    "ik_tolerance": 1e-4,  # m
    "check_stride": 5,  # collision check every n-th IK sample
    "max_tries": 50,  # drawn groups per requested trajectory before giving up
    "chunk_size": 25,
}


def resolve_params(params: Mapping[str, Any] | None) -> dict[str, Any]:
    """DEFAULT_PARAMS updated by `params`; unknown keys and invalid values raise DatasetError (one line)."""
    out = {**DEFAULT_PARAMS}
    unknown = sorted(set(params or {}) - set(out))
    if unknown:
        raise DatasetError(f"dataset.params: unknown keys {unknown} for {KIND!r}; valid: {sorted(out)}")
    out.update({k: (list(v) if isinstance(v, Sequence) and not isinstance(v, str) else v)
                for k, v in (params or {}).items()})
    try:
        areas = np.asarray(out["areas"], dtype=np.float64)
        zr = np.asarray(out["z_range"], dtype=np.float64)
    except (TypeError, ValueError):
        raise DatasetError("dataset.params.areas / z_range: expected [[[x0, x1], [y0, y1]], ...] / [z0, z1]") from None
    if areas.ndim != 3 or areas.shape[1:] != (2, 2) or len(areas) < 2 or np.any(areas[:, :, 0] >= areas[:, :, 1]):
        raise DatasetError(f"dataset.params.areas: need >= 2 boxes [[x0, x1], [y0, y1]] with x0 < x1, y0 < y1; "
                           f"got {out['areas']}")
    if zr.shape != (2,) or not zr[0] <= zr[1]:
        raise DatasetError(f"dataset.params.z_range: expected [z0 <= z1], got {out['z_range']}")
    for key in ("vel_scale", "acc_scale"):
        if not 0.0 < float(out[key]) <= 1.0:
            raise DatasetError(f"dataset.params.{key} must be in (0, 1], got {out[key]}")
    for key in ("sample_dt", "cartesian_step", "ik_tolerance"):
        if not float(out[key]) > 0.0:
            raise DatasetError(f"dataset.params.{key} must be > 0, got {out[key]}")
    for key in ("check_stride", "max_tries", "chunk_size"):
        if int(out[key]) < 1:
            raise DatasetError(f"dataset.params.{key} must be >= 1, got {out[key]}")
    return out


# ----------------------------------------------------------------------------------------------------
# pure steps


def sample_waypoints(rng: np.random.Generator, areas: np.ndarray, z_range: Sequence[float],
                     z_jitter: float) -> np.ndarray:
    """One waypoint per area (A, 2, 2): uniform in its box, at a common height plus jitter; (A, 3) metres."""
    xy = rng.uniform(areas[:, :, 0], areas[:, :, 1])
    z = rng.uniform(*z_range) + rng.uniform(-z_jitter, z_jitter, size=len(areas))
    return np.column_stack([xy, z])


def mirror_variants(waypoints: np.ndarray, mirror_x: float) -> list[np.ndarray]:
    """The waypoints (W, 3) and their mirror images about y = 0, about x = mirror_x, and about both."""
    my = waypoints * np.array([1.0, -1.0, 1.0])
    mx = waypoints * np.array([-1.0, 1.0, 1.0]) + np.array([2.0 * mirror_x, 0.0, 0.0])
    return [waypoints, my, mx, mx * np.array([1.0, -1.0, 1.0])]


def cartesian_path(waypoints: np.ndarray, step: float) -> np.ndarray:
    """Natural cubic spline through waypoints (W, 3) over chord length, sampled every ~`step` m; (S, 3)."""
    chord = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1))]
    spline = make_interp_spline(chord, waypoints, k=3 if len(waypoints) > 2 else 1,
                                bc_type="natural" if len(waypoints) > 2 else None)
    n = max(int(math.ceil(chord[-1] / step)) + 1, 3)
    return spline(np.linspace(0.0, chord[-1], n))


def level_plate_seed(points: np.ndarray) -> np.ndarray:
    """Closed-form elbow-up joints (S, 7) putting the TCP at `points` (S, 3) with the plate level, facing up.

    In the arm's vertical plane (azimuth q1) the upper arm and forearm make angles q2 and q2 - q4 with the
    vertical; with q6 = q4 - q2 the flange stays vertical and the TCP sits HAND above the wrist. NaN where the
    point is out of reach.
    """
    q1 = np.arctan2(points[:, 1], points[:, 0])
    r = np.hypot(points[:, 0], points[:, 1])
    h = points[:, 2] - HAND - SHOULDER_Z
    mu = np.arctan2(r, h)  # direction of the wrist from the shoulder, from the vertical
    with np.errstate(invalid="ignore"):
        delta = np.arccos(np.hypot(r, h) / (UPPER + FORE))  # equal links: both deviate by delta from mu
    q = np.zeros((len(points), 7))
    q[:, 0], q[:, 1], q[:, 3] = q1, mu - delta, -2.0 * delta
    q[:, 5] = q[:, 3] - q[:, 1]
    return q


class _LevelPlateIK:
    """Adapter for :func:`pathrl.datagen.generators.ik.solve_ik`: (q1, q2, q4) -> full joints of the level plate."""

    def __init__(self, spec: RobotSpec, margin: float):
        from pathrl.robot.kinematics import ForwardKinematics

        self._fk = ForwardKinematics(spec)
        lim = torch.as_tensor(spec.pos_limits[[0, 1, 3]]) + torch.tensor([margin, -margin], dtype=torch.float64)
        self.lo, self.hi = lim[:, 0], lim[:, 1]
        self.fk = self  # solve_ik calls ctx.fk.tcp_positions

    @staticmethod
    def full(red: torch.Tensor) -> torch.Tensor:
        q = torch.zeros(len(red), 7, dtype=red.dtype)
        q[:, 0], q[:, 1], q[:, 3], q[:, 5] = red[:, 0], red[:, 1], red[:, 2], red[:, 2] - red[:, 1]
        return q

    def tcp_positions(self, red: torch.Tensor) -> torch.Tensor:
        return self._fk.tcp_positions(self.full(red))


def level_plate_ik(ik: _LevelPlateIK, points: np.ndarray, tolerance: float) -> np.ndarray | None:
    """Joints (S, 7) for TCP points (S, 3) with a level plate, or None if any point is unreachable."""
    from pathrl.datagen.generators.ik import solve_ik

    seed = level_plate_seed(points)
    if not np.all(np.isfinite(seed)):
        return None
    red = torch.as_tensor(seed[:, [0, 1, 3]])
    red = torch.minimum(torch.maximum(red, ik.lo), ik.hi)
    q, ok = solve_ik(ik, red, torch.as_tensor(points)[:, None, :], iterations=30, tolerance=tolerance)
    return ik.full(q).numpy() if bool(ok.all()) else None


def time_optimal_samples(q_path: np.ndarray, spec: RobotSpec, p: Mapping[str, Any]) -> np.ndarray | None:
    """TOPP-RA along the joint path (S, 7) under the scaled limits, sampled every sample_dt; (T, 7) or None."""
    from pathrl.baselines.toppra import ToppraSettings, path_limits, solve_segment
    from pathrl.paths.spline import PathError, dedupe_knots, knot_arc_lengths

    try:
        knots = dedupe_knots(q_path, tol=1e-6)
        _, length = knot_arc_lengths(knots)
    except PathError:
        return None
    lim = path_limits(spec)
    lim = replace(lim, vel=lim.vel * float(p["vel_scale"]), acc=lim.acc * float(p["acc_scale"]))
    res = solve_segment(knots, 0.0, length, lim, ToppraSettings(control_rate=1.0 / float(p["sample_dt"])))
    if not res.ok or len(res.q) < 3:
        return None
    return res.q


# ----------------------------------------------------------------------------------------------------
# generation


class _Context:
    def __init__(self, robot_cfg: Mapping[str, Any], p: Mapping[str, Any]):
        from pathrl.robot.collision import CollisionChecker

        torch.set_num_threads(1)
        self.spec = load_robot(robot_cfg)
        self.ik = _LevelPlateIK(self.spec, float(p["limit_margin"]))
        self.checker = CollisionChecker(self.spec)
        m = float(p["limit_margin"])
        self.lo, self.hi = self.spec.pos_limits[:, 0] + m, self.spec.pos_limits[:, 1] - m


def trajectory_from_waypoints(ctx: _Context, waypoints: np.ndarray, p: Mapping[str, Any],
                              stats: dict[str, int]) -> np.ndarray | None:
    """Steps 2-5 of the module docstring for one set of waypoints; samples (T, 7) or None (reason counted)."""
    q = level_plate_ik(ctx.ik, cartesian_path(waypoints, float(p["cartesian_step"])), float(p["ik_tolerance"]))
    if q is None or np.any(q < ctx.lo) or np.any(q > ctx.hi):
        stats["rejected_ik"] = stats.get("rejected_ik", 0) + 1
        return None
    if np.any(ctx.checker.in_collision(q[:: int(p["check_stride"])])):
        stats["rejected_collision"] = stats.get("rejected_collision", 0) + 1
        return None
    out = time_optimal_samples(q, ctx.spec, p)
    if out is None:
        stats["rejected_toppra"] = stats.get("rejected_toppra", 0) + 1
    return out


def generate_chunk(robot_cfg: Mapping[str, Any], params: Mapping[str, Any], seed: int, split_id: int, chunk: int,
                   n: int) -> dict[str, Any]:
    """`n` groups (1 or 4 trajectories each) from the seeded stream (seed, split, chunk)."""
    from pathrl.datagen.generators.context import GenerationError, chunk_rngs

    ctx = _Context(robot_cfg, params)
    rng, _ = chunk_rngs(seed, split_id, chunk)
    areas = np.asarray(params["areas"], dtype=np.float64)
    stats: dict[str, int] = {}
    groups: list[list[np.ndarray]] = []
    t0 = time.perf_counter()
    while len(groups) < n:
        stats["drawn"] = stats.get("drawn", 0) + 1
        if stats["drawn"] > int(params["max_tries"]) * n:
            raise GenerationError(f"{KIND}: only {len(groups)} of {n} valid trajectories in {stats['drawn']} "
                                  f"draws ({stats}); check dataset.params.areas / z_range against the reach")
        wp = sample_waypoints(rng, areas, params["z_range"], float(params["z_jitter"]))
        variants = mirror_variants(wp, float(params["mirror_x"])) if params["mirror"] else [wp]
        group = []
        for v in variants:
            traj = trajectory_from_waypoints(ctx, v, params, stats)
            if traj is None:
                break
            group.append(traj)
        if len(group) == len(variants):
            groups.append(group)
    return {"groups": groups, "stats": stats, "seconds": time.perf_counter() - t0}


def generate_trueadapt(robot_cfg: Mapping[str, Any], dataset_cfg: Mapping[str, Any], dest: str | None = None,
                       workers: int = 1, overwrite: bool = False, progress: bool = True):
    """Generate and save a TrueAdapt trajectory set (same signature as
    :func:`pathrl.datagen.generate.generate_dataset`, which dispatches here for ``kind: trueadapt``)."""
    from pathrl.datagen.generators.jobs import chunk_jobs, run_jobs, split_counts

    robot_cfg = dict(robot_cfg)
    spec = load_robot(robot_cfg)
    if not spec.name.startswith("iiwa") or spec.dof != 7:
        raise DatasetError(f"dataset {KIND}: the level-plate IK is for the iiwa7, not robot {spec.name!r}")
    p = resolve_params(dataset_cfg.get("params"))
    seed = int(dataset_cfg.get("seed", 0))
    counts = split_counts(dataset_cfg)
    dest = str(dest if dest is not None else dataset_cfg["path"])
    check_destination(dest, overwrite)
    t0 = time.perf_counter()
    jobs = chunk_jobs(counts, int(p["chunk_size"]))
    results = run_jobs(jobs, _ChunkFn(robot_cfg, p, seed), workers, progress, f"{spec.name}/{KIND}",
                        sum(counts.values()))
    splits: dict[str, list[tuple[str, np.ndarray]]] = {"train": [], "test": []}
    gen: dict[str, float] = {}
    bases = {"train": 0, "test": 0}
    for job, res in zip(jobs, results, strict=True):
        for group in res["groups"]:
            splits[job.split] += [(f"{job.split}_{bases[job.split]:05d}_m{k}", q) for k, q in enumerate(group)]
            bases[job.split] += 1
        for key, val in res["stats"].items():
            gen[key] = gen.get(key, 0) + int(val)
        gen["worker_seconds"] = gen.get("worker_seconds", 0.0) + res["seconds"]
    dt = float(p["sample_dt"])
    meta = {"robot": spec.name, "kind": KIND, "path_joints": list(spec.path_joints), "seed": seed,
            "sample_dt": dt, "source": "generated",
            "generator": {"name": str(dataset_cfg.get("name", KIND)), "kind": KIND, "params": p,
                          "num_train": counts["train"], "num_test": counts["test"], "robot_config": robot_cfg},
            "trajectories": {s: trajectory_stats([q for _, q in v], spec, dt) for s, v in splits.items()},
            "generation": {"seconds": round(time.perf_counter() - t0, 2), "workers": workers,
                           **{k: (round(v, 2) if isinstance(v, float) else v) for k, v in gen.items()}}}
    stats = {s: {"stored": dataset_stats([q for _, q in v])} for s, v in splits.items()}
    return save_dataset(dest, splits, meta, overwrite=overwrite, stats=stats)


@dataclass
class _ChunkFn:
    robot_cfg: dict[str, Any]
    params: dict[str, Any]
    seed: int

    def __call__(self, job) -> dict[str, Any]:
        from pathrl.datagen.generators.jobs import SPLIT_IDS

        return generate_chunk(self.robot_cfg, self.params, self.seed, SPLIT_IDS[job.split], job.chunk, job.n)
