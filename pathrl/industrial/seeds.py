"""Several training seeds per configuration: their per-seed results on the evaluation rows, the mean and
min-max over seeds, and a validation set from the training family on which a seed may be chosen.

The evaluation rows of Table II are never used to choose a policy. A choice among seeds is made on
:func:`validation_targets`: random type-1 curves from the training generator
(:func:`pathrl.industrial.trajectories.type1_random`) with seeds ``VALIDATION_BASE + 1000 * seed + i``, which no
training run with ``rl.seed < VALIDATION_BASE / 1000 - 1`` draws (training uses ``1000 * (seed + 1) + i``,
``i < n_train <= 1000``), in poses 1-3 at the training speed commands. The criterion (:func:`validation_score`)
is the mean number of iterations to 0.5 mm with a trajectory that never reaches it counted as ``k_max + 1``,
ties broken by the mean best error.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from pathrl.industrial.controller import ControllerParams
from pathrl.industrial.iwa_env import IWAEpisode, IWASettings
from pathrl.industrial.rl import run_policy_iwa
from pathrl.industrial.rl_train import POSE_SPEEDS
from pathrl.industrial.tables import Table2Row, ratios
from pathrl.industrial.timing import (
    PAPER_EXECUTION_S,
    PAPER_MPGD_DECISION_S,
    PAPER_POLICY_DECISION_S,
    RowTiming,
    model_ratio,
)
from pathrl.industrial.trajectories import Target, type1, type1_random

__all__ = [
    "RowResult", "SeedSummary", "VALIDATION_BASE", "parse_runs", "run_policy_rows", "seed_table_markdown", "spread",
    "summarise", "validation_markdown", "validation_score", "validation_targets",
]

#: First seed of the validation curves; far above the training seeds 1000 * (seed + 1) + i.
VALIDATION_BASE = 10_000_000

Policy = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class RowResult:
    """One policy on one trajectory: best max error (mm), iterations to 0.5 mm (None = not reached), executions
    and wall time (s)."""

    name: str
    err_mm: float
    itr: int | None
    executions: int
    t_opt: float


def validation_targets(n: int, seed: int = 0) -> list[Target]:
    """`n` type-1 curves of the training family that no training run uses (module doc), poses 1-3 in turn."""
    if n < 1 or n > 1000:
        raise ValueError(f"validation.n must be in 1..1000, got {n}")
    out = []
    for i in range(n):
        pose = 1 + i % 3
        p, rot = type1(type1_random(VALIDATION_BASE + 1000 * seed + i), pose)
        out.append(Target(f"val{i}", p, rot, pose, "L", POSE_SPEEDS[pose]))
    return out


def run_policy_rows(targets: Sequence[Target], policy: Policy, controller: ControllerParams, waypoints: int = 100,
                    zone: float = 10.0, k_max: int = 10) -> list[RowResult]:
    """The learned IWA of `policy` on each target at its speed command."""
    out = []
    for t in targets:
        res = run_policy_iwa(IWAEpisode(t, t.speed, controller, IWASettings(waypoints, zone, k_max)), policy)
        out.append(RowResult(t.name, res.errors.max_pos_mm, res.iterations_to_spec, res.executions, res.t_opt))
    return out


def validation_score(results: Sequence[RowResult], k_max: int) -> tuple[float, float]:
    """(mean iterations to 0.5 mm counting a miss as k_max + 1, mean best error mm): lower is better."""
    itr = [r.itr if r.itr is not None else k_max + 1 for r in results]
    return float(np.mean(itr)), float(np.mean([r.err_mm for r in results]))


@dataclass(frozen=True)
class SeedSummary:
    """One seed on the evaluation rows: rows at 0.5 mm, mean iterations over them (nan if none), and MPGD /
    policy iterations and t_opt on the rows both reach (nan if none; :func:`pathrl.industrial.tables.ratios`);
    `model_ratio` is the t_opt ratio the executions counted here would give at the paper's costs (a model:
    :func:`pathrl.industrial.timing.model_ratio` with 12 s per execution, 60.86 s per MPGD and 0.004 s per policy
    decision)."""

    name: str
    reached: int
    rows: int
    mean_itr: float
    itr_ratio: float
    t_ratio: float
    model_ratio: float = math.nan


def summarise(name: str, results: Sequence[RowResult], mpgd_rows: Sequence[Table2Row] | None = None) -> SeedSummary:
    """A seed's summary; the ratios against MPGD's rows (same targets, same order) if given, else nan."""
    itrs = [r.itr for r in results if r.itr is not None]
    rat, model = None, math.nan
    if mpgd_rows is not None:
        pairs = list(zip(mpgd_rows, results, strict=True))
        rat = ratios([replace(m, rl_mm=r.err_mm, rl_itr=r.itr, rl_t=r.t_opt) for m, r in pairs])
        counts = [RowTiming(r.name, m.mpgd_itr, m.executions, r.itr, r.executions, [], [], [], [], [])
                  for m, r in pairs]
        model = model_ratio(counts, PAPER_EXECUTION_S, 0.0, PAPER_MPGD_DECISION_S, PAPER_POLICY_DECISION_S)
    return SeedSummary(name, len(itrs), len(results), float(np.mean(itrs)) if itrs else math.nan,
                       rat[1] if rat else math.nan, rat[2] if rat else math.nan, model)


def spread(values: Sequence[float], fmt: str) -> str:
    """'mean (min-max)' of the finite values ('N/A' if none; just the value if there is one)."""
    v = [x for x in values if math.isfinite(x)]
    if not v:
        return "N/A"
    if len(v) == 1:
        return format(v[0], fmt)
    return f"{format(float(np.mean(v)), fmt)} ({format(min(v), fmt)}-{format(max(v), fmt)})"


def seed_table_markdown(summaries: dict[str, list[SeedSummary]], with_ratios: bool = True) -> list[str]:
    """Markdown lines: per configuration, one line per seed and one 'mean (min-max)' line over its seeds."""
    cols = ["configuration", "seed run", "rows at 0.5 mm", "mean iterations"]
    cols += ["MPGD / policy iterations", "MPGD / policy t_opt", "t_opt at the paper's costs (model)"] \
        if with_ratios else []
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for config, seeds in summaries.items():
        for s in seeds:
            cells = [config, s.name, f"{s.reached}/{s.rows}", spread([s.mean_itr], ".1f")]
            cells += [spread([x], ".1f") + "x" for x in (s.itr_ratio, s.t_ratio, s.model_ratio)] if with_ratios else []
            lines.append("| " + " | ".join(cells) + " |")
        if len(seeds) > 1:
            cells = [f"**{config}**", f"**mean (min-max) of {len(seeds)} seeds**",
                     spread([s.reached for s in seeds], ".1f") + f" /{seeds[0].rows}",
                     spread([s.mean_itr for s in seeds], ".1f")]
            if with_ratios:
                cells += [spread([getattr(s, k) for s in seeds], ".1f") + "x"
                          for k in ("itr_ratio", "t_ratio", "model_ratio")]
            lines.append("| " + " | ".join(cells) + " |")
    return lines


def parse_runs(entries: Sequence[str]) -> dict[str, list[str]]:
    """``NAME=RUN_DIR[,RUN_DIR...]`` entries -> {name: run dirs}; ValueError on a malformed or repeated entry."""
    out: dict[str, list[str]] = {}
    for entry in entries:
        name, sep, dirs = str(entry).partition("=")
        runs = [d.strip() for d in dirs.split(",") if d.strip()]
        if not sep or not name.strip() or not runs:
            raise ValueError(f"expected NAME=RUN_DIR[,RUN_DIR...], got {entry!r}")
        if name.strip() in out:
            raise ValueError(f"repeated name {name.strip()!r} in {entry!r}")
        out[name.strip()] = runs
    if not out:
        raise ValueError("expected a non-empty list of NAME=RUN_DIR[,RUN_DIR...] entries")
    return out


def validation_markdown(results: dict[str, list[RowResult]], k_max: int, command: str, n: int, seed: int) -> str:
    """The validation table (one line per run) and the run the criterion selects."""
    lines = ["| run | reached 0.5 mm | mean iterations (miss = k_max + 1) | mean best error (mm) |",
             "|---|---|---|---|"]
    scores = {}
    for name, res in results.items():
        scores[name] = validation_score(res, k_max)
        reached = sum(r.itr is not None for r in res)
        lines.append(f"| {name} | {reached}/{len(res)} | {scores[name][0]:.2f} | {scores[name][1]:.3f} |")
    best = min(scores, key=lambda k: scores[k])
    return "\n".join([
        "# Industrial motion-profile optimisation: validation of policies (choosing a seed)", "",
        f"Measured with `{command}`.", "",
        f"Validation set: {n} random type-1 trajectories of the training family (`type1_random` seeds "
        f"{VALIDATION_BASE + 1000 * seed}..{VALIDATION_BASE + 1000 * seed + n - 1}, never drawn by training), poses "
        "1-3 at 250 / 400 / 400 mm/s, k_max = " + f"{k_max}. None of the Table II evaluation rows is used.", "",
        *lines, "",
        f"Criterion: lowest mean iterations to 0.5 mm (a miss counts {k_max + 1}), ties by mean best error. "
        f"Selected: **{best}**.", ""])
