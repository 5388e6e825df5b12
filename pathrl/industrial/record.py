"""One waypoint optimisation with every execution kept, written to ``industrial.mcap`` for ``pathrl-view``.

``pathrl-industrial record traj=<row> method=mpgd|rl [policy=RUN_DIR] out=DIR`` runs the optimisation Table II
runs for that row (:func:`pathrl.industrial.experiments.run_table2`: the baseline profile of ``waypoints`` MoveL
waypoints at the row's speed command, then MPGD (``mpgd.k_max``) or the policy's IWA (``rl.k_max``)) and keeps,
for every execution k (0 = the baseline profile), the waypoints, the executed TCP path and its position error
profile. Topics and layouts: :mod:`pathrl.logging.schema` (``INDUSTRIAL_*``); positions in mm as in
:mod:`pathrl.industrial`.

MPGD: :func:`mpgd_iterations` is :func:`pathrl.industrial.mpgd.run_mpgd`'s loop (same executions, seeds, stop rule
and best program; the test checks the error history against ``run_mpgd``'s) with each execution kept, because
``run_mpgd`` keeps only the best program. Policy: :func:`policy_iterations` runs
:func:`pathrl.industrial.rl.run_policy_iwa` itself on an :class:`~pathrl.industrial.iwa_env.IWAEpisode` that
executes each accepted profile a second time to keep its path (the controller is deterministic for a seed, so the
copy is the execution the policy saw).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pathrl.industrial.controller import ControllerParams, Execution, execute
from pathrl.industrial.iwa_env import IWAEpisode, IWASettings, StepResult
from pathrl.industrial.metrics import POS_SPEC_MM, Errors, evaluate, position_errors
from pathrl.industrial.mpgd import IWAResult, MPGDParams, run_mpgd
from pathrl.industrial.program import Program
from pathrl.industrial.rl import run_policy_iwa
from pathrl.industrial.trajectories import Target
from pathrl.logging.mcap_io import McapJsonWriter
from pathrl.logging.schema import (
    INDUSTRIAL_ERROR,
    INDUSTRIAL_EXECUTED,
    INDUSTRIAL_SUMMARY,
    INDUSTRIAL_TARGET,
    INDUSTRIAL_WAYPOINTS,
)
from pathrl.storage import atomic_write

__all__ = [
    "Iteration", "Optimiser", "best_iteration", "mpgd_iterations", "observe", "policy_iterations",
    "record_optimisation", "write_industrial_mcap",
]

FILE_NAME = "industrial.mcap"
METHODS = ("mpgd", "rl")


@dataclass(frozen=True)
class Iteration:
    """One execution of the optimisation: iteration k, waypoints (m, 3) mm, times t (N,) s, executed TCP positions
    (N, 3) mm, the execution's metrics, the position error of each sample (N,) mm and the fractional index of its
    nearest target point (N,)."""

    k: int
    waypoints: np.ndarray
    t: np.ndarray
    executed: np.ndarray
    errors: Errors
    profile: np.ndarray
    target_index: np.ndarray


def observe(k: int, program: Program, ex: Execution, target: Target, controller: ControllerParams) -> Iteration:
    """The record of execution `ex` of `program` (the metrics as :func:`pathrl.industrial.metrics.evaluate`)."""
    d, u = position_errors(ex.p, target.p)
    errs = evaluate(ex.p, ex.rot, 1.0 / controller.rate, target.p, target.z_axis)
    return Iteration(k, program.positions.copy(), ex.t, ex.p, errs, d, u)


def mpgd_iterations(target: Target, program: Program, v: float, params: MPGDParams, controller: ControllerParams,
                    seed: int = 0) -> tuple[IWAResult, list[Iteration]]:
    """:func:`~pathrl.industrial.mpgd.run_mpgd` from `program` at speed command `v` mm/s, with every execution
    kept."""
    kept: list[Iteration] = []
    best = run_mpgd(target, program, v, params, controller, seed,
                    on_execution=lambda k, prog, ex: kept.append(observe(k, prog, ex, target, controller)))
    return best, kept


class _KeepingEpisode(IWAEpisode):
    """An IWA episode that keeps every executed profile (module doc)."""

    kept: list[Iteration]

    def _keep(self) -> None:
        ex = execute(self.program, self.v, self.controller)
        self.kept.append(observe(self.k, self.program, ex, self.target, self.controller))

    def reset(self) -> np.ndarray:
        obs = super().reset()
        self.kept = []
        self._keep()
        return obs

    def step(self, actions: np.ndarray) -> StepResult:
        res = super().step(actions)
        if res.errors is not None:  # a profile out of reach is not executed (the episode ends)
            self._keep()
        return res


def policy_iterations(target: Target, v: float, controller: ControllerParams,
                      policy: Callable[[np.ndarray], np.ndarray],
                      iwa: IWASettings | None = None) -> tuple[IWAResult, list[Iteration]]:
    """The learned IWA (:func:`~pathrl.industrial.rl.run_policy_iwa`, features (m, 313) -> actions (m, 3)) at speed
    command `v` mm/s with `iwa` (default :class:`IWASettings`), every execution kept."""
    env = _KeepingEpisode(target, v, controller, iwa or IWASettings())
    result = run_policy_iwa(env, policy)
    return result, env.kept


def best_iteration(iterations: list[Iteration]) -> int:
    """Index of the execution with the smallest max position error (the first of equals), as the IWA keeps it."""
    return int(np.argmin([i.errors.max_pos_mm for i in iterations]))


def write_industrial_mcap(path: Path, target: Target, method: str, iterations: list[Iteration], result: IWAResult,
                          v: float, meta: dict[str, Any] | None = None) -> None:
    """Write the recording of one optimisation to `path` atomically (topics: module doc)."""
    if not iterations:
        raise ValueError("no executions to record")

    def write(tmp: Path) -> None:
        with McapJsonWriter(tmp) as w:
            w.write(INDUSTRIAL_TARGET, {"name": target.name, "pose": target.pose, "move": target.move,
                                        "speed_mm_s": float(v), "method": method, "positions": target.p,
                                        "z_axis": target.z_axis, **(meta or {})}, 0)
            for it in iterations:
                ns = int(it.k * 1e9)
                w.write(INDUSTRIAL_WAYPOINTS, {"iteration": it.k, "positions": it.waypoints}, ns)
                w.write(INDUSTRIAL_EXECUTED, {"iteration": it.k, "t": it.t, "positions": it.executed}, ns)
                w.write(INDUSTRIAL_ERROR, {"iteration": it.k, **it.errors.as_dict(), "profile_mm": it.profile,
                                           "target_index": it.target_index}, ns)
            w.write(INDUSTRIAL_SUMMARY, {
                "method": method, "iterations": len(iterations) - 1, "best_iteration": best_iteration(iterations),
                "iterations_to_spec": result.iterations_to_spec, "executions": result.executions,
                "t_opt_s": result.t_opt, "history": result.history, "best": result.errors.as_dict(),
                "spec_mm": POS_SPEC_MM}, int(iterations[-1].k * 1e9))

    atomic_write(Path(path), write)


@dataclass(frozen=True)
class Optimiser:
    """The optimiser of a recording: `method` ``mpgd`` (MPGD from the baseline profile with `mpgd`, default
    :class:`~pathrl.industrial.mpgd.MPGDParams`) or ``rl`` (the IWA of `policy`, features (m, 313) -> actions
    (m, 3))."""

    method: str
    mpgd: MPGDParams | None = None
    policy: Callable[[np.ndarray], np.ndarray] | None = None


def record_optimisation(target: Target, optimiser: Optimiser, controller: ControllerParams, out_dir: Path, *,
                        iwa: IWASettings | None = None, seed: int = 0,
                        meta: dict[str, Any] | None = None) -> tuple[Path, IWAResult, list[Iteration]]:
    """Optimise the waypoints of `target` at its speed command like Table II with `optimiser` (the baseline profile
    and the learned IWA as `iwa` says, default :class:`IWASettings`; MPGD's seed `seed`) and write
    ``out_dir/industrial.mcap`` (`meta`: extra fields of its target message); returns (file, result, kept)."""
    from pathrl.industrial.trajectories import baseline_program

    method, iwa = optimiser.method, iwa or IWASettings()
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if method == "mpgd":
        result, kept = mpgd_iterations(target, baseline_program(target, iwa.m, iwa.zone), target.speed,
                                       optimiser.mpgd or MPGDParams(), controller, seed)
    elif optimiser.policy is None:
        raise ValueError("method rl needs a policy")
    else:
        result, kept = policy_iterations(target, target.speed, controller, optimiser.policy, iwa)
    out = Path(out_dir) / FILE_NAME
    out.parent.mkdir(parents=True, exist_ok=True)
    write_industrial_mcap(out, target, method, kept, result, target.speed, meta)
    return out, result, kept
