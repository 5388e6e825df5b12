"""Seed aggregates, the validation set and the t_opt timing model of the motion-profile task (issue 21):
hand-computed summaries and ratios, and small smoke runs with fixed error-feedback policies."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pathrl.industrial.controller import ControllerParams
from pathrl.industrial.mpgd import MPGDParams
from pathrl.industrial.rl_train import POSE_SPEEDS
from pathrl.industrial.seeds import (
    VALIDATION_BASE,
    RowResult,
    parse_runs,
    run_policy_rows,
    seed_table_markdown,
    spread,
    summarise,
    validation_markdown,
    validation_score,
    validation_targets,
)
from pathrl.industrial.tables import Table2Row
from pathrl.industrial.timing import RowTiming, model_ratio, paper_per_iteration, time_row, timing_markdown
from pathrl.industrial.trajectories import evaluation_targets

pytest.importorskip("torchrl")


def feedback(gain: float):
    return lambda obs: np.tile([gain, 0.0, 0.0], (len(obs), 1))


def test_spread_is_mean_and_range_of_the_finite_values():
    assert spread([1.0, 2.0, 6.0], ".1f") == "3.0 (1.0-6.0)"
    assert spread([2.0, math.nan], ".2f") == "2.00"
    assert spread([math.nan], ".1f") == "N/A"


def test_parse_runs_splits_seeds_and_rejects_bad_entries():
    assert parse_runs(["RL=a, b", "RL-e=c"]) == {"RL": ["a", "b"], "RL-e": ["c"]}
    for bad in (["a"], ["RL="], ["=a"], ["RL=a", "RL=b"], []):
        with pytest.raises(ValueError):
            parse_runs(bad)


def test_validation_score_counts_a_miss_as_k_max_plus_one():
    res = [RowResult("a", 0.4, 1, 2, 0.1), RowResult("b", 0.9, None, 11, 1.0), RowResult("c", 0.2, 3, 4, 0.2)]
    itr, err = validation_score(res, k_max=10)
    assert itr == pytest.approx((1 + 11 + 3) / 3)
    assert err == pytest.approx(0.5)


def test_summary_ratios_are_summed_over_rows_both_reach():
    mpgd = [Table2Row(n, 1, 250.0, 2.0, 0.4, itr, t, ex) for n, itr, t, ex in
            (("a", 4, 1.0, 5), ("b", 6, 2.0, 7), ("c", None, 3.0, 51))]
    rl = [RowResult("a", 0.3, 1, 2, 0.5), RowResult("b", 0.3, 2, 3, 0.5), RowResult("c", 0.3, 1, 2, 0.5)]
    s = summarise("seed", rl, mpgd)
    assert (s.reached, s.rows) == (3, 3)
    assert s.mean_itr == pytest.approx(4 / 3)
    assert s.itr_ratio == pytest.approx(10 / 3)  # rows a, b: (4 + 6) / (1 + 2)
    assert s.t_ratio == pytest.approx(3.0)  # (1 + 2) / (0.5 + 0.5)
    # paper's costs: MPGD (5 + 7) x 12 s + (4 + 6) x 60.86 s; policy (2 + 3) x (12 + 0.004) s
    assert s.model_ratio == pytest.approx((12 * 12 + 10 * 60.86) / (5 * 12.004))
    assert math.isnan(summarise("seed", rl).itr_ratio)
    lines = seed_table_markdown({"cfg": [s, summarise("other", rl[:1] + [RowResult("b", 0.6, None, 11, 1.0)] + rl[2:],
                                                       mpgd)]})
    assert "mean (min-max) of 2 seeds" in lines[-1]
    assert "2.5 (2.0-3.0) /3" in lines[-1]


def test_validation_curves_are_the_training_family_and_never_trained_on():
    targets = validation_targets(4, seed=0)
    assert [t.pose for t in targets] == [1, 2, 3, 1]
    assert [t.speed for t in targets] == [POSE_SPEEDS[p] for p in (1, 2, 3, 1)]
    train = {1000 * (s + 1) + i for s in range(100) for i in range(1000)}  # rl.seed < 100, n_train <= 1000
    assert not train & {VALIDATION_BASE + 1000 * s + i for s in range(10) for i in range(1000)}
    with pytest.raises(ValueError):
        validation_targets(0)


def test_validation_selects_the_better_policy():
    targets = validation_targets(2, seed=0)
    ctrl = ControllerParams()
    results = {name: run_policy_rows(targets, feedback(g), ctrl, k_max=2) for name, g in (("zero", 0.0), ("ef", 1.0))}
    assert all(r.itr is None for r in results["zero"])  # no move, no improvement
    text = validation_markdown(results, 2, "cmd", 2, 0)
    assert "Selected: **ef**" in text


def test_model_ratio_is_hand_computed():
    rows = [RowTiming("a", 3, 4, 1, 2, [], [], [], [], []), RowTiming("b", None, 51, 1, 2, [], [], [], [], [])]
    # row a only: MPGD 4 executions x (2 + 0) + 3 updates x 1 = 11; policy 2 executions x (2 + 0 + 0.5) = 5
    assert model_ratio(rows, 2.0, 0.0, 1.0, 0.5) == pytest.approx(11 / 5)
    assert model_ratio(rows, 1.0, 0.0, 0.0, 0.0) == pytest.approx(2.0)
    # without the baseline execution: MPGD 3 x 2 + 3 x 1 = 9; policy 1 x 2.5
    assert model_ratio(rows, 2.0, 0.0, 1.0, 0.5, baseline=False) == pytest.approx(9 / 2.5)
    mpgd, rl = paper_per_iteration()  # the paper's Table II, rows both reach: 1764.87 s / 44, 95.75 s / 10
    assert mpgd == pytest.approx(1764.87 / 44)
    assert rl == pytest.approx(95.75 / 10)


def test_time_row_times_every_execution_and_decision():
    target = next(t for t in evaluation_targets() if t.name == "Type 1 Easy")
    row = time_row(target, ControllerParams(), MPGDParams(), feedback(1.0))
    assert row.mpgd_itr is not None and row.rl_itr is not None
    assert row.mpgd_exec == row.mpgd_itr + 1 and row.rl_exec == row.rl_itr + 1
    assert len(row.t_execute) == len(row.t_measure) == row.mpgd_exec
    assert len(row.t_mpgd) == row.mpgd_exec - 1
    assert len(row.t_features) == row.rl_exec and len(row.t_act) == row.rl_exec - 1
    assert min(row.t_execute + row.t_mpgd + row.t_features + row.t_act) > 0
    text = timing_markdown([row], "cmd")
    assert "a model, not a measurement" in text and "Type 1 Easy" in text


def test_cli_table4_summarises_several_runs_per_variant(tmp_path):
    from pathrl.cli.industrial import main

    out = tmp_path / "t4.md"
    code = main(["table4", 'table4_runs=["EF=feedback:1.0,feedback:0.5"]', 'rows=["Type 1 Easy"]',
                 f"out_table4={out}"])
    assert code == 0
    text = out.read_text()
    assert "| EF | feedback:0.5 | 1/1 |" in text and "mean (min-max) of 2 seeds" in text
    assert main(["table4", "table4_runs=[EF=feedback:1.0,feedback:0.5]", f"out_table4={out}"]) == 2
