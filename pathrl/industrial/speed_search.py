"""Motion-profile optimisation (paper Alg. 1): bisection on the speed command around an inner IWA.

Each outer iteration runs the inner waypoint adjustment (MPGD, :func:`pathrl.industrial.mpgd.run_mpgd`, or any
``iwa(program, v) -> IWAResult``, e.g. the learned policy) from the baseline profile at the current speed
command v and checks the best execution against all three specs (position <= 0.5 mm, orientation <= 3 deg,
speed std <= 5 % of the mean). Meeting them raises the lower bound (v_min = v, next v = (v_max + v) / 2),
failing lowers the upper bound (v_max = v, next v = (v_min + v) / 2). The result is the fastest speed command
whose IWA met every spec, or None.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from pathrl.industrial.controller import ControllerParams
from pathrl.industrial.mpgd import IWAResult, MPGDParams, run_mpgd
from pathrl.industrial.program import Program
from pathrl.industrial.trajectories import Target, baseline_program

__all__ = ["SearchParams", "SearchResult", "bisection_search"]


@dataclass(frozen=True)
class SearchParams:
    """Bisection settings: outer iterations (paper: 10), bounds as factors of the initial speed command."""

    outer: int = 10
    v_min_factor: float = 0.2
    v_max_factor: float = 2.0

    def __post_init__(self) -> None:
        if self.outer < 1 or not 0.0 < self.v_min_factor < 1.0 < self.v_max_factor:
            raise ValueError("speed search: need outer >= 1 and 0 < v_min_factor < 1 < v_max_factor")


@dataclass
class SearchResult:
    """Best speed command (None if no speed met the specs), its IWA result, every tried (v, met specs,
    IWA result) and the wall time (s)."""

    v: float | None
    best: IWAResult | None
    trials: list[tuple[float, bool, IWAResult]] = field(default_factory=list)
    t_total: float = 0.0


def bisection_search(target: Target, v0: float, params: SearchParams | None = None, mpgd: MPGDParams | None = None,
                     controller: ControllerParams | None = None, seed: int = 0, program: Program | None = None,
                     iwa: Callable[[Program, float], IWAResult] | None = None) -> SearchResult:
    """Alg. 1 from speed command v0 mm/s (module doc); every IWA starts from `program` (default: the 100-MoveL
    baseline of the target) and is `iwa` (default: MPGD with `mpgd` and `controller`)."""
    program = baseline_program(target) if program is None else program
    if iwa is None:
        def iwa(prog: Program, v: float) -> IWAResult:
            return run_mpgd(target, prog, v, mpgd, controller, seed)
    params = SearchParams() if params is None else params
    v_lo, v_hi, v = params.v_min_factor * v0, params.v_max_factor * v0, float(v0)
    out = SearchResult(None, None)
    t0 = time.perf_counter()
    for _ in range(params.outer):
        res = iwa(program, v)
        ok = res.errors.meets_specs()
        out.trials.append((v, ok, res))
        if ok and (out.v is None or v > out.v):
            out.v, out.best = v, res
        if ok:
            v_lo, v = v, 0.5 * (v_hi + v)
        else:
            v_hi, v = v, 0.5 * (v_lo + v)
    out.t_total = time.perf_counter() - t0
    return out
