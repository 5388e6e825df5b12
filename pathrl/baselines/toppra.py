"""TOPP-RA baseline: time-optimal, rest-to-rest parameterization of the same path segments the policy tracks.

Geometry: the segment [start_s, end_s] (arc length, rad) of the path's natural cubic spline (the same
spline as :func:`pathrl.paths.spline.fit_spline`, so the same geometry as the PathSet). It is mapped to
the chord parameter u through the arc-length table and reparameterized affinely to r in [0, 1]
(toppra's gridpoint heuristics and tolerances are in path-parameter units).

Limit honouring. toppra enforces the limits only at its gridpoints. Its default output
(``ParametrizeSpline``, a cubic spline in t through the gridpoints) overshoots the acceleration limit by
~10-17 % and the velocity limit slightly at the control rate, and leaves the path by ~1e-4 rad. We

1. evaluate the solution with the *constant path acceleration* law of ``ParametrizeConstAccel``
   (vectorized here): q(t) = path(s(t)) exactly, so the trajectory never leaves the path;
2. solve on gridpoints that contain every spline knot inside the segment (q'' of a cubic spline has
   its kinks there; an interval straddling a knot overshoots the acceleration limit by up to
   ~15-40 % in between) plus a uniform arc-length grid of ``grid_step`` rad, with the limits scaled by
   ``1 - margin`` (0.1 %: absorbs the ~1e-4 relative bulge of q'(s)^2 sd^2 between gridpoints);
3. sample the trajectory at the control rate and, while a sample exceeds a velocity / acceleration
   limit, insert the overshooting samples' path parameters as gridpoints and solve again; after
   ``refine_iterations`` solves, also scale the limits down by the observed overshoot (last resort).
   The final samples are checked with :func:`pathrl.limits.check.limit_violations` (position,
   velocity, acceleration); residual violations are reported (status ``violations``).

Measured on the iiwa7 random test set (paper segments, ~9 rad; whole paths, ~23 rad, ~150 knots):
2-4 solves, ~530 / ~1300 gridpoints, zero violations, durations within +-0.4 % (mean -0.05 %) of
toppra's default output, which exceeded the limits at the control rate in every episode (acceleration
by up to 26 %, velocity by up to 0.9 %). Cost: ~2x the default solve time.

Position limits are not a TOPP constraint (toppra only times the path); samples outside them are
counted, which happens only if the path itself leaves them. Jerk is unconstrained (TOPP-RA has no jerk
limits, paper Table V): the constant-acceleration law makes the acceleration jump at gridpoints, so
the control-rate jerk is large; it is reported, never counted as a violation.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import TYPE_CHECKING, Any

import numpy as np

from pathrl.baselines.toppra_path import (
    CHECK_RTOL,
    PathLimits,
    SegmentPath,
    as_toppra_path,
    const_accel_eval,
    limit_counts,
    merge_gridpoints,
    sample_times,
    segment_gridpoints,
    toppra_module,
)
from pathrl.paths.spline import arc_length_table, chord_params, dedupe_knots, fit_spline

if TYPE_CHECKING:
    from pathrl.paths.pathset import PathSet
    from pathrl.paths.segments import Segments
    from pathrl.robot.model import RobotSpec

__all__ = ["GRID_STEP", "MARGIN", "MAX_ITERATIONS", "REFINE_ITERATIONS", "RESCALE_MARGIN", "VIOLATION_KEYS",
           "PathLimits", "ToppraResult", "ToppraSettings", "ToppraStatus", "path_limits", "solve_plan",
           "solve_segment"]


#: Default spacing (rad of arc length) of the uniform part of the gridpoints.
GRID_STEP = 0.02
#: Relative safety margin on the velocity / acceleration limits given to toppra.
MARGIN = 1e-3
#: Every re-solve inserts the overshooting samples as gridpoints; after this many solves it also
#: scales the limits down by the overshoot.
REFINE_ITERATIONS = 6
#: Extra margin applied when scaling limits down after an overshoot.
RESCALE_MARGIN = 1e-3
MAX_ITERATIONS = 12


@dataclass(frozen=True)
class ToppraSettings:
    """How :func:`solve_segment` solves (module doc): samples and checks at `control_rate` (Hz); gridpoints at the
    spline knots and every `grid_step` rad of arc length; at most `max_iterations` solves, the limits scaled by
    1 - `margin` (after `refine_iterations` solves also by the observed overshoot). `keep_trajectory` False drops
    the samples (q, qd, qdd become (0, M)) to save memory."""

    control_rate: float = 240.0
    grid_step: float = GRID_STEP
    max_iterations: int = MAX_ITERATIONS
    refine_iterations: int = REFINE_ITERATIONS
    margin: float = MARGIN
    keep_trajectory: bool = True


VIOLATION_KEYS = ("position", "velocity", "acceleration")


class ToppraStatus(StrEnum):
    """Result code of one solved segment (:attr:`ToppraResult.status`); a ``str``, so reports keep the plain names
    (``"status": "ok"``) and comparisons with the names still hold."""

    OK = "ok"  # solved, no limit violation at the control rate
    VIOLATIONS = "violations"  # solved, residual violations after the last solve
    INFEASIBLE = "infeasible"  # toppra found no parameterisation
    EMPTY = "empty"  # zero-length segment

    @property
    def solved(self) -> bool:
        """A trajectory exists (ok or violations)."""
        return self in (ToppraStatus.OK, ToppraStatus.VIOLATIONS)


@dataclass
class ToppraResult:
    """One solved segment.

    duration_s: trajectory duration from rest to rest (nan unless solved).
    solve_time_s: wall time of the whole solve (gridpoints, every toppra solve, sampling, checks).
    max_joint_dev_rad: max Euclidean joint-space distance between the control-rate samples and the
        geometric path at the same path parameter (0 up to float error: the trajectory is q(s(t))).
    q, qd, qdd: (T, M) samples at t = k / control_rate, the last one at t = duration (rest).
    status: :class:`ToppraStatus`: ``ok`` (no violation), ``violations`` (residual violations after the last
        solve), ``infeasible`` (toppra failed) or ``empty`` (zero-length segment).
    vel_scale, acc_scale: factors applied to the velocity / acceleration limits of the final solve.
    violations: control-rate samples x joints beyond each limit (position, velocity, acceleration).
    max_vel_ratio, max_acc_ratio: max |qd| / vel_limit and |qdd| / acc_limit over the samples.
    max_jerk: max |d qdd / dt| (finite differences at the control rate, rad/s^3); max_jerk_ratio the
        same relative to the jerk limits (nan without jerk limits). Not a violation.
    """

    duration_s: float
    solve_time_s: float
    max_joint_dev_rad: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    status: ToppraStatus
    vel_scale: float = 1.0
    acc_scale: float = 1.0
    violations: dict[str, int] = field(default_factory=dict)
    max_vel_ratio: float = math.nan
    max_acc_ratio: float = math.nan
    max_jerk: float = math.nan
    max_jerk_ratio: float = math.nan
    jerk_violations: int = 0
    num_gridpoints: int = 0
    iterations: int = 0
    tracked: dict[str, Any] | None = None  # the plan tracked by Ruckig (solve_plan(track=True))

    @property
    def limit_scale(self) -> float:
        """The smaller of the velocity and acceleration limit scales of the final solve."""
        return min(self.vel_scale, self.acc_scale)

    @property
    def num_violations(self) -> int:
        """Position + velocity + acceleration violations (jerk excluded)."""
        return int(sum(self.violations.get(k, 0) for k in VIOLATION_KEYS))

    @property
    def ok(self) -> bool:
        """No limit violation (status ok)."""
        return self.status == ToppraStatus.OK

    def summary(self) -> dict[str, float | int | str]:
        """JSON-friendly scalars (no samples)."""
        return {
            "status": self.status.value,
            "duration_s": self.duration_s,
            "solve_time_s": self.solve_time_s,
            "max_joint_dev_rad": self.max_joint_dev_rad,
            "vel_scale": self.vel_scale,
            "acc_scale": self.acc_scale,
            "violations": self.num_violations,
            "violations_by_kind": dict(self.violations),
            "max_vel_ratio": self.max_vel_ratio,
            "max_acc_ratio": self.max_acc_ratio,
            "max_jerk": self.max_jerk,
            "max_jerk_ratio": self.max_jerk_ratio,
            "num_gridpoints": self.num_gridpoints,
            "iterations": self.iterations,
        }


def _warm_imports() -> None:
    import pathrl.limits.check  # noqa: F401


@dataclass
class _Refined:
    """Outcome of :func:`_solve_refined`: the limit scales, gridpoints and solves used; if feasible, the samples
    at times t (T,): path parameter r (T,), joint velocities qd and accelerations qdd (T, M), and the duration."""

    feasible: bool
    vel_scale: float
    acc_scale: float
    grid: np.ndarray
    iterations: int
    t: np.ndarray | None = None
    r: np.ndarray | None = None
    qd: np.ndarray | None = None
    qdd: np.ndarray | None = None
    duration: float = math.nan


def _solve_refined(seg: SegmentPath, grid: np.ndarray, limits: PathLimits, start_rate: float,
                   settings: ToppraSettings) -> _Refined:
    """Solve with toppra from path velocity `start_rate` (rad of arc length / s) on gridpoints `grid` and re-solve
    while a control-rate sample exceeds a velocity / acceleration limit (steps 2-3 of the module doc)."""
    import toppra.algorithm as algo
    import toppra.constraint as constraint
    from toppra.algorithm.algorithm import ParameterizationReturnCode

    path = as_toppra_path(seg)
    vel, acc, control_rate = limits.vel, limits.acc, settings.control_rate
    max_iterations = settings.max_iterations
    vel_scale = acc_scale = 1.0 - settings.margin
    tol = 1.0 + CHECK_RTOL
    for it in range(1, max_iterations + 1):
        cons = [
            constraint.JointVelocityConstraint(vel * vel_scale),
            constraint.JointAccelerationConstraint(acc * acc_scale),
        ]
        inst = algo.TOPPRA(cons, path, gridpoints=grid, solver_wrapper="seidel")
        sd_start = start_rate / max(float(np.linalg.norm(seg(0.0, 1))), 1e-12)  # arc length / s -> r / s
        inst.compute_parameterization(sd_start, 0.0)
        data = inst.problem_data
        if data.return_code != ParameterizationReturnCode.Ok or data.sd_vec is None:
            return _Refined(False, vel_scale, acc_scale, grid, it)
        ss, sdv = np.asarray(data.gridpoints), np.asarray(data.sd_vec)
        sdv = np.maximum(sdv, 0.0)
        sdv[0], sdv[-1] = sd_start, 0.0
        _, _, _, duration = const_accel_eval(ss, sdv, np.zeros(1))
        t = sample_times(duration, control_rate)
        r, rd, rdd, _ = const_accel_eval(ss, sdv, t)
        d1 = seg(r, 1)
        qd = d1 * rd[:, None]
        qdd = seg(r, 2) * (rd**2)[:, None] + d1 * rdd[:, None]
        qd[-1] = 0.0  # at rest at t = duration (float residue of the last interval)
        over_v = np.any(np.abs(qd) > vel * tol, axis=1)
        over_a = np.any(np.abs(qdd) > acc * tol, axis=1)
        if not (over_v.any() or over_a.any()) or it == max_iterations:
            break
        # constrain the trajectory where it overshot: the violating samples become gridpoints
        grid = merge_gridpoints(grid, r[over_v | over_a])
        if it > settings.refine_iterations:  # last resort: also scale the limits down by the observed overshoot
            vr, ar = float(np.max(np.abs(qd) / vel)), float(np.max(np.abs(qdd) / acc))
            if vr > 1.0:
                vel_scale *= (1.0 - RESCALE_MARGIN) / vr
            if ar > 1.0:
                acc_scale *= (1.0 - RESCALE_MARGIN) / ar
    return _Refined(True, vel_scale, acc_scale, grid, it, t, r, qd, qdd, duration)


def _sample_checks(seg: SegmentPath, sol: _Refined, q: np.ndarray, limits: PathLimits,
                   control_rate: float) -> dict[str, Any]:
    """Path deviation, limit violations and limit ratios of the control-rate samples q (T, M) of `sol`."""
    t, r, qd, qdd = sol.t, sol.r, sol.qd, sol.qdd
    vel, acc, jerk = limits.vel, limits.acc, limits.jerk
    dev = float(np.linalg.norm(q - seg(r), axis=1).max())
    viol = limit_counts(q, qd, qdd, limits, control_rate)
    jerk_abs = np.abs(np.diff(qdd, axis=0)) * control_rate if len(t) > 1 else np.zeros((1, q.shape[1]))
    return {
        "max_joint_dev_rad": dev,
        "violations": {k: viol.get(k, 0) for k in VIOLATION_KEYS},
        "max_vel_ratio": float(np.max(np.abs(qd) / vel)),
        "max_acc_ratio": float(np.max(np.abs(qdd) / acc)),
        "max_jerk": float(jerk_abs.max()),
        "max_jerk_ratio": float((jerk_abs / jerk).max()) if jerk is not None else math.nan,
        "jerk_violations": int(viol.get("jerk", 0)),
    }


def solve_segment(knots: np.ndarray, start_s: float, end_s: float, limits: PathLimits,
                  settings: ToppraSettings = ToppraSettings(), start_rate: float = 0.0) -> ToppraResult:
    """Time-optimal trajectory along the path segment [start_s, end_s] (arc length, rad) to rest (see module doc).

    knots: (K, M) path knots (path joints only); `limits` of those M joints; `settings`: how it is solved and
    sampled. start_rate: path velocity at the start (rad of arc length per s; 0: from rest). toppra reports the
    segment infeasible if the limits cannot be kept from that velocity.
    """
    toppra_module()
    _warm_imports()  # one-time import cost (torch, limits check) stays out of solve_time_s
    t_begin = time.perf_counter()
    knots = dedupe_knots(knots)
    m = knots.shape[1]
    limits = limits.as_float64(m)
    keep_trajectory = settings.keep_trajectory
    spline = fit_spline(knots)
    u_table, s_table = arc_length_table(spline, knots)
    length = float(s_table[-1])
    start_s, end_s = float(np.clip(start_s, 0.0, length)), float(np.clip(end_s, 0.0, length))
    empty = np.zeros((0, m))

    def result(status: ToppraStatus, **kw) -> ToppraResult:
        kw.setdefault("duration_s", math.nan)
        kw.setdefault("max_joint_dev_rad", math.nan)
        return ToppraResult(
            solve_time_s=time.perf_counter() - t_begin,
            q=kw.pop("q", empty),
            qd=kw.pop("qd", empty),
            qdd=kw.pop("qdd", empty),
            status=status,
            **kw,
        )

    if end_s - start_s < 1e-9:
        return result(ToppraStatus.EMPTY, duration_s=0.0, max_joint_dev_rad=0.0)
    u0, u1 = np.interp([start_s, end_s], s_table, u_table)
    seg = SegmentPath(spline, u0, u1)
    grid = segment_gridpoints(u_table, s_table, chord_params(knots), start_s, end_s, u0, u1, settings.grid_step)
    sol = _solve_refined(seg, grid, limits, start_rate, settings)
    vel_scale, acc_scale, grid, it = sol.vel_scale, sol.acc_scale, sol.grid, sol.iterations
    if not sol.feasible:
        return result(ToppraStatus.INFEASIBLE, vel_scale=vel_scale, acc_scale=acc_scale, num_gridpoints=len(grid),
                      iterations=it)
    q = seg(sol.r)
    res = result(
        ToppraStatus.OK,
        duration_s=sol.duration,
        q=q if keep_trajectory else empty,
        qd=sol.qd if keep_trajectory else empty,
        qdd=sol.qdd if keep_trajectory else empty,
        vel_scale=vel_scale,
        acc_scale=acc_scale,
        **_sample_checks(seg, sol, q, limits, settings.control_rate),
        num_gridpoints=len(grid),
        iterations=it,
    )
    if res.num_violations:
        res.status = ToppraStatus.VIOLATIONS
    res.solve_time_s = time.perf_counter() - t_begin
    return res


# ----------------------------------------------------------------------------------------------- plan


@dataclass(frozen=True)
class _Task:
    index: int
    knots: np.ndarray
    start_s: float
    end_s: float


def _solve_chunk(tasks: Sequence[_Task], limits: PathLimits, settings: ToppraSettings,
                 track: bool = False) -> list[tuple[int, ToppraResult]]:
    """(index, result) of each task; `track`: also track each plan with Ruckig (the samples are kept for it and
    dropped after unless ``settings.keep_trajectory``)."""
    keep = settings.keep_trajectory
    solving = replace(settings, keep_trajectory=keep or track)
    out = []
    for task in tasks:
        res = solve_segment(task.knots, task.start_s, task.end_s, limits, solving)
        if track and res.status.solved and len(res.q):
            from pathrl.baselines.ruckig_track import ruckig_tracked

            res.tracked = ruckig_tracked(res, limits, settings.control_rate)
        if track and not keep:
            res.q = res.qd = res.qdd = np.zeros((0, res.q.shape[1]))
        out.append((task.index, res))
    return out


def _worker_init() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass


def path_limits(robot: RobotSpec) -> PathLimits:
    """Limits of the robot's path joints: vel, acc, jerk (M,), pos (M, 2)."""
    idx = np.asarray(robot.path_index)
    return PathLimits(vel=np.asarray(robot.vel_limits)[idx], acc=np.asarray(robot.acc_limits)[idx],
                      pos=np.asarray(robot.pos_limits)[idx], jerk=np.asarray(robot.jerk_limits)[idx])


