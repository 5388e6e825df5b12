"""Which of the TrueAdapt paper's findings (on plate; in place, the open-loop rows) our rows reproduce: each
ablation's value over its full policy's, classed the same way for the paper and for ours (trained from scratch, and
from a teacher). Rendered under the TrueAdapt table (:mod:`pathrl.repro.trueadapt`) from the same results."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pathrl.repro.trueadapt import COLUMNS, ROWS, ours, paper, row_values

__all__ = ["FINDINGS", "Finding", "markdown", "outcome"]


@dataclass(frozen=True)
class Finding:
    """One of the paper's findings: row `key`'s `column` against the full policy's of its task (``<task>/test_set``;
    the ratio ablation / full classed by :func:`outcome`), checked on our rows trained from scratch (`scratch`,
    against ``<task>/test_set_scratch``) and from a teacher (`teacher`, against `teacher_full`, by default
    ``<task>/test_set``); None: no such row of ours."""

    key: str
    column: str
    scratch: str | None
    teacher: str | None
    teacher_full: str | None = None

    @property
    def full(self) -> str:
        """The paper's full policy of the finding's task (``<task>/test_set``)."""
        return f"{self.key.split('/')[0]}/test_set"


#: The findings, in the table's order: success for the state and open-loop ablations, the penalised quantity (and
#: success) for the penalty ablations.
FINDINGS: tuple[Finding, ...] = (
    Finding("on_plate/open_loop_evaluation", "success_pct", "on_plate/open_loop_evaluation_scratch",
            "on_plate/open_loop_evaluation"),
    Finding("on_plate/open_loop_training", "success_pct", "on_plate/open_loop_training_scratch",
            "on_plate/open_loop_training"),
    Finding("on_plate/no_current_position", "success_pct", "on_plate/no_current_position_scratch",
            "on_plate/no_current_position"),
    Finding("on_plate/no_current_velocity", "success_pct", "on_plate/no_current_velocity_scratch",
            "on_plate/no_current_velocity"),
    Finding("on_plate/no_current_acceleration", "success_pct", "on_plate/no_current_acceleration_scratch",
            "on_plate/no_current_acceleration"),
    Finding("on_plate/no_following_positions", "success_pct", "on_plate/no_following_positions_scratch",
            "on_plate/no_following_positions"),
    Finding("on_plate/ten_following_positions", "success_pct", "on_plate/ten_following_positions_scratch",
            "on_plate/ten_following_positions"),
    Finding("on_plate/no_jerk_penalty", "success_pct", "on_plate/no_jerk_penalty_scratch",
            "on_plate/no_jerk_penalty", "on_plate/test_set_ppo"),
    Finding("on_plate/no_jerk_penalty", "jerk_pct", "on_plate/no_jerk_penalty_scratch", "on_plate/no_jerk_penalty",
            "on_plate/test_set_ppo"),
    Finding("on_plate/no_acceleration_penalty", "success_pct", "on_plate/no_acceleration_penalty_scratch",
            "on_plate/no_acceleration_penalty", "on_plate/test_set_ppo"),
    Finding("on_plate/no_acceleration_penalty", "acc_pct", "on_plate/no_acceleration_penalty_scratch",
            "on_plate/no_acceleration_penalty", "on_plate/test_set_ppo"),
    Finding("in_place/open_loop_evaluation", "success_pct", "in_place/open_loop_evaluation_scratch",
            "in_place/open_loop_evaluation"),
    Finding("in_place/open_loop_training", "success_pct", "in_place/open_loop_training_scratch",
            "in_place/open_loop_training"),
)


#: The table's rows by key.
_BY_KEY = {r.key: r for r in ROWS}


def outcome(ratio: float, column: str) -> str:
    """The class of an ablation's value over the full policy's: success ``fails`` (< 0.25), ``partly`` (< 0.9) or
    ``keeps``; a penalised quantity (|acc|, |jerk|) ``rises`` (> 2x) or ``stays``."""
    if column != "success_pct":
        return "rises" if ratio > 2.0 else "stays"
    return "fails" if ratio < 0.25 else "partly" if ratio < 0.9 else "keeps"


def _ours_ratio(results: dict[str, Any], key: str | None, full: str, column: str) -> tuple[float, float] | None:
    """(ablation, full) values of ours for row keys `key` and `full`, or None if either has no result."""
    if key is None:
        return None
    a, b = (ours(row_values(results, _BY_KEY[k])[0], column) for k in (key, full))
    return None if a is None or b is None or b == 0 else (a, b)


def _finding_cells(pair: tuple[float, float] | None, column: str, paper_class: str) -> list[str]:
    """'value / full (class)' and whether the class is the paper's, or dashes."""
    if pair is None:
        return ["–", "–"]
    cls = outcome(pair[0] / pair[1], column)
    return [f"{pair[0]:.1f} / {pair[1]:.1f} ({cls})", "yes" if cls == paper_class else "**no**"]


def markdown(results: dict[str, Any]) -> list[str]:
    """Which of the paper's findings our rows reproduce, from scratch and from a teacher: the ablation's value
    over the full policy's, classed the same way for the paper and for us."""
    p = paper()
    idx = {c: i for i, c in enumerate(p["columns"])}
    names = dict(zip(COLUMNS, ("success", "fraction", "error distance", "\\|acc\\|", "\\|jerk\\|"), strict=True))
    lines = ["", "Which of the paper's findings hold here (on plate; in place, the open-loop rows). Each cell: the "
             "ablation's value / the full policy's (%), and its class: success *fails* below 0.25x the full "
             "policy's, *partly* below 0.9x, else *keeps*; a penalised quantity *rises* above 2x, else *stays*. "
             "The full policies: the paper's; ours from scratch (`iiwa7_trueadapt_<task>_ppo_scratch`, seed 0); "
             "ours from a teacher (the distilled policy; for the penalties the distilled policy + PPO, whose runs "
             "drop the penalty). Same class as the paper: *yes*.",
             "", "| the paper's setting | value | paper | from scratch | same | from a teacher | same |",
             "|---|---|---|---|---|---|---|"]
    for f in FINDINGS:
        full = p["rows"][f.full][idx[f.column]]
        value = p["rows"][f.key][idx[f.column]]
        cls = outcome(value / full, f.column)
        teacher_full = f.teacher_full or f.full
        cells = (_finding_cells(_ours_ratio(results, f.scratch, f"{f.full}_scratch", f.column), f.column, cls)
                 + _finding_cells(_ours_ratio(results, f.teacher, teacher_full, f.column), f.column, cls))
        lines.append(f"| {_BY_KEY[f.key].setting} | {names[f.column]} | {value:.1f} / {full:.1f} ({cls}) | "
                     + " | ".join(cells) + " |")
    return lines
