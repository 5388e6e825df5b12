"""Render reproduced tables next to the paper's values: Markdown, CSV rows and LaTeX.

Pure functions of ``results`` = ``{"evaluations": {evaluation_id: metrics.json}, "baselines":
{baseline_id: toppra.json}, "realtime": {key: realtime.json}, "training": {model: summary.json}}`` and the
paper's tables (``pathrl/config/paper/tracking.yaml``), so the output is fixed by its inputs (tests/golden/tables.md).
"""

from __future__ import annotations

from typing import Any

from pathrl.repro import trueadapt, trueadapt_findings
from pathrl.repro.tables import (
    AUTHORS_BUDGETS,
    PAPER_TABLE,
    PATH_CHANGE,
    REALTIME,
    ROWS,
    SHORT_COLUMNS,
    TABLE_GREEDY,
    TABLE_I,
    TABLE_I_TEST2,
    TABLE_II,
    TABLE_III,
    TABLE_IV,
    TABLE_IX,
    TABLE_PATH_CHANGE,
    TABLE_V,
    TABLE_VI,
    TABLE_VII,
    TABLE_VIII,
    WARM_STARTS,
    Row,
)

__all__ = ["render_latex", "render_markdown", "time_out_pct"]

TITLES = {
    TABLE_I: "Table I: tracking without sensory feedback",
    TABLE_I_TEST2: "Table I on a second test split (not in the paper: the generator's next seed, never trained "
                   "on; paper values from Table I)",
    TABLE_II: "Table II: reward trade-off, path length vs deviation (iiwa7, random)",
    TABLE_III: "Table III: knots in the state (iiwa7, random)",
    TABLE_IV: "Table IV: generalization, trained on random, evaluated on target point paths",
    TABLE_VII: "Table VII: ball on plate (iiwa7, ball-balancing paths, whole paths, PyBullet)",
    TABLE_VIII: "Table VIII: ARMAR-4 standing free (target point paths, PyBullet)",
}
UNITS = {"duration_s": "s", "rad": "rad", "cm": "cm", "deg": "deg"}


def _fmt(x: float | None, nd: int = 2) -> str:
    return "–" if x is None else f"{x:.{nd}f}"


def _columns(paper: dict[str, Any], table: str) -> list[str]:
    """Our columns of `table`: Table I's and VII-VIII's are the paper's (VII-VIII: the share of episodes that reached
    the end after the end-of-path duration, which is a mean over those episodes only); II-IV: SHORT_COLUMNS."""
    if table not in (TABLE_I, TABLE_VII, TABLE_VIII):
        return list(SHORT_COLUMNS)
    cols = list(paper[PAPER_TABLE.get(table, table)]["columns"])
    return cols if table == TABLE_I else cols[:1] + ["reached_end_pct"] + cols[1:]


def _nd(column: str) -> int:
    return 3 if column.endswith("_rad") else 2


def _metrics(results: dict[str, Any], row: Row) -> dict[str, Any] | None:
    return results.get("evaluations", {}).get(row.evaluation.id)


def time_out_pct(metrics: dict[str, Any] | None) -> float | None:
    """Share (%) of a result's episodes that ended on the time limit rather than at rest at the end of the path
    (their duration and deviation are those of the unfinished attempt); None without per-episode records."""
    per = (metrics or {}).get("per_episode")
    if not per:
        return None
    return 100.0 * sum(p.get("termination") == "time_out" for p in per) / len(per)


def _toppra(results: dict[str, Any], row: Row) -> dict[str, Any] | None:
    return results.get("baselines", {}).get(row.evaluation.baseline.id)


def _cell(ours: float | None, paper: float | None, nd: int) -> str:
    if ours is None:
        return f"– / {_fmt(paper, nd)}" if paper is not None else "–"
    if paper is None:
        return f"**{_fmt(ours, nd)}**"
    ratio = f" ({ours / paper:.2f})" if paper else ""
    return f"**{_fmt(ours, nd)}** / {_fmt(paper, nd)}{ratio}"


