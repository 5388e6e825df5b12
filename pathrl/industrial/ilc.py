"""Iterative learning control (ILC) of the waypoints: the classical baseline beside MPGD and the learned policy.

Trial k executes the program, matches the executed path to the target (nearest executed point of every target
point, :func:`pathrl.industrial.features.match`) and reads the error vector e_k(i) at each waypoint's target
point (m, 3) mm. The update moves every waypoint (positions only; the first and last stay):

* **P-type** (``kind="p"``): P_{k+1} = P_k + gain e_k. This is the fixed policy a = (gain, 0, 0) of the
  paper's action frame.
* **Filtered, model-inverted** (``kind="filtered"``): the error is smoothed along the waypoints by a zero-phase
  Gaussian Q-filter of ``q_sigma`` waypoints, and divided by the local gain of the plant as measured between
  the two last trials (the secant g_i = -<e_k - e_{k-1}, P_k - P_{k-1}> / |P_k - P_{k-1}|^2, Q-filtered and
  clipped to [``g_min``, 1.5]; 1 before the second trial): P_{k+1} = P_k + gain Q(e_k) / g.

The loop stops at the 0.5 mm spec or after ``k_max`` updates and returns the best program, like
:func:`pathrl.industrial.mpgd.run_mpgd`. :func:`tune_gain` picks the gain on training-family curves only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from pathrl.industrial.controller import ControllerParams, Execution
from pathrl.industrial.features import match
from pathrl.industrial.mpgd import IWAResult, iterate_waypoints
from pathrl.industrial.program import Program
from pathrl.industrial.trajectories import Target, baseline_program, waypoint_indices

__all__ = ["ILCColumns", "ILCParams", "ilc_update", "plant_gain", "run_ilc", "tune_gain"]


@dataclass(frozen=True)
class ILCParams:
    """ILC settings: ``kind`` "p" or "filtered", learning gain, Q-filter width (waypoints), smallest plant gain
    the inverse divides by, updates."""

    kind: str = "p"
    gain: float = 1.0
    q_sigma: float = 1.0
    g_min: float = 0.3
    k_max: int = 10

    def __post_init__(self) -> None:
        if self.kind not in ("p", "filtered"):
            raise ValueError(f"ilc.kind must be 'p' or 'filtered', got {self.kind!r}")
        if not (self.gain > 0 and self.q_sigma >= 0 and 0 < self.g_min <= 1 and self.k_max >= 1):
            raise ValueError("ilc: need gain > 0, q_sigma >= 0, 0 < g_min <= 1, k_max >= 1")


@dataclass(frozen=True)
class ILCColumns:
    """The ILC columns of ``pathrl-industrial table2``: ``columns`` "auto" (with ``controller.model=abb`` only, so
    the shipped ``lag`` tables stay as they are), "always" or "never"; the P-type and filtered gains (as tuned on
    training curves in ``results/industrial_abb_ilc.md``: 1 and 1) and the updates per row."""

    columns: str = "auto"
    gain_p: float = 1.0
    gain_filtered: float = 1.0
    k_max: int = 10

    def __post_init__(self) -> None:
        if self.columns not in ("auto", "always", "never"):
            raise ValueError(f"ilc.columns must be auto, always or never, got {self.columns!r}")
        if not (self.gain_p > 0 and self.gain_filtered > 0 and self.k_max >= 1):
            raise ValueError("ilc: need gain_p > 0, gain_filtered > 0, k_max >= 1")

    def variants(self, model: str) -> dict[str, ILCParams]:
        """Column name -> ILC settings for a controller `model` ("lag" or "abb"); empty when the columns are off."""
        if self.columns == "never" or (self.columns == "auto" and model != "abb"):
            return {}
        return {"ILC P": ILCParams("p", self.gain_p, k_max=self.k_max),
                "ILC filtered": ILCParams("filtered", self.gain_filtered, k_max=self.k_max)}


def _q_filter(x: np.ndarray, sigma: float) -> np.ndarray:
    """Zero-phase Gaussian smoothing (m, ...) along the waypoints (sigma in waypoints; 0 = none)."""
    return gaussian_filter1d(x, sigma, axis=0, mode="nearest") if sigma > 0 else x


def plant_gain(dp: np.ndarray, de: np.ndarray, sigma: float, g_min: float) -> np.ndarray:
    """Per-waypoint plant gain (m,) from waypoint moves dp (m, 3) mm and the error change de (m, 3) they caused:
    the secant -<de, dp> / |dp|^2, Q-filtered, clipped to [g_min, 1.5]; 1 where nothing moved."""
    norm2 = np.einsum("ij,ij->i", dp, dp)
    moved = norm2 > 1e-12
    g = np.where(moved, -np.einsum("ij,ij->i", de, dp) / np.maximum(norm2, 1e-12), 1.0)
    return np.clip(_q_filter(g, sigma), g_min, 1.5)


def ilc_update(positions: np.ndarray, e: np.ndarray, params: ILCParams, g: np.ndarray | None = None) -> np.ndarray:
    """Next waypoint positions (m, 3) mm from the current ones and the waypoint errors e (m, 3) mm (module doc);
    `g` (m,) is the filtered variant's plant gain (None = 1). The first and last waypoints stay."""
    step = params.gain * e if params.kind == "p" else params.gain * _q_filter(e, params.q_sigma)
    if params.kind == "filtered" and g is not None:
        step = step / g[:, None]
    step[0] = step[-1] = 0.0
    return positions + step


def run_ilc(target: Target, program: Program, v: float, params: ILCParams | None = None,
            controller: ControllerParams | None = None, seed: int = 0) -> IWAResult:
    """ILC from `program` at speed command `v` mm/s; execution k uses seed + k (module doc; the loop is
    :func:`~pathrl.industrial.mpgd.iterate_waypoints`)."""
    params = ILCParams() if params is None else params
    controller = ControllerParams() if controller is None else controller
    psi = waypoint_indices(len(target.p), len(program.positions))
    prev: list[tuple[np.ndarray, np.ndarray]] = []  # the last (waypoints, errors), for the filtered plant gain

    def update(_k: int, prog: Program, ex: Execution) -> Program:
        e = match(target.p, target.z_axis, ex.p, ex.rot[:, :, 2]).err[psi]
        g = None
        if params.kind == "filtered" and prev:
            g = plant_gain(prog.positions - prev[-1][0], e - prev[-1][1], params.q_sigma, params.g_min)
        prev[:] = [(prog.positions, e)]
        return prog.with_positions(ilc_update(prog.positions, e, params, g))

    return iterate_waypoints(target, program, v, controller, seed, params.k_max, update)


def tune_gain(targets: Sequence[Target], gains: Sequence[float], params: ILCParams, controller: ControllerParams,
              waypoints: int = 100, zone: float = 10.0) -> tuple[float, dict[float, float]]:
    """The gain with the fewest mean iterations to 0.5 mm on `targets` (training curves; a miss counts
    k_max + 1, ties go to the smaller gain) and the score of every gain tried."""
    scores = {}
    for gain in gains:
        p = ILCParams(params.kind, float(gain), params.q_sigma, params.g_min, params.k_max)
        its = [run_ilc(t, baseline_program(t, waypoints, zone), t.speed, p, controller).iterations_to_spec
               for t in targets]
        scores[float(gain)] = float(np.mean([params.k_max + 1 if i is None else i for i in its]))
    best = min(scores, key=lambda g: (scores[g], g))
    return best, scores
