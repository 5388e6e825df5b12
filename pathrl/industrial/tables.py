"""Markdown tables laid out like the paper's Table II (IWA: baseline and MPGD) and Table III (speed search),
with the paper's values beside ours.

The paper's values are from Wen et al., Tables II and III (RobotStudio simulation of an ABB IRB 6640; Table II
also lists the real robot's baseline error). They come from a different controller, so they are context, not
a target: our controller is :mod:`pathrl.industrial.controller`. ``None`` is the paper's "N/A" (the 0.5 mm spec
was not reached within k_max).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = [
    "PAPER_RL", "PAPER_TABLE2", "PAPER_TABLE3", "PAPER_TABLE4", "Table2Row", "Table3Row", "ratios", "table2_markdown",
    "table3_markdown", "table4_markdown",
]

#: Paper Table II per row: speed command (sim), baseline error sim / real (mm), MPGD (sim) error (mm),
#: iterations, t_opt (s).
PAPER_TABLE2: dict[str, tuple[float, float, float, float, int | None, float | None]] = {
    "Type 1 Hard": (250, 1.55, 1.92, 1.07, None, None),
    "Type 1 Easy": (250, 0.80, 1.02, 0.20, 3, 95.45),
    "Type 1 Medium": (250, 1.79, 2.06, 0.43, 5, 333.38),
    "Type 1 (pose 1)": (250, 1.63, 2.07, 0.20, 3, 153.71),
    "Type 1 (pose 2)": (400, 4.60, 4.28, 0.66, None, None),
    "Type 1 (pose 3)": (400, 2.03, 3.66, 0.31, 8, 383.67),
    "Type 2 (pose 1)": (1100, 1.74, 1.31, 0.21, 14, 642.66),
    "Type 2 (pose 4)": (1100, 1.71, 1.24, 0.51, None, None),
    "Type 2 (MoveJ)": (1100, 1.59, 1.22, 0.22, 11, 156.00),
}

#: Paper Table II RL (sim) per row: error (mm), iterations, t_opt (s).
PAPER_RL: dict[str, tuple[float, int | None, float | None]] = {
    "Type 1 Hard": (1.14, None, None),
    "Type 1 Easy": (0.23, 1, 9.61),
    "Type 1 Medium": (0.45, 2, 22.73),
    "Type 1 (pose 1)": (0.13, 1, 10.74),
    "Type 1 (pose 2)": (0.46, 7, 63.46),
    "Type 1 (pose 3)": (0.23, 2, 17.42),
    "Type 2 (pose 1)": (0.22, 2, 17.68),
    "Type 2 (pose 4)": (0.22, 2, 17.30),
    "Type 2 (MoveJ)": (0.23, 2, 17.57),
}

#: Paper Table III per row (RL inner loop): IWA + bisection error (mm), mean speed (mm/s), speed std (%).
PAPER_TABLE3: dict[str, tuple[float, float, float]] = {
    "Type 1 Hard": (0.49, 91.13, 3.0),
    "Type 1 Easy": (0.31, 408.78, 4.8),
    "Type 1 Medium": (0.48, 133.25, 4.5),
    "Type 1 (pose 1)": (0.11, 258.89, 4.9),
    "Type 1 (pose 2)": (0.48, 223.37, 0.9),
    "Type 1 (pose 3)": (0.44, 410.02, 3.4),
    "Type 2 (pose 1)": (0.19, 991.25, 4.8),
    "Type 2 (pose 4)": (0.47, 1085.25, 3.4),
    "Type 2 (MoveJ)": (0.49, 998.18, 4.9),
}


@dataclass(frozen=True)
class Table2Row:
    """Our measurement of one evaluation trajectory: baseline and MPGD error (mm), iterations to 0.5 mm (None
    = not reached), MPGD wall time (s) and executions."""

    name: str
    pose: int
    speed: float
    baseline_mm: float
    mpgd_mm: float
    mpgd_itr: int | None
    mpgd_t: float
    executions: int
    rl_mm: float | None = None
    rl_itr: int | None = None
    rl_t: float | None = None


@dataclass(frozen=True)
class Table3Row:
    """Our speed search on one trajectory: best speed command (None = none met the specs) and its best
    execution's error (mm), mean speed (mm/s), speed std (% of mean); wall time (s)."""

    name: str
    v: float | None
    err_mm: float
    mean_speed: float
    std_pct: float
    t_total: float


def _f(x: float | int | None, fmt: str) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "N/A"
    return format(x, fmt)


