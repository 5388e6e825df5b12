"""A path-dependent time law for carrying a tray: fast where the path is easy, slow only where it must be.

For every whole path of a :class:`~pathrl.paths.pathset.PathSet`:

1. **Time-optimal along the path (toppra)** from rest to rest under the joint velocity and acceleration
   limits (scaled by ``limit_margin``) and a box bound ``plate_acc`` (m/s^2) on each world component of the
   plate's acceleration, :class:`PlateAccelerationConstraint`. The plate acceleration is what the tray has
   to tilt into, so bounding it bounds the tilt (``tan(tilt) <= plate_acc / g``).
   Without a plate (``plate=None``) only the joint limits bound it: the time-optimal law that
   :mod:`pathrl.baselines.law_tracker` tracks.
2. **Smoothed** by a moving average of the path velocity over ``smooth_s`` seconds: the tilt then turns at a
   bounded rate (toppra's accelerations are bang-bang: an instant tilt). The average keeps the arc length
   and adds ``smooth_s`` to the duration.
3. **Tabulated** as arc length s (rad, the env's measure) at ``t = k * sample_dt``. The controller looks the
   law up by the env's arc length (:meth:`TimeLawTable.time_at`), so its plan is a function of where the
   robot is on the path, not of the time since the start: a Markov teacher.

Unlike the single minimum-jerk law of :mod:`pathrl.baselines.ball_feedback` (whose duration is set by the
worst point of the path), the path is not slowed everywhere for one sharp turn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import toppra.algorithm as algo
import toppra.constraint as constraint
import torch
from toppra.constraint import LinearConstraint
from torch import Tensor

from pathrl.baselines.toppra import SegmentPath, as_toppra_path, const_accel_eval
from pathrl.paths.pathset import PathSet
from pathrl.paths.spline import arc_length_table, fit_spline

__all__ = ["PlateAccelerationConstraint", "TimeLawCfg", "TimeLawTable", "build_time_laws", "tray_time_law"]


@dataclass(frozen=True)
class TimeLawCfg:
    """Bounds of :func:`tray_time_law` (units: m/s^2, s)."""

    plate_acc: float = 2.0  # m/s^2, box bound on each world component of the plate acceleration
    limit_margin: float = 0.9  # share of the joint velocity / acceleration limits
    smooth_s: float = 0.4  # s, width of the moving average of the path velocity
    grid_step: float = 0.02  # rad of arc length between toppra gridpoints
    sample_dt: float = 0.01  # s, spacing of the tabulated law


class PlateAccelerationConstraint(LinearConstraint):
    """toppra constraint ``|p'(r) r_dd + p''(r) r_d^2|_i <= bound`` on the plate's world acceleration (m/s^2).

    ``plate`` maps joint positions (G, M) to plate positions (G, 3) (m); p' and p'' are central differences
    along the geometric path (step ``h`` in the path parameter).
    """

    def __init__(self, plate, bound: float, h: float = 1e-4):
        super().__init__()
        self.identical = True
        self.plate, self.bound, self.h = plate, float(bound), h
        self._format_string = f"    Kind: plate acceleration, |a_i| <= {bound} m/s^2\n"

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
        """toppra's (a, b, c, F, g, ubound, xbound) of the constraint at `gridpoints` (G,): the plate acceleration a
        r_dd + b r_d^2 (G, 3) within ±bound per axis."""
        r, h = np.asarray(gridpoints, dtype=np.float64), self.h
        p_lo, p_0, p_hi = self.plate(path(r - h)), self.plate(path(r)), self.plate(path(r + h))
        a = (p_hi - p_lo) / (2.0 * h)
        b = (p_hi - 2.0 * p_0 + p_lo) / h**2
        f = np.vstack([np.eye(3), -np.eye(3)])
        return a, b, np.zeros_like(a), f, np.full(6, self.bound), None, None


def tray_time_law(knots: np.ndarray, vel: np.ndarray, acc: np.ndarray, plate, cfg: TimeLawCfg) -> np.ndarray:
    """Arc length (K,) at ``t = k * cfg.sample_dt`` of the module docstring's law for one path (knots (K0, M);
    vel, acc (M,) limits; ``plate`` as in :class:`PlateAccelerationConstraint`, or None: joint limits only). Ends
    exactly at the path's length, at rest."""
    spline = fit_spline(knots)
    u_table, s_table = arc_length_table(spline, knots)
    length = float(s_table[-1])
    path = as_toppra_path(SegmentPath(spline, 0.0, 1.0))
    n = max(int(np.ceil(length / cfg.grid_step)) + 1, 50)
    grid = np.interp(np.linspace(0.0, length, n), s_table, u_table)
    grid[0], grid[-1] = 0.0, 1.0
    cons = [constraint.JointVelocityConstraint(cfg.limit_margin * vel),
            constraint.JointAccelerationConstraint(cfg.limit_margin * acc)]
    if plate is not None:
        cons.append(PlateAccelerationConstraint(plate, cfg.plate_acc))
    inst = algo.TOPPRA(cons, path, gridpoints=grid, solver_wrapper="seidel")
    inst.compute_parameterization(0.0, 0.0)
    sd = inst.problem_data.sd_vec
    if sd is None:
        raise ValueError(f"tray time law: toppra found no parameterization (code {inst.problem_data.return_code})")
    sd = np.maximum(np.asarray(sd, dtype=np.float64), 0.0)
    sd[0] = sd[-1] = 0.0
    ss = np.asarray(inst.problem_data.gridpoints, dtype=np.float64)
    _, _, _, duration = const_accel_eval(ss, sd, np.zeros(1))
    t = np.arange(int(np.ceil(duration / cfg.sample_dt)) + 1) * cfg.sample_dt
    r, _, _, _ = const_accel_eval(ss, sd, np.minimum(t, duration))
    s = np.interp(r, u_table, s_table)
    s[-1] = length
    width = max(int(round(cfg.smooth_s / cfg.sample_dt)), 1)
    v = np.convolve(np.diff(s), np.full(width, 1.0 / width))  # keeps sum(diff) = length
    s = np.r_[0.0, np.cumsum(v)]
    s[-1] = length
    return np.minimum(s, length)


