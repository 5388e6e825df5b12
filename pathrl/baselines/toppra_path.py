"""TOPP-RA building blocks of :func:`pathrl.baselines.toppra.solve_segment`: the segment as a toppra geometric
path, its gridpoints, the constant-path-acceleration evaluation of a solution and the control-rate limit count."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import BSpline

__all__ = ["CHECK_RTOL", "MIN_GRIDPOINTS", "PathLimits", "SegmentPath", "as_toppra_path", "const_accel_eval",
           "limit_counts", "merge_gridpoints", "sample_times", "segment_gridpoints", "toppra_module"]


#: Minimum number of gridpoints of a segment (short segments).
MIN_GRIDPOINTS = 100
#: Relative tolerance of the control-rate limit check (float noise only).
CHECK_RTOL = 1e-9


@dataclass(frozen=True)
class PathLimits:
    """Limits of the M path joints: velocity and acceleration magnitudes (M,) (rad/s, rad/s^2), position limits
    (M, 2) (rad) and jerk magnitudes (M,) (rad/s^3); None: unbounded. TOPP-RA keeps velocity and acceleration;
    position and jerk are checked on the samples (and bound Ruckig's tracking)."""

    vel: np.ndarray
    acc: np.ndarray
    pos: np.ndarray | None = None
    jerk: np.ndarray | None = None

    def as_float64(self, m: int) -> PathLimits:
        """The limits as float64 arrays of `m` joints: (m,), pos (m, 2)."""
        return PathLimits(_float64(self.vel, (m,)), _float64(self.acc, (m,)), _float64(self.pos, (m, 2)),
                          _float64(self.jerk, (m,)))


def _float64(a: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray | None:
    """`a` as a float64 array of `shape` (None stays None)."""
    return None if a is None else np.asarray(a, dtype=np.float64).reshape(shape)


def toppra_module():
    """toppra, its logging at WARNING."""
    import toppra as ta

    ta.setup_logging("WARNING")
    return ta


class SegmentPath:
    """q(r) = spline(u0 + r (u1 - u0)), r in [0, 1], with derivatives in r (a toppra geometric path)."""

    def __init__(self, spline: BSpline, u0: float, u1: float) -> None:
        self._d = [spline]
        for nu in (1, 2):
            self._d.append(spline.derivative(nu) if spline.k >= nu else None)
        self._m = spline.c.shape[1]
        self.u0, self.du = float(u0), float(u1 - u0)

    def __call__(self, r, order: int = 0) -> np.ndarray:
        r = np.asarray(r, dtype=np.float64)
        d = self._d[order]
        if d is None:
            return np.zeros((*r.shape, self._m))
        return d(self.u0 + self.du * r) * self.du**order

    @property
    def dof(self) -> int:
        """Number of joints M."""
        return self._m

    @property
    def path_interval(self) -> np.ndarray:
        """The path parameter's range [0, 1]."""
        return np.array([0.0, 1.0])

    @property
    def waypoints(self):
        """None: the path has no waypoints toppra could use."""
        return None


def as_toppra_path(seg: SegmentPath):
    """`seg` as a toppra ``AbstractGeometricPath``."""
    ta = toppra_module()

    class _Path(ta.interpolator.AbstractGeometricPath):
        def __call__(self, r, order=0):
            return seg(r, order)

        @property
        def dof(self):
            return seg.dof

        @property
        def path_interval(self):
            return seg.path_interval

        @property
        def waypoints(self):
            return None

    return _Path()


def segment_gridpoints(
    u_table: np.ndarray,
    s_table: np.ndarray,
    u_knots: np.ndarray,
    start_s: float,
    end_s: float,
    u0: float,
    u1: float,
    grid_step: float,
) -> np.ndarray:
    """Gridpoints in r: a uniform arc-length grid plus every spline knot strictly inside the segment."""
    n = max(int(math.ceil((end_s - start_s) / grid_step)) + 1, MIN_GRIDPOINTS)
    u_grid = np.interp(np.linspace(start_s, end_s, n), s_table, u_table)
    inner = u_knots[(u_knots > u0) & (u_knots < u1)]
    r = (np.r_[u_grid, inner] - u0) / (u1 - u0)
    r = np.unique(np.clip(r, 0.0, 1.0))
    # drop points closer than 1e-9 (float duplicates) and pin the ends
    keep = np.r_[True, np.diff(r) > 1e-9]
    r = r[keep]
    r[0], r[-1] = 0.0, 1.0
    if len(r) >= 2 and r[-1] - r[-2] <= 1e-9:
        r = np.r_[r[:-2], 1.0]
    return r


def const_accel_eval(
    ss: np.ndarray, sd: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Path parameter, its rate and acceleration at times t under constant sdd between gridpoints.

    Same law as toppra's ``ParametrizeConstAccel`` (vectorized). Returns (s, sd, sdd, duration).
    """
    x = sd**2
    ds = np.diff(ss)
    u = 0.5 * np.diff(x) / ds
    dt = 2.0 * ds / np.maximum(sd[:-1] + sd[1:], 1e-300)
    ts = np.r_[0.0, np.cumsum(dt)]
    i = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ss) - 2)
    tau = t - ts[i]
    s = np.clip(ss[i] + sd[i] * tau + 0.5 * u[i] * tau**2, ss[0], ss[-1])
    v = np.maximum(sd[i] + u[i] * tau, 0.0)
    return s, v, u[i], float(ts[-1])


def sample_times(duration: float, control_rate: float) -> np.ndarray:
    """Sample times 0, 1/rate, ..., up to and including `duration` (s)."""
    n = int(math.ceil(duration * control_rate - 1e-9))
    return np.minimum(np.arange(n + 1) / control_rate, duration)


def limit_counts(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, limits: PathLimits,
                 control_rate: float) -> dict[str, int]:
    """Counts of control-rate samples x joints (q, qd, qdd: (T, M)) beyond `limits` (pathrl.limits.check)."""
    import torch

    from pathrl.limits.check import limit_violations
    from pathrl.limits.feasible import JointLimits

    m = q.shape[1]
    pos_lim = limits.pos if limits.pos is not None else np.tile([-np.inf, np.inf], (m, 1))
    jerk_lim = limits.jerk if limits.jerk is not None else np.full(m, np.inf)
    joint_limits = JointLimits.from_arrays(pos_lim, limits.vel, limits.acc, jerk_lim)
    t = lambda a: torch.as_tensor(a, dtype=torch.float64)  # noqa: E731
    out = limit_violations(t(q), t(qd), t(qdd), joint_limits, 1.0 / control_rate, CHECK_RTOL)
    return {k: int(v.sum()) for k, v in out.items() if k != "total"}


def merge_gridpoints(grid: np.ndarray, new: np.ndarray, min_gap: float = 1e-7) -> np.ndarray:
    """Insert `new` parameters into the sorted `grid`, skipping those closer than min_gap to a point."""
    new = np.unique(new[(new > min_gap) & (new < 1.0 - min_gap)])
    if not len(new):
        return grid
    j = np.clip(np.searchsorted(grid, new), 1, len(grid) - 1)
    gap = np.minimum(new - grid[j - 1], grid[j] - new)
    new = new[gap > min_gap]
    if len(new) > 1:
        new = new[np.r_[True, np.diff(new) > min_gap]]
    return np.sort(np.r_[grid, new])