def ratios(rows: Sequence[Table2Row]) -> tuple[int, float, float] | None:
    """(rows both brought to 0.5 mm, MPGD / policy iterations, MPGD / policy t_opt) summed over those rows (a
    policy count of 0 iterations counts as 1); None if no row reached 0.5 mm with both methods."""
    both = [r for r in rows if r.mpgd_itr is not None and r.rl_itr is not None]
    if not both:
        return None
    itr = sum(r.mpgd_itr for r in both) / max(sum(max(r.rl_itr, 1) for r in both), 1)
    t = sum(r.mpgd_t for r in both) / max(sum(r.rl_t for r in both), 1e-9)
    return len(both), itr, t


def _ratio(rows: Sequence[Table2Row]) -> str:
    """Iterations and t_opt of MPGD over the policy on the rows both brought to 0.5 mm."""
    rat = ratios(rows)
    if rat is None:
        return "no row reached 0.5 mm with both methods"
    return (f"On the {rat[0]} rows both reach 0.5 mm: MPGD / policy iterations = {rat[1]:.1f}x, t_opt = "
            f"{rat[2]:.1f}x (paper: 4.2x and 17.7x)")


def table2_markdown(rows: Sequence[Table2Row], command: str, note: str = "", policy_name: str = "RL") -> str:
    """Table II (baseline, MPGD and, if measured, RL columns) with the paper's simulation values beside ours."""
    has_rl = any(r.rl_mm is not None for r in rows)
    cols = ["Traj.", "Pose", "Speed cmd (mm/s)", "Baseline err. (mm)", "paper (sim/real)", "MPGD err. (mm)", "paper",
            "MPGD itr.", "paper", "MPGD t_opt (s)", "paper", "executions"]
    if has_rl:
        cols += [f"{policy_name} err. (mm)", "paper RL", f"{policy_name} itr.", "paper RL", f"{policy_name} t_opt (s)",
                 "paper RL"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        p, q = PAPER_TABLE2.get(r.name), PAPER_RL.get(r.name)
        cells = [r.name, str(r.pose), f"{r.speed:.0f}", f"{r.baseline_mm:.2f}", f"{p[1]:.2f}/{p[2]:.2f}" if p else "-",
                 f"{r.mpgd_mm:.2f}", _f(p[3], ".2f") if p else "-", _f(r.mpgd_itr, "d"), _f(p[4], "d") if p else "-",
                 f"{r.mpgd_t:.2f}", _f(p[5], ".2f") if p else "-", str(r.executions)]
        if has_rl:
            cells += [_f(r.rl_mm, ".2f"), _f(q[0], ".2f") if q else "-", _f(r.rl_itr, "d"), _f(q[1], "d") if q else "-",
                      _f(r.rl_t, ".2f"), _f(q[2], ".2f") if q else "-"]
        lines.append("| " + " | ".join(cells) + " |")
    reached = sum(r.mpgd_itr is not None for r in rows)
    itrs = [r.mpgd_itr for r in rows if r.mpgd_itr is not None]
    summary = [f"MPGD reached 0.5 mm on {reached}/{len(rows)} trajectories"
               + (f", mean {sum(itrs) / len(itrs):.1f} iterations" if itrs else "")
               + "; the paper's MPGD (RobotStudio): 6/9, mean 7.3 iterations."]
    if has_rl:
        rl_itrs = [r.rl_itr for r in rows if r.rl_itr is not None]
        summary.append(f"{policy_name} reached 0.5 mm on {len(rl_itrs)}/{len(rows)}"
                       + (f", mean {sum(rl_itrs) / len(rl_itrs):.1f} iterations" if rl_itrs else "")
                       + "; the paper's RL: 8/9, mean 2.4 iterations. " + _ratio(rows) + ".")
    title = "# Industrial motion-profile optimisation: Table II (Baseline, MPGD" + (
        f", {policy_name})" if has_rl else ")")
    text = [title, "",
            f"Measured with `{command}`.", "", *lines, "", *summary, ""]
    if note:
        text += [note, ""]
    return "\n".join(text)


def table3_markdown(rows: Sequence[Table3Row], command: str, note: str = "", iwa_name: str = "MPGD") -> str:
    """Table III-like: IWA + bisection on the speed command, the paper's RL + bisection beside it."""
    lines = ["| Traj. | best v cmd (mm/s) | error (mm) | paper | mean speed (mm/s) | paper | speed std (%) | paper "
             "| wall time (s) |", "|" + "---|" * 9]
    for r in rows:
        p = PAPER_TABLE3.get(r.name)
        lines.append(
            f"| {r.name} | {_f(r.v, '.0f')} | {r.err_mm:.2f} | {p[0] if p else '-'} | {r.mean_speed:.0f} | "
            f"{p[1] if p else '-'} | {r.std_pct:.1f} | {p[2] if p else '-'} | {r.t_total:.1f} |")
    text = [f"# Industrial motion-profile optimisation: IWA ({iwa_name}) + bisection speed search (cf. Table III)", "",
            f"Measured with `{command}`.", "", *lines, ""]
    if note:
        text += [note, ""]
    return "\n".join(text)


#: Paper Table IV (RobotStudio) per row and variant: error (mm), iterations (None = N/A).
PAPER_TABLE4: dict[str, dict[str, tuple[float, int | None]]] = {
    "RL": {"Type 1 Hard": (1.14, None), "Type 1 Easy": (0.23, 1), "Type 1 Medium": (0.45, 2),
           "Type 1 (pose 1)": (0.13, 1), "Type 1 (pose 2)": (0.46, 7), "Type 1 (pose 3)": (0.23, 2),
           "Type 2 (pose 1)": (0.24, 2), "Type 2 (pose 4)": (0.22, 2), "Type 2 (MoveJ)": (0.23, 2)},
    "RL-PER": {"Type 1 Hard": (1.09, None), "Type 1 Easy": (0.17, 1), "Type 1 Medium": (0.43, 2),
               "Type 1 (pose 1)": (0.23, 1), "Type 1 (pose 2)": (0.96, None), "Type 1 (pose 3)": (0.31, 4),
               "Type 2 (pose 1)": (0.24, 2), "Type 2 (pose 4)": (0.44, 6), "Type 2 (MoveJ)": (0.18, 2)},
    "RL-P_target": {"Type 1 Hard": (1.18, None), "Type 1 Easy": (0.23, 1), "Type 1 Medium": (0.45, 2),
                    "Type 1 (pose 1)": (0.21, 2), "Type 1 (pose 2)": (1.39, None), "Type 1 (pose 3)": (0.24, 7),
                    "Type 2 (pose 1)": (0.18, 2), "Type 2 (pose 4)": (0.47, 5), "Type 2 (MoveJ)": (0.20, 1)},
    "RL-q-F_jac": {"Type 1 Hard": (1.30, None), "Type 1 Easy": (0.25, 1), "Type 1 Medium": (0.42, 2),
                   "Type 1 (pose 1)": (0.24, 2), "Type 1 (pose 2)": (2.00, None), "Type 1 (pose 3)": (0.22, 4),
                   "Type 2 (pose 1)": (0.17, 2), "Type 2 (pose 4)": (0.53, None), "Type 2 (MoveJ)": (0.15, 2)},
    "RL-e": {"Type 1 Hard": (1.33, None), "Type 1 Easy": (0.24, 1), "Type 1 Medium": (0.47, 3),
             "Type 1 (pose 1)": (0.20, 2), "Type 1 (pose 2)": (1.56, None), "Type 1 (pose 3)": (0.20, 3),
             "Type 2 (pose 1)": (0.23, 3), "Type 2 (pose 4)": (0.54, None), "Type 2 (MoveJ)": (0.19, 2)},
}


def table4_markdown(results: dict[str, list[tuple[str, float, int | None]]], command: str, note: str = "") -> str:
    """Table IV (ablations): per variant (name -> [(row, error mm, iterations or None)]) our error / iterations
    beside the paper's."""
    variants = list(results)
    cols = ["Traj."] + [c for v in variants for c in (f"{v} err.", "paper", f"{v} itr.", "paper")]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    names = [r[0] for r in results[variants[0]]] if variants else []
    for i, name in enumerate(names):
        cells = [name]
        for v in variants:
            _, err, itr = results[v][i]
            p = PAPER_TABLE4.get(v, {}).get(name)
            cells += [f"{err:.2f}", _f(p[0], ".2f") if p else "-", _f(itr, "d"), _f(p[1], "d") if p else "-"]
        lines.append("| " + " | ".join(cells) + " |")
    summary = []
    for v in variants:
        itrs = [itr for _, _, itr in results[v] if itr is not None]
        summary.append(f"{v}: 0.5 mm on {len(itrs)}/{len(results[v])}"
                       + (f", mean {sum(itrs) / len(itrs):.1f} iterations" if itrs else ""))
    text = ["# Industrial motion-profile optimisation: Table IV (IWA ablations)", "", f"Measured with `{command}`.",
            "", *lines, "", "; ".join(summary) + ".", ""]
    if note:
        text += [note, ""]
    return "\n".join(text)