@dataclass(frozen=True)
class TimeLawTable:
    """Tabulated laws of P paths: ``s[p, k]`` arc length at ``t = k * dt`` (padded with the path length)."""

    s: Tensor  # (P, K) rad
    steps: Tensor  # (P,) long, index of the first sample at the path end
    dt: float

    def duration(self, path: Tensor) -> Tensor:
        """Law durations (N,) of paths `path` (N,) (s)."""
        return self.steps[path].to(self.s.dtype) * self.dt

    def arc_at(self, path: Tensor, t: Tensor) -> Tensor:
        """Arc lengths (N, ...) of paths `path` (N,) at times t (N, ...) (clamped to the law), linear between
        samples."""
        shape = t.shape
        view = (-1, *([1] * (t.dim() - 1)))
        x = (t / self.dt).clamp(min=0.0).minimum(self.steps[path].view(view).to(t.dtype))
        i = x.floor().long().clamp(max=self.s.shape[1] - 2)
        w = x - i
        rows = self.s[path].view(len(path), -1)
        flat_i = i.reshape(len(path), -1)
        lo = rows.gather(1, flat_i)
        hi = rows.gather(1, flat_i + 1)
        return (lo + (hi - lo) * w.reshape(len(path), -1)).reshape(shape)

    def time_at(self, path: Tensor, s: Tensor) -> Tensor:
        """Time (N,) at which the laws of paths `path` (N,) reach arc length `s` (N,) (the first sample at or
        past it, interpolated linearly; 0 at the start, the duration at the end)."""
        rows = self.s[path]
        j = torch.searchsorted(rows, s.unsqueeze(1).to(rows.dtype)).squeeze(1)
        j = j.clamp(1, rows.shape[1] - 1).minimum(self.steps[path].clamp(min=1))
        lo, hi = rows.gather(1, (j - 1).unsqueeze(1)).squeeze(1), rows.gather(1, j.unsqueeze(1)).squeeze(1)
        w = ((s - lo) / (hi - lo).clamp(min=1e-12)).clamp(0.0, 1.0)
        return (j.to(s.dtype) - 1.0 + w) * self.dt


def build_time_laws(paths: PathSet, vel: Tensor, acc: Tensor, plate, cfg: TimeLawCfg) -> TimeLawTable:
    """:func:`tray_time_law` of every path of `paths` (limits (M,) of the path joints; `plate` None: joint limits
    only), tabulated."""
    laws = []
    for p in range(paths.num_paths):
        k = int(paths.num_knots[p])
        laws.append(tray_time_law(paths.knots[p, :k].cpu().numpy(), vel.cpu().numpy(), acc.cpu().numpy(),
                                  plate, cfg))
    width = max(len(x) for x in laws) + 1
    s = np.empty((len(laws), width))
    for i, x in enumerate(laws):
        s[i, : len(x)], s[i, len(x):] = x, x[-1]
    steps = torch.as_tensor([len(x) - 1 for x in laws], dtype=torch.long, device=paths.device)
    return TimeLawTable(torch.as_tensor(s, dtype=torch.float64, device=paths.device), steps, cfg.sample_dt)