def solve_plan(paths: PathSet, plan: Segments, robot: RobotSpec, settings: ToppraSettings = ToppraSettings(), *,
               workers: int = 1, progress: bool = True, chunk_size: int = 4, track: bool = False) -> list[ToppraResult]:
    """Solve every episode of `plan` under the robot's path-joint limits as `settings` says (in plan order,
    independent of `workers` processes and of `chunk_size` episodes per task); `track`: also track each plan with
    Ruckig (``ToppraResult.tracked``)."""
    if paths.dof != robot.path_dof:
        raise ValueError(
            f"paths have {paths.dof} joints, robot {robot.name!r} has {robot.path_dof} path joints"
        )
    limits = path_limits(robot)
    knots = paths.knots.detach().cpu().numpy()
    nk = paths.num_knots.cpu().numpy()
    idx = plan.path.cpu().numpy()
    s0 = plan.start_s.detach().cpu().double().numpy()
    s1 = plan.end_s.detach().cpu().double().numpy()
    tasks = [
        _Task(i, knots[p, : nk[p]], float(a), float(b))
        for i, (p, a, b) in enumerate(zip(idx, s0, s1, strict=True))
    ]
    chunks = [tasks[i : i + chunk_size] for i in range(0, len(tasks), chunk_size)]
    results: list[ToppraResult | None] = [None] * len(tasks)

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    bar = Progress(
        TextColumn("TOPP-RA"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        disable=not progress,
    )
    with bar:
        job = bar.add_task("solve", total=len(tasks))
        if workers <= 1 or len(chunks) <= 1:
            for chunk in chunks:
                for i, res in _solve_chunk(chunk, limits, settings, track):
                    results[i] = res
                bar.advance(job, len(chunk))
        else:
            import multiprocessing as mp

            ctx = mp.get_context("spawn")
            with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init) as pool:
                futures = [pool.submit(_solve_chunk, chunk, limits, settings, track) for chunk in chunks]
                from concurrent.futures import as_completed

                for fut in as_completed(futures):
                    done = fut.result()
                    for i, res in done:
                        results[i] = res
                    bar.advance(job, len(done))
    return [r for r in results if r is not None]
