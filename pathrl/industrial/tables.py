"""Markdown tables laid out like the paper's Table II (IWA: baseline and MPGD) and Table III (speed search),
with the paper's values beside ours.

The paper's values are from Wen et al., Tables II-IV (RobotStudio simulation of an ABB IRB 6640; Table II also
lists the real robot's baseline error), read from ``pathrl/config/paper/industrial.yaml`` (:mod:`pathrl.config.paper`).
They come from a different controller, so they are context, not a target: our controller is
:mod:`pathrl.industrial.controller`. ``None`` is the paper's "N/A" (the 0.5 mm spec was not reached within k_max).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from pathrl.config.paper import load as load_paper

__all__ = [
    "PAPER_RL", "PAPER_TABLE2", "PAPER_TABLE3", "PAPER_TABLE4", "Table2Row", "Table3Row", "ilc_summary",
    "per_row_ratio", "ratios", "table2_markdown", "table3_markdown", "table4_markdown",
]

_PAPER = load_paper("industrial")
_T2 = _PAPER.table("table_II")
#: Paper Table II per row: speed command (sim), baseline error sim / real (mm), MPGD (sim) error (mm),
#: iterations, t_opt (s).
PAPER_TABLE2: dict[str, tuple[float, float, float, float, int | None, float | None]] = {
    k: v[:6] for k, v in _T2.rows.items()}
#: Paper Table II RL (sim) per row: error (mm), iterations, t_opt (s).
PAPER_RL: dict[str, tuple[float, int | None, float | None]] = {k: v[6:] for k, v in _T2.rows.items()}
#: Paper Table III per row (RL inner loop): IWA + bisection error (mm), mean speed (mm/s), speed std (%).
PAPER_TABLE3: dict[str, tuple[float, float, float]] = dict(_PAPER.table("table_III").rows)


def _paper_reached(itrs: Sequence[int | None]) -> str:
    """'6/9, mean 7.3 iterations': the paper's rows at 0.5 mm and their mean iterations."""
    done = [i for i in itrs if i is not None]
    return f"{len(done)}/{len(itrs)}, mean {sum(done) / len(done):.1f} iterations"


@dataclass(frozen=True)
class Table2Row:
    """Our measurement of one evaluation trajectory: baseline and MPGD error (mm), iterations to 0.5 mm (None
    = not reached), MPGD wall time (s) and executions; the policy's and each ILC variant's where measured."""

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
    ilc: tuple[tuple[str, float, int | None], ...] = ()  # (column name, best error mm, iterations) per ILC variant


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
            f"{rat[2]:.1f}x (paper: {_PAPER.value('rl_itr_improvement')}x and {_PAPER.value('rl_t_opt_speedup')}x)")


