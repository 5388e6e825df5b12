"""The measurements behind the tables: baseline and MPGD per evaluation trajectory (Table II), MPGD + bisection
(Table III-like) and a sweep of baseline errors over speed commands."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from pathrl.industrial.controller import ControllerParams, execute
from pathrl.industrial.ilc import ILCParams, run_ilc
from pathrl.industrial.iwa_env import IWAEpisode, IWASettings
from pathrl.industrial.metrics import evaluate
from pathrl.industrial.mpgd import IWAResult, MPGDParams, run_mpgd
from pathrl.industrial.program import Program
from pathrl.industrial.rl import run_policy_iwa
from pathrl.industrial.speed_search import SearchParams, bisection_search
from pathrl.industrial.tables import Table2Row, Table3Row
from pathrl.industrial.trajectories import EVALUATION, Target, baseline_program, evaluation_targets

__all__ = ["baseline_sweep", "run_speed", "run_table2", "run_table4", "select_targets", "speed_iwa",
           "sweep_markdown"]


def select_targets(rows: Sequence[str]) -> list[Target]:
    """The evaluation targets named in `rows` (all if empty), in table order; ValueError on an unknown name."""
    known = [r[0] for r in EVALUATION]
    bad = [r for r in rows if r not in known]
    if bad:
        raise ValueError(f"unknown evaluation row {bad[0]!r}; known: {', '.join(known)}")
    return [t for t in evaluation_targets() if not rows or t.name in rows]


def run_table2(targets: Sequence[Target], controller: ControllerParams, mpgd: MPGDParams,
               iwa: IWASettings | None = None, seed: int = 0,
               policy: Callable[[np.ndarray], np.ndarray] | None = None,
               ilc: dict[str, ILCParams] | None = None) -> list[Table2Row]:
    """Baseline (the profile of ``iwa.m`` MoveL waypoints, zone ``iwa.zone``; `iwa` default :class:`IWASettings`)
    and MPGD (seed `seed`) on each target at its speed command; with a `policy` (features (m, 313) -> actions
    (m, 3)) also the learned IWA (``iwa.k_max`` iterations); with `ilc` (column name -> settings) each ILC
    variant from the same baseline (seed `seed`)."""
    iwa = iwa or IWASettings()
    rows = []
    for t in targets:
        prog = baseline_program(t, iwa.m, iwa.zone)
        res = run_mpgd(t, prog, t.speed, mpgd, controller, seed)
        rl: dict[str, object] = {}
        if policy is not None:
            out = run_policy_iwa(IWAEpisode(t, t.speed, controller, iwa), policy)
            rl = {"rl_mm": out.errors.max_pos_mm, "rl_itr": out.iterations_to_spec, "rl_t": out.t_opt}
        runs = {name: run_ilc(t, prog, t.speed, p, controller, seed) for name, p in (ilc or {}).items()}
        rl["ilc"] = tuple((name, r.errors.max_pos_mm, r.iterations_to_spec) for name, r in runs.items())
        rows.append(Table2Row(t.name, t.pose, t.speed, res.history[0], res.errors.max_pos_mm,
                              res.iterations_to_spec, res.t_opt, res.executions, **rl))
    return rows


def run_speed(targets: Sequence[Target], controller: ControllerParams, mpgd: MPGDParams, search: SearchParams,
              iwa: IWASettings | None = None, seed: int = 0,
              policy: Callable[[np.ndarray], np.ndarray] | None = None, ilc: ILCParams | None = None
              ) -> list[Table3Row]:
    """IWA + bisection on the speed command (paper Alg. 1) for each target, from its speed command and the profile
    of ``iwa.m`` MoveL waypoints, zone ``iwa.zone`` (`iwa` default :class:`IWASettings`); the IWA is MPGD (seed
    `seed`), the `policy` (``iwa.k_max`` iterations) or the ILC `ilc` (seed `seed`) if given."""
    settings = iwa or IWASettings()
    rows = []
    for t in targets:
        start = baseline_program(t, settings.m, settings.zone)
        res = bisection_search(t, t.speed, search, mpgd, controller, seed, start,
                               speed_iwa(t, controller, settings, seed, policy, ilc))
        if res.best is None:
            rows.append(Table3Row(t.name, None, float("nan"), float("nan"), float("nan"), res.t_total))
            continue
        e = res.best.errors
        rows.append(Table3Row(t.name, res.v, e.max_pos_mm, e.mean_speed, 100 * e.speed_std_ratio, res.t_total))
    return rows


def speed_iwa(target: Target, controller: ControllerParams, settings: IWASettings, seed: int = 0,
              policy: Callable[[np.ndarray], np.ndarray] | None = None, ilc: ILCParams | None = None
              ) -> Callable[[Program, float], IWAResult] | None:
    """The inner IWA ``(program, v) -> IWAResult`` of the speed search on `target`: the `policy`'s learned IWA,
    else the ILC `ilc`, else None (the search's default, MPGD)."""
    if policy is not None:
        return lambda _prog, v: run_policy_iwa(IWAEpisode(target, v, controller, settings), policy)
    if ilc is not None:
        return lambda prog, v: run_ilc(target, prog, v, ilc, controller, seed)
    return None


def baseline_sweep(targets: Sequence[Target], speeds: Sequence[float], controller: ControllerParams,
                   waypoints: int = 100, zone: float = 10.0) -> np.ndarray:
    """Max position error (mm) of the baseline profile, (len(targets), len(speeds))."""
    out = np.zeros((len(targets), len(speeds)))
    for i, t in enumerate(targets):
        prog = baseline_program(t, waypoints, zone)
        for j, v in enumerate(speeds):
            ex = execute(prog, float(v), controller)
            out[i, j] = evaluate(ex.p, ex.rot, 1.0 / controller.rate, t.p, t.z_axis).max_pos_mm
    return out


def sweep_markdown(targets: Sequence[Target], speeds: Sequence[float], errors: np.ndarray, command: str) -> str:
    """The baseline sweep as a markdown table (rows: targets, columns: speed commands)."""
    head = "| Traj. | " + " | ".join(f"{v:.0f} mm/s" for v in speeds) + " |"
    lines = [head, "|" + "---|" * (len(speeds) + 1)]
    for t, row in zip(targets, errors, strict=True):
        lines.append(f"| {t.name} | " + " | ".join(f"{e:.2f}" for e in row) + " |")
    return "\n".join(["# Baseline (100 MoveL, z10) max position error (mm) over the speed command", "",
                      f"Measured with `{command}`.", "", *lines, ""])


def run_table4(targets: Sequence[Target], controller: ControllerParams,
               policies: dict[str, Callable[[np.ndarray], np.ndarray]], waypoints: int = 100, zone: float = 10.0,
               k_max: int = 10) -> dict[str, list[tuple[str, float, int | None]]]:
    """The learned IWA of each policy variant on each target: (row, best error mm, iterations to 0.5 mm)."""
    out: dict[str, list[tuple[str, float, int | None]]] = {}
    for name, policy in policies.items():
        out[name] = []
        for t in targets:
            res = run_policy_iwa(IWAEpisode(t, t.speed, controller, IWASettings(waypoints, zone, k_max)), policy)
            out[name].append((t.name, res.errors.max_pos_mm, res.iterations_to_spec))
    return out