def _learned_table(results: dict[str, Any], paper: dict[str, Any], table: str) -> tuple[list[str], list[list[str]]]:
    ptable = paper[PAPER_TABLE.get(table, table)]
    cols = _columns(paper, table)
    pcols = ptable["columns"]
    lines = [f"## {TITLES[table]}", "",
             "| row | " + " | ".join(cols) + " | learned / TOPP-RA | episodes | time-outs (%) | limit violations | "
             "trained by |",
             "|---|" + "---|" * (len(cols) + 5)]
    training = results.get("training") or {}
    csv_rows: list[list[str]] = []
    for row in (r for r in ROWS if r.table == table):
        p = dict(zip(pcols, ptable["rows"].get(row.key, []), strict=False))
        m, tp = _metrics(results, row), _toppra(results, row)
        cells = [_cell(None if m is None else m.get(c), p.get(c), _nd(c)) for c in cols]
        rel = "–"
        if m is not None and tp is not None and tp.get("toppra_duration_s"):
            rel = f"{m['duration_s'] / tp['toppra_duration_s']:.2f}"
        eps = "–" if m is None else str(m["episodes"])
        timeouts = time_out_pct(m)
        viol = "–" if m is None else str(m["limit_violations"])
        method = "–" if m is None else training.get(row.evaluation.model, {}).get("method", "–")
        lines.append(f"| {row.key} | " + " | ".join(cells) + f" | {rel} | {eps} | {_fmt(timeouts, 1)} | {viol} | "
                     f"{method} |")
        for c in cols:
            csv_rows.append([table, row.key, c, "" if m is None or m.get(c) is None else f"{m[c]:.6g}",
                             "" if p.get(c) is None else f"{p[c]:g}"])
        if timeouts is not None:
            csv_rows.append([table, row.key, "time_out_pct", f"{timeouts:.6g}", ""])
    return lines, csv_rows