def table2_markdown(rows: Sequence[Table2Row], command: str, note: str = "", policy_name: str = "RL") -> str:
    """Table II (baseline, MPGD and, if measured, RL columns) with the paper's simulation values beside ours."""
    has_rl = any(r.rl_mm is not None for r in rows)
    ilc_names = [name for name, _, _ in rows[0].ilc] if rows else []
    cols = ["Traj.", "Pose", "Speed cmd (mm/s)", "Baseline err. (mm)", "paper (sim/real)", "MPGD err. (mm)", "paper",
            "MPGD itr.", "paper", "MPGD t_opt (s)", "paper", "executions"]
    if has_rl:
        cols += [f"{policy_name} err. (mm)", "paper RL", f"{policy_name} itr.", "paper RL", f"{policy_name} t_opt (s)",
                 "paper RL"]
    cols += [c for name in ilc_names for c in (f"{name} err. (mm)", f"{name} itr.")]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        p, q = PAPER_TABLE2.get(r.name), PAPER_RL.get(r.name)
        cells = [r.name, str(r.pose), f"{r.speed:.0f}", f"{r.baseline_mm:.2f}", f"{p[1]:.2f}/{p[2]:.2f}" if p else "-",
                 f"{r.mpgd_mm:.2f}", _f(p[3], ".2f") if p else "-", _f(r.mpgd_itr, "d"), _f(p[4], "d") if p else "-",
                 f"{r.mpgd_t:.2f}", _f(p[5], ".2f") if p else "-", str(r.executions)]
        if has_rl:
            cells += [_f(r.rl_mm, ".2f"), _f(q[0], ".2f") if q else "-", _f(r.rl_itr, "d"), _f(q[1], "d") if q else "-",
                      _f(r.rl_t, ".2f"), _f(q[2], ".2f") if q else "-"]
        cells += [c for _, mm, itr in r.ilc for c in (f"{mm:.2f}", _f(itr, "d"))]
        lines.append("| " + " | ".join(cells) + " |")
    reached = sum(r.mpgd_itr is not None for r in rows)
    itrs = [r.mpgd_itr for r in rows if r.mpgd_itr is not None]
    summary = [f"MPGD reached 0.5 mm on {reached}/{len(rows)} trajectories"
               + (f", mean {sum(itrs) / len(itrs):.1f} iterations" if itrs else "")
               + f"; the paper's MPGD (RobotStudio): {_paper_reached([p[4] for p in PAPER_TABLE2.values()])}."]
    if has_rl:
        rl_itrs = [r.rl_itr for r in rows if r.rl_itr is not None]
        summary.append(f"{policy_name} reached 0.5 mm on {len(rl_itrs)}/{len(rows)}"
                       + (f", mean {sum(rl_itrs) / len(rl_itrs):.1f} iterations" if rl_itrs else "")
                       + f"; the paper's RL: {_paper_reached([q[1] for q in PAPER_RL.values()])}. " + _ratio(rows)
                       + ".")
    summary += [ilc_summary(rows, j, policy_name if has_rl else None) for j in range(len(ilc_names))]
    title = "# Industrial motion-profile optimisation: Table II (Baseline, MPGD" + (
        f", {policy_name}" if has_rl else "") + "".join(f", {n}" for n in ilc_names) + ")"
    text = [title, "",
            f"Measured with `{command}`.", "", *lines, "", *summary, ""]
    if note:
        text += [note, ""]
    return "\n".join(text)


def per_row_ratio(a: Sequence[int | None], b: Sequence[int | None]) -> tuple[int, float, float] | None:
    """(rows where both counts are known, mean of the per-row ratios a_i / b_i, ratio of the totals); counts of 0
    iterations count as 1; None if no row has both."""
    pairs = [(max(x, 1), max(y, 1)) for x, y in zip(a, b, strict=True) if x is not None and y is not None]
    if not pairs:
        return None
    return (len(pairs), sum(x / y for x, y in pairs) / len(pairs),
            sum(x for x, _ in pairs) / sum(y for _, y in pairs))


def ilc_summary(rows: Sequence[Table2Row], j: int, policy_name: str | None = None) -> str:
    """One sentence on ILC variant j of the rows: rows at 0.5 mm, mean iterations, and MPGD (and the policy, if
    `policy_name`) over it in iterations on the rows both reach (mean of per-row ratios; ratio of totals)."""
    name = rows[0].ilc[j][0]
    itrs = [r.ilc[j][2] for r in rows]
    got = [i for i in itrs if i is not None]
    text = f"{name} reached 0.5 mm on {len(got)}/{len(rows)}" + (
        f", mean {sum(got) / len(got):.1f} iterations" if got else "")
    others = [("MPGD", [r.mpgd_itr for r in rows])]
    if policy_name is not None:
        others.append((policy_name, [r.rl_itr for r in rows]))
    for other, counts in others:
        rat = per_row_ratio(counts, itrs)
        text += (f"; {other} / {name} iterations on the {rat[0]} rows both reach: {rat[1]:.2f}x (mean of per-row "
                 f"ratios; totals {rat[2]:.2f}x)" if rat else f"; no row reached by both {other} and {name}")
    return text + "."


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


def _by_variant(rows: Mapping[str, tuple]) -> dict[str, dict[str, tuple]]:
    """Rows keyed "<variant>/<trajectory>" as {variant: {trajectory: cells}}, in file order."""
    out: dict[str, dict[str, tuple]] = {}
    for key, cells in rows.items():
        variant, _, name = key.partition("/")
        out.setdefault(variant, {})[name] = cells
    return out


#: Paper Table IV (RobotStudio) per row and variant: error (mm), iterations (None = N/A).
PAPER_TABLE4: dict[str, dict[str, tuple[float, int | None]]] = _by_variant(_PAPER.table("table_IV").rows)


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
