"""Iterative waypoint adjustment (IWA) with the Multi-Peak Gradient Descent baseline (MPGD, paper Sec. III-B).

One iteration executes the program on the controller, finds the peaks of the position error along the
executed path and, for each peak, adjusts the waypoints next to it:

* the peak's executed point p_exe, its nearest target point p_trk and error e = p_trk - p_exe;
* a local model M: the cubic spline (``scipy.interpolate.CubicSpline``) through the ``2 * window + 1``
  waypoints around the peak, parameterised by their target indices and evaluated at the peak's target index.
  Moving the waypoints by dP moves the predicted execution by M(P + dP) - M(P) (the controller's own offset
  p_exe - M(P) is taken as fixed);
* the gradient of |e| with respect to each coordinate of the ``2 * adjust + 1`` waypoints nearest the peak,
  by forward differences of size ``delta`` mm through M (paper eq. 6);
* a gradient step sized to remove the share ``gain`` of the peak error under the model,
  dP = -gain |e| g / |g|^2 (peaks sharing a waypoint add their steps).

Only positions move; orientations stay as initialised (as in the paper's RL actions). The loop stops when the
maximum error meets the spec (0.5 mm) or after ``k_max`` iterations (paper: 50), or when an adjusted program
cannot be executed (out of reach), and returns the best program.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import find_peaks

from pathrl.industrial.controller import ControllerParams, Execution, execute
from pathrl.industrial.metrics import POS_SPEC_MM, Errors, evaluate, position_errors
from pathrl.industrial.program import Program
from pathrl.industrial.trajectories import Target, waypoint_indices

__all__ = ["IWAResult", "MPGDParams", "error_peaks", "iterate_waypoints", "mpgd_update", "peak_step", "run_mpgd"]


@dataclass(frozen=True)
class MPGDParams:
    """MPGD settings: iterations, model window and adjusted neighbours (waypoints each side), finite difference
    (mm), step gain, peak threshold (mm), peaks per iteration."""

    k_max: int = 50
    window: int = 3
    adjust: int = 1
    delta: float = 0.01
    gain: float = 0.5
    peak_threshold: float = 0.8 * POS_SPEC_MM
    max_peaks: int = 30

    def __post_init__(self) -> None:
        if self.k_max < 1 or self.window < 1 or not 0 <= self.adjust <= self.window:
            raise ValueError("mpgd: need k_max >= 1, window >= 1, 0 <= adjust <= window")
        if not (self.delta > 0 and self.gain > 0 and self.peak_threshold > 0 and self.max_peaks >= 1):
            raise ValueError("mpgd: delta, gain, peak_threshold must be > 0 and max_peaks >= 1")


@dataclass
class IWAResult:
    """Outcome of an iterative waypoint adjustment: the best program and its errors, the max position error of
    every execution (index 0 = the initial profile), the iteration that first met the 0.5 mm spec (None if
    never), the number of executions and the wall time (s)."""

    program: Program
    errors: Errors
    history: list[float] = field(default_factory=list)
    iterations_to_spec: int | None = None
    executions: int = 0
    t_opt: float = 0.0


def error_peaks(d: np.ndarray, threshold: float, max_peaks: int) -> np.ndarray:
    """Sample indices of the error peaks (local maxima of d (N,) above `threshold`), highest first."""
    peaks, props = find_peaks(np.r_[0.0, d, 0.0], height=threshold)
    order = np.argsort(-props["peak_heights"])[:max_peaks]
    return peaks[order] - 1


def peak_step(positions: np.ndarray, psi: np.ndarray, u_peak: float, p_exe: np.ndarray, p_trk: np.ndarray,
              params: MPGDParams) -> tuple[np.ndarray, np.ndarray]:
    """The waypoint indices and their position steps (k, 3) mm of one error peak (module doc)."""
    m = len(positions)
    near = int(np.argmin(np.abs(psi - u_peak)))
    lo, hi = max(near - params.window, 0), min(near + params.window, m - 1)
    idx = np.arange(lo, hi + 1)
    knots = psi[idx].astype(float)

    def model(pts: np.ndarray) -> np.ndarray:
        return CubicSpline(knots, pts)(u_peak) if len(idx) >= 2 else pts[0]

    base = model(positions[idx])
    err = np.linalg.norm(p_trk - p_exe)
    adj = np.arange(max(near - params.adjust, lo), min(near + params.adjust, hi) + 1)
    grad = np.zeros((len(adj), 3))
    for a, w in enumerate(adj):
        for c in range(3):
            moved = positions[idx].copy()
            moved[w - lo, c] += params.delta
            pred = p_exe + model(moved) - base
            grad[a, c] = (np.linalg.norm(p_trk - pred) - err) / params.delta
    norm2 = float(np.sum(grad**2))
    if norm2 < 1e-12:
        return adj, np.zeros_like(grad)
    return adj, -params.gain * err * grad / norm2


def mpgd_update(program: Program, ex: Execution, target: Target, psi: np.ndarray, params: MPGDParams) -> Program:
    """One MPGD adjustment of `program` from its execution `ex` (module doc)."""
    d, u = position_errors(ex.p, target.p)
    steps = np.zeros_like(program.positions)
    for j in error_peaks(d, params.peak_threshold, params.max_peaks):
        i0 = int(np.clip(np.floor(u[j]), 0, len(target.p) - 2))
        f = u[j] - i0
        p_trk = (1 - f) * target.p[i0] + f * target.p[i0 + 1]
        adj, step = peak_step(program.positions, psi, float(u[j]), ex.p[j], p_trk, params)
        steps[adj] += step
    return program.with_positions(program.positions + steps)


def iterate_waypoints(target: Target, program: Program, v: float, controller: ControllerParams, seed: int,
                      k_max: int, update: Callable[[int, Program, Execution], Program],
                      on_execution: Callable[[int, Program, Execution], None] | None = None) -> IWAResult:
    """The iterative waypoint adjustment loop shared by MPGD and ILC: execute `program` at speed command `v` mm/s
    (execution k with seed + k), keep the best, stop at the 0.5 mm spec or after `k_max` adjustments, else
    ``program = update(k, program, execution)``. An adjusted program out of the arm's reach or axis ranges ends the
    loop with the best so far (the first program's is an error). `on_execution(k, program, execution)` sees every
    execution (a recorder; it runs inside the timed loop)."""
    t0 = time.perf_counter()
    best: IWAResult | None = None
    history: list[float] = []
    for k in range(k_max + 1):
        try:
            ex = execute(program, v, controller, seed=seed + k)
        except ValueError:
            if best is None:
                raise
            break
        if on_execution is not None:
            on_execution(k, program, ex)
        errs = evaluate(ex.p, ex.rot, 1.0 / controller.rate, target.p, target.z_axis)
        history.append(errs.max_pos_mm)
        if best is None or errs.max_pos_mm < best.errors.max_pos_mm:
            best = IWAResult(program, errs)
        if errs.max_pos_mm <= POS_SPEC_MM:
            best.iterations_to_spec = k
            break
        if k < k_max:
            program = update(k, program, ex)
    assert best is not None
    best.history, best.executions, best.t_opt = history, len(history), time.perf_counter() - t0
    return best


def run_mpgd(target: Target, program: Program, v: float, params: MPGDParams | None = None,
             controller: ControllerParams | None = None, seed: int = 0,
             on_execution: Callable[[int, Program, Execution], None] | None = None) -> IWAResult:
    """IWA with MPGD from `program` at speed command `v` mm/s (:func:`iterate_waypoints`; k_max + 1 executions at
    most)."""
    params = MPGDParams() if params is None else params
    controller = ControllerParams() if controller is None else controller
    psi = waypoint_indices(len(target.p), len(program.positions))
    return iterate_waypoints(target, program, v, controller, seed, params.k_max,
                             lambda _k, prog, ex: mpgd_update(prog, ex, target, psi, params), on_execution)