def _table_vi(results: dict[str, Any], paper: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    p6 = paper[TABLE_VI]["rows"]
    p1 = paper[TABLE_I]
    lines = ["## Table VI: TOPP-RA on the same segments", "",
             "Relative duration = TOPP-RA duration / learned duration (%). Our TOPP-RA honours the velocity and "
             "acceleration limits exactly (checked at 240 Hz). *paper learned / our TOPP-RA* sets the paper's "
             "learned duration (Table I) against our TOPP-RA on our test split, the bar a policy here has to meet. "
             "TOPP-RA has no jerk limit: *+ Ruckig* is its plan tracked every control cycle by Ruckig under the "
             "velocity, acceleration and jerk limits (what a jerk-limited robot gets from the plan; "
             "`pathrl/baselines/ruckig_track.py`): its duration, its largest distance from the path (mean over the "
             "segments, rad) and its limit violations (position / jerk). *Greedy*: a non-learned follower through the "
             "same valid acceleration range "
             "(`pathrl/baselines/greedy_follower.py`: per decision the candidate speed with the most progress within "
             "a deviation bound, capped by the curvature ahead), its duration, mean Cartesian deviation and "
             "limit violations on the learned policy's segments.",
             "",
             "| row | TOPP-RA duration (s) | relative duration (%) | TOPP-RA max joint dev (rad) | "
             "learned / TOPP-RA | paper learned / our TOPP-RA | + Ruckig duration (s) | + Ruckig max joint dev "
             "(rad) | learned / (+ Ruckig) | + Ruckig violations (pos / jerk) | greedy duration (s) | greedy "
             "cart. dev mean (cm) | learned / greedy | greedy violations |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    csv_rows: list[list[str]] = []
    for row in (r for r in ROWS if r.table == TABLE_I):
        pv = p6.get(row.key, [None, None, None])
        m, tp = _metrics(results, row), _toppra(results, row)
        td = None if tp is None else tp.get("toppra_duration_s")
        rel = None if (m is None or td is None) else 100.0 * td / m["duration_s"]
        dev = None if tp is None else tp.get("toppra_max_joint_dev_rad")
        ratio = "–" if rel is None else f"**{100.0 / rel:.2f}** / {_fmt(None if pv[1] is None else 100.0 / pv[1])}"
        paper_dur = dict(zip(p1["columns"], p1["rows"][row.key], strict=True))["duration_s"]
        bar = "–" if td is None else f"{paper_dur / td:.2f}"
        rk = (tp or {}).get("ruckig") or {}
        rd = rk.get("duration_s")
        rk_ratio = "–" if (m is None or rd is None) else f"**{m['duration_s'] / rd:.2f}**"
        kinds = rk.get("limit_violations_by_kind") or {}
        rk_viol = "–" if not kinds else f"{kinds.get('position', 0)} / {kinds.get('jerk', 0)}"
        g = _metrics(results, next(r for r in ROWS if r.table == TABLE_GREEDY and r.key == row.key)) or {}
        gd = g.get("duration_s")
        g_ratio = "–" if (m is None or gd is None) else f"**{m['duration_s'] / gd:.2f}**"
        lines.append(f"| {row.key} | {_cell(td, pv[0], 2)} | {_cell(rel, pv[1], 1)} | {_cell(dev, pv[2], 4)} | "
                     f"{ratio} | {bar} | {_fmt(rd)} | {_fmt(rk.get('max_dev_rad'), 3)} | {rk_ratio} | {rk_viol} | "
                     f"{_fmt(gd)} | {_fmt(g.get('cart_pos_dev_mean_cm'))} | {g_ratio} | "
                     f"{g.get('limit_violations', '–')} |")
        for name, ours, pap in (("toppra_duration_s", td, pv[0]), ("toppra_relative_duration_pct", rel, pv[1]),
                                ("toppra_max_joint_dev_rad", dev, pv[2]), ("toppra_ruckig_duration_s", rd, None),
                                ("greedy_duration_s", gd, None)):
            csv_rows.append([TABLE_VI, row.key, name, "" if ours is None else f"{ours:.6g}",
                             "" if pap is None else f"{pap:g}"])
    return lines, csv_rows


def _table_ix(results: dict[str, Any], paper: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    rows = paper[TABLE_IX]["rows"]
    lines = ["## Table IX: computation time per trajectory duration (highest over the episodes)", "",
             "One env, one torch thread, CPU time per decision: the policy, the setpoints, the valid acceleration "
             "range and state of the next decision; *with simulation* adds the 24 PyBullet steps per decision "
             "(iiwa7: plate and ball; ARMAR-4: free-standing; ARMAR-6: fixed base). The paper's figure includes "
             "its simulation (i7-8700K). The valid range runs as in training and evaluation: natively "
             "(`pathrl/native`) where it is built, else as compiled torch kernels (`limits` in each raw "
             "result); the timed pass repeats an untimed one over the same episodes.", "",
             "| row | policy + limits (%) | with simulation (%) | decision mean / max (ms) | episodes |",
             "|---|---|---|---|---|"]
    csv_rows: list[list[str]] = []
    for key, _, _ in REALTIME:
        r = results.get("realtime", {}).get(key)
        pv = rows.get(key, [None])[0]
        if r is None:
            lines.append(f"| {key} | – | – / {_fmt(pv)} | – | – |")
            ours = None
        else:
            a, b = r["policy_and_limits"], r["with_simulation"]
            ours = b["max_compute_to_duration_pct"]
            lines.append(f"| {key} | **{_fmt(a['max_compute_to_duration_pct'])}** | {_cell(ours, pv, 2)} | "
                         f"{_fmt(b['decision_ms_mean'])} / {_fmt(b['decision_ms_max'])} | {b['episodes']} |")
        csv_rows.append([TABLE_IX, key, "max_compute_to_duration_pct", "" if ours is None else f"{ours:.6g}",
                         "" if pv is None else f"{pv:g}"])
    return lines, csv_rows


def _path_change(results: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    """Table of ``results["path_change"]`` (pathrl.eval.path_change: key -> its JSON)."""
    lines = ["## Path adjustments (not in the paper: Table V's \"path adjustments: yes\", measured)", "",
             "`python -m pathrl.eval.path_change`: the deployable follower (`pathrl.deploy`) follows a whole test "
             "path; 1-4 s in, the rest of the path is replaced by a branch from the moving robot whose knots shift "
             "by a random joint offset ramped in over some arc length (gentle: 0.3 rad over 1 rad; sharp: 0.6 rad "
             "over 0.3 rad; none: the path replaced by itself, the control). *Band*: the policy's normal tracking "
             "band, the 95th percentile of its largest step deviation per path on the same test paths without a "
             "change. *Settled within 2 s*: from 2 s after the change to the end of the path every step deviation "
             "is inside the band; *settle*: the time after which it stays inside; *left the band*: changes whose "
             "deviation exceeded it at all. Two stricter readings beside it: *at the step level*, back at the 95th "
             "percentile of the step deviation on unchanged paths within 2 s after the largest excursion of the "
             "first 4 s (the path's own turns trip it too: compare with *none*); *against the control*, the same "
             "change with offset 0 (same path, time and policy) as the bound where it is higher than that level "
             "(+-0.2 s); *excess after 2 s*: how far the deviation still exceeds that bound 2-4 s after the change. "
             "TOPP-RA cannot take over a "
             "moving robot onto a new path (its start velocity must lie along the path): it brakes to rest with "
             "the jerk-limited braking law, then re-plans from rest (*from motion*: share of changes toppra could "
             "have started at the robot's speed along the branch).",
             "", "| row | episodes | re-plan (ms) mean / max | peak deviation (rad) median / p95 | band (rad) | "
             "settled within 2 s (%) | settle (s) median / p95 | left the band (%) | at the step level: settled within "
             "2 s (%) | against the control: settled within 2 s (%) | excess after 2 s (rad) median / p95 | change to "
             "rest (s) | TOPP-RA brake + re-plan (s) | learned / TOPP-RA | TOPP-RA solve (ms) | TOPP-RA from motion "
             "(%) | limit violations (learned / TOPP-RA) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    csv_rows: list[list[str]] = []
    for key, _, _ in PATH_CHANGE:
        r = results.get("path_change", {}).get(key)
        for name, v in ({} if r is None else r["variants"]).items():
            lines.append(
                f"| {key} {name} | {v['episodes']} | {_fmt(v['replan_ms_mean'], 1)} / {_fmt(v['replan_ms_max'], 1)} | "
                f"{_fmt(v['dev_peak_rad_median'], 3)} / {_fmt(v['dev_peak_rad_p95'], 3)} | "
                f"{_fmt(v.get('settle_band_rad'), 3)} | **{_fmt(v.get('settled_in_band_within_2s_pct'), 1)}** | "
                f"{_fmt(v.get('settle_in_band_s_median'), 1)} / {_fmt(v.get('settle_in_band_s_p95'), 1)} | "
                f"{_fmt(v.get('left_band_pct'), 1)} | {_fmt(v['settled_within_2s_pct'], 1)} | "
                f"{_fmt(v.get('settled_vs_control_within_2s_pct'), 1)} | "
                f"{_fmt(v.get('excess_after_2s_rad_median'), 3)} / {_fmt(v.get('excess_after_2s_rad_p95'), 3)} | "
                f"{_fmt(v['duration_after_switch_s'])} | "
                f"{_fmt(v['toppra_duration_after_switch_s'])} | {_fmt(v['learned_over_toppra'])} | "
                f"{_fmt(v['toppra_solve_ms_mean'], 1)} | {_fmt(v['toppra_from_motion_feasible_pct'], 1)} | "
                f"{v['limit_violations']} / {v['toppra_violations']} |")
            for metric in ("settled_in_band_within_2s_pct", "settled_within_2s_pct", "settled_vs_control_within_2s_pct",
                           "duration_after_switch_s", "learned_over_toppra", "limit_violations"):
                x = v.get(metric)
                csv_rows.append([TABLE_PATH_CHANGE, f"{key}/{name}", metric, "" if x is None else f"{x:.6g}", ""])
        if r is None:
            lines.append(f"| {key} |" + " – |" * 16)
    return lines, csv_rows


def _theirs(model: str) -> str:
    b = AUTHORS_BUDGETS.get(model)
    return "–" if b is None else f"{b[0]} / {b[1]:.0f}"


def _training(results: dict[str, Any]) -> list[str]:
    """Budgets of the shipped policies (``results["training"]``: model -> its summary.json)."""
    budgets = results.get("training") or {}
    if not budgets:
        return []
    lines = ["## Training budgets of the shipped policies", "",
             "From `models/<family>/<policy>/summary.json`; wall time on the 2-core reference machine, not always "
             "idle (a "
             "warm-started policy's budget excludes its source's). The authors' budget from their checkpoints' "
             "metadata.", "",
             "| policy | trained by | iterations | env steps (M) | envs | wall time (min) | warm start from | "
             "authors: env steps (M) / wall time (h) |",
             "|---|---|---|---|---|---|---|---|"]
    for model, sm in budgets.items():
        if sm.get("controller"):  # a model-based controller: nothing trained
            continue
        steps = sm.get("env_steps")
        wall = sm.get("wall_time_s")
        lines.append(f"| {model} | {sm.get('method', '–')} | {sm.get('iterations', '–')} | "
                     f"{_fmt(None if steps is None else steps / 1e6, 1)} | "
                     f"{sm.get('num_envs', '–')} | {_fmt(None if wall is None else wall / 60.0, 0)} | "
                     f"{WARM_STARTS.get(model, '–')} | {_theirs(model)} |")
    return lines


def _table_v(paper: dict[str, Any]) -> list[str]:
    lines = ["## Table V: features (TOPP-RA vs learned)", "", "| feature | TOPP-RA | ours |", "|---|---|---|"]
    for k, (a, b) in paper[TABLE_V]["rows"].items():
        lines.append(f"| {k.replace('_', ' ')} | {'yes' if a else 'no'} | {'yes' if b else 'no'} |")
    return lines


def render_markdown(results: dict[str, Any], paper: dict[str, Any], profile: str) -> tuple[str, list[list[str]]]:
    """`results/tables.md` text and the CSV rows (table, row, metric, ours, paper)."""
    lines = [f"# pathrl: the paper's tables reproduced (profile `{profile}`)", "",
             "Each cell: **ours** / paper (ours / paper). Episodes: random segments of the project's test split "
             "(start U(0, 0.8), end U(start + 0.2, 1) moved forward to a knot; whole paths for ball balancing), "
             "fixed seed; the deterministic policy and TOPP-RA see the same segments. *Time-outs*: the share of "
             "episodes that ended on the episode's time limit instead of at rest at the end of the path; their "
             "duration is the time limit and their deviation that of an unfinished attempt, so a row with many "
             "does not describe finished paths. A dash: no shipped policy for that row yet.", ""]
    csv_rows = [["table", "row", "metric", "ours", "paper"]]
    for table in (TABLE_I, TABLE_I_TEST2, TABLE_II, TABLE_III, TABLE_IV, TABLE_VII, TABLE_VIII):
        body, rows = _learned_table(results, paper, table)
        lines += body + [""]
        csv_rows += rows
    body, rows = _table_vi(results, paper)
    lines += body + [""] + _table_v(paper)
    csv_rows += rows
    body, rows = _table_ix(results, paper)
    lines += [""] + body
    csv_rows += rows
    body, rows = _path_change(results)
    lines += [""] + body
    csv_rows += rows
    body, rows = trueadapt.markdown(results)
    lines += [""] + body + trueadapt_findings.markdown(results)
    csv_rows += rows
    training = _training(results)
    if training:
        lines += [""] + training
    missing = sorted({r.evaluation.model for r in ROWS if _metrics(results, r) is None})
    if missing:
        lines += ["", "Policies not shipped yet (train with `make reproduce-tables TRAIN=1` or "
                  "`pathrl-train +experiment=NAME`): " + ", ".join(missing) + "."]
    return "\n".join(lines) + "\n", csv_rows


def _tex_escape(s: str) -> str:
    return s.replace("_", r"\_")


def render_latex(results: dict[str, Any], paper: dict[str, Any]) -> str:
    """Tables I-IV as booktabs tabulars, cells `ours (paper)`."""
    out = ["% generated by tools/reproduce_tables.py; cells: ours (paper)"]
    for table in (TABLE_I, TABLE_II, TABLE_III, TABLE_IV, TABLE_VII, TABLE_VIII):
        cols, pcols = _columns(paper, table), paper[table]["columns"]
        out += [f"% {TITLES[table]}", r"\begin{tabular}{l" + "r" * len(cols) + "}", r"\toprule",
                "row & " + " & ".join(_tex_escape(c) for c in cols) + r" \\", r"\midrule"]
        for row in (r for r in ROWS if r.table == table):
            p = dict(zip(pcols, paper[table]["rows"].get(row.key, []), strict=False))
            m = _metrics(results, row)
            cells = []
            for c in cols:
                ours = "--" if m is None else _fmt(m.get(c), _nd(c))
                cells.append(f"{ours} ({_fmt(p.get(c), _nd(c))})" if c in p else ours)
            out.append(_tex_escape(row.key) + " & " + " & ".join(cells) + r" \\")
        out += [r"\bottomrule", r"\end{tabular}", ""]
    out += trueadapt.latex(results)
    return "\n".join(out)
