"""Reproduction pipeline: table definitions, the renderer (golden files), figures and a quick-profile run."""

from __future__ import annotations

import csv
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pathrl.config.paper import load as load_paper
from pathrl.models import model_dir, model_path
from pathrl.repro.figures import pareto_table_ii
from pathrl.repro.render import render_latex, render_markdown
from pathrl.repro.tables import (
    CONTROLLER_MODELS,
    NOT_IN_PAPER,
    OURS_ONLY,
    PAPER_TABLE,
    ROWS,
    TABLE_I,
    TABLE_I_TEST2,
    baselines,
    evaluations,
    training_method,
    training_record,
)

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = Path(__file__).parent / "golden"
PAPER = load_paper("tracking").as_dict()
METRICS = ["duration_s", "joint_dev_mean_rad", "joint_dev_max_rad", "joint_dev_final_rad", "cart_pos_dev_mean_cm",
           "cart_pos_dev_max_cm", "cart_pos_dev_final_cm", "cart_rot_dev_mean_deg", "cart_rot_dev_max_deg",
           "cart_rot_dev_final_deg"]


def synthetic_results() -> dict:
    """Fixed numbers for some rows (others missing): every branch of the renderer."""
    evs = {}
    for i, e in enumerate(evaluations()):
        if e.model in ("iiwa7_random_track_distill", "iiwa7_random", "iiwa7_random_length_eq_deviation",
                       "armar4_random"):
            m = {k: round(1.0 + 0.25 * i + 0.01 * j, 4) for j, k in enumerate(METRICS)}
            evs[e.id] = {**m, "episodes": 1200, "limit_violations": 0}
        if e.model == "greedy_iiwa7_random":
            evs[e.id] = {"duration_s": 5.0, "cart_pos_dev_mean_cm": 6.0, "episodes": 1200, "limit_violations": 0}
        if e.task:  # Table VII: one row reached the path end, the other never did (no duration)
            m = {k: 0.5 + 0.01 * j for j, k in enumerate(METRICS)}
            reached = "_reward" in e.model
            evs[e.id] = {**m, "episodes": 200, "limit_violations": 0, "ball_fell_pct": 0.5 if reached else 100.0,
                         "duration_end_of_path_s": 2.5 if reached else None}
    bases = {b.id: {"toppra_duration_s": 2.5 + 0.1 * i, "toppra_max_joint_dev_rad": 1e-4}
             for i, b in enumerate(baselines()) if b.robot != "armar6"}
    bases["toppra_iiwa7_random_paper"]["ruckig"] = {"duration_s": 3.2, "max_dev_rad": 0.125,
                                                   "limit_violations_by_kind": {"position": 0, "jerk": 0}}
    one = {"max_compute_to_duration_pct": 6.25, "decision_ms_mean": 5.0, "decision_ms_max": 12.5, "episodes": 50}
    realtime = {"iiwa7": {"policy_and_limits": one, "with_simulation": {**one, "max_compute_to_duration_pct": 8.5}}}
    training = {"iiwa7_random": {"iterations": 600, "env_steps": 39321600, "num_envs": 4096, "wall_time_s": 1620.0,
                                 "method": "PPO"},
                "iiwa7_ball_balancing_reward": {"iterations": 900},  # a summary without steps / wall time
                "iiwa7_random_track_distill": {"iterations": 1500, "method": "DAgger from law_tracker"}}
    variant = {"episodes": 200, "replan_ms_mean": 7.25, "replan_ms_max": 18.0, "dev_peak_rad_median": 0.175,
               "dev_peak_rad_p95": 0.25, "settled_within_2s_pct": 97.5, "settle_s_median": 0.0, "settle_s_p95": 1.5,
               "duration_after_switch_s": 7.0, "toppra_duration_after_switch_s": 5.6, "learned_over_toppra": 1.25,
               "toppra_solve_ms_mean": 50.0, "toppra_from_motion_feasible_pct": 90.0, "limit_violations": 0,
               "toppra_violations": 0, "settled_vs_control_within_2s_pct": 98.5, "excess_after_2s_rad_median": 0.0,
               "excess_after_2s_rad_p95": 0.0125, "settle_band_rad": 0.25, "settled_in_band_within_2s_pct": 99.0,
               "settle_in_band_s_median": 0.0, "settle_in_band_s_p95": 0.5, "left_band_pct": 7.5}
    none = {k: v for k, v in variant.items() if "control" not in k and "excess" not in k}
    older = {k: v for k, v in variant.items() if "band" not in k}  # a result written before the band columns
    path_change = {"iiwa7/random": {"variants": {"none": none, "gentle": variant, "sharp": older}}}
    return {"evaluations": evs, "baselines": bases, "realtime": realtime, "training": training,
            "path_change": path_change}


def check_golden(name: str, text: str) -> None:
    path = GOLDEN / name
    if os.environ.get("UPDATE_GOLDEN"):
        path.write_text(text)
    assert path.read_text() == text, f"{name} changed; rerun with UPDATE_GOLDEN=1 if intended"


def test_rows_match_paper_tables_and_experiments():
    for r in ROWS:
        if r.table in OURS_ONLY:
            assert r.evaluation.model in CONTROLLER_MODELS
        else:
            assert (r.key in PAPER[PAPER_TABLE.get(r.table, r.table)]["rows"]) != ((r.table, r.key) in NOT_IN_PAPER)
        if r.evaluation.model in CONTROLLER_MODELS:
            assert "controller" in yaml.safe_load((model_dir(r.evaluation.model) / "config.yaml").read_text())
        elif not r.evaluation.generalization and r.table not in OURS_ONLY:
            assert (ROOT / "conf" / "experiment" / f"{r.evaluation.model}.yaml").is_file(), r.evaluation.model
    assert {r.key for r in ROWS if r.table == TABLE_I} == set(PAPER[TABLE_I]["rows"])
    # every Table I row on a second test split of its own
    assert {r.key for r in ROWS if r.table == TABLE_I_TEST2} == set(PAPER[TABLE_I]["rows"])
    assert all((ROOT / "datasets" / r.evaluation.data_robot / r.evaluation.test_dir / "test.npz").is_file()
               for r in ROWS if r.table == TABLE_I_TEST2)
    # knots 5 / 7 / 9 share knot positions, so Tables II / III / I share one TOPP-RA run per dataset (6), plus
    # one per second test split (6)
    assert len(baselines()) == 12


def test_renderer_golden_markdown_csv_latex():
    res = synthetic_results()
    md, rows = render_markdown(res, PAPER, "full")
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    check_golden("tables.md", md)
    check_golden("tables.csv", buf.getvalue())
    check_golden("tables.tex", render_latex(res, PAPER))


def test_renderer_hand_checked_cells():
    res = synthetic_results()
    md, rows = render_markdown(res, PAPER, "full")
    m = res["evaluations"]["iiwa7_random_track_distill"]
    # Table I iiwa7/random duration: ours / paper (ratio)
    assert f"**{m['duration_s']:.2f}** / 4.28 ({m['duration_s'] / 4.28:.2f})" in md
    tp = res["baselines"]["toppra_iiwa7_random_paper"]["toppra_duration_s"]
    assert f"| {m['duration_s'] / tp:.2f} |" in md  # learned / TOPP-RA
    assert f"{4.28 / tp:.2f} |" in md  # paper learned / our TOPP-RA
    assert "| armar6/random | – / 4.98" in md  # row without a policy: dash and the paper value
    csv_ours = {(r[0], r[1], r[2]): r[3] for r in rows[1:]}
    assert float(csv_ours[(TABLE_I, "iiwa7/random", "duration_s")]) == pytest.approx(m["duration_s"])
    assert csv_ours[(TABLE_I, "armar6/random", "duration_s")] == ""
    # path adjustments: a measured row, a result without the band columns (dashes), a robot without results
    assert ("| iiwa7/random gentle | 200 | 7.2 / 18.0 | 0.175 / 0.250 | 0.250 | **99.0** | 0.0 / 0.5 | 7.5 | 97.5 | "
            "98.5 | 0.000 / 0.013 | 7.00 | 5.60 | 1.25 | 50.0 | 90.0 | 0 / 0 |") in md
    assert "| 7.5 | 97.5 | – | – / – | 7.00 |" in md  # the control has no paired columns
    assert "| 0.175 / 0.250 | – | **–** | – / – | – | 97.5 | 98.5 |" in md and "| armar6/random | – |" in md
    # every learned table says how each row's policy was trained (a dash without a record); no episode records: no
    # time-out share (a dash)
    table_i = md.split("## Table I: tracking without sensory feedback")[1].split("##")[0]
    table_ii = md.split("## Table II:")[1].split("##")[0]
    assert "| 1200 | – | 0 | DAgger from law_tracker |" in table_i and "| 1200 | – | 0 | PPO |" in table_ii
    assert "| 1200 | – | 0 | – |" in md  # armar4_random (Table IV): evaluated, no training record
    # budgets: how each policy was trained (a dash for a summary without a config beside it)
    assert "| iiwa7_random | PPO | 600 | 39.3 | 4096 | 27 |" in md and "| iiwa7_ball_balancing_reward | – | 900 |" in md
    # Table VI's Ruckig and greedy columns: duration, deviation, learned / baseline, violations
    assert (f"| 3.20 | 0.125 | **{m['duration_s'] / 3.2:.2f}** | 0 / 0 | 5.00 | 6.00 | "
            f"**{m['duration_s'] / 5.0:.2f}** | 0 |") in md


def test_pareto_plot(tmp_path):
    res = synthetic_results()
    assert pareto_table_ii(res, PAPER, tmp_path / "p.png")
    assert (tmp_path / "p.png").stat().st_size > 10_000
    assert not pareto_table_ii({"evaluations": {}, "baselines": {}}, PAPER, tmp_path / "none.png")
    assert not (tmp_path / "none.png").exists()


def test_unknown_only_is_a_one_line_error():
    r = subprocess.run([sys.executable, "tools/reproduce_tables.py", "--only", "nope"], cwd=ROOT,
                       capture_output=True, text=True)
    assert r.returncode != 0 and "unknown model" in r.stderr and len(r.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_quick_profile_trains_evaluates_and_renders(tmp_path):
    """`make reproduce-tables PROFILE=quick TRAIN=1` on three rows: tiny datasets, tiny training, every output."""
    out = tmp_path / "quick"
    only = "iiwa7_random_track_distill,iiwa7_random_length_eq_deviation,iiwa7_ball_balancing_reward"
    r = subprocess.run([sys.executable, "tools/reproduce_tables.py", "--profile", "quick", "--train", "--only", only,
                        "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    md = (out / "tables.md").read_text()
    m = json.loads((out / "raw" / "iiwa7_random_track_distill" / "metrics.json").read_text())
    assert m["episodes"] == 12 and m["limit_violations"] == 0
    assert f"**{m['duration_s']:.2f}** / 4.28" in md and "| DAgger from law_tracker |" in md
    # a distilled student (its teacher builds each tiny path's law), a PPO policy, and a warm start: the ball
    # reward row starts from iiwa7_ball_balancing, which is trained and shipped first
    for model in ("iiwa7_random_track_distill", "iiwa7_random_length_eq_deviation", "iiwa7_ball_balancing",
                  "iiwa7_ball_balancing_reward"):
        assert (model_path(model, out / "models") / "model.pt").is_file(), model
    assert (out / "raw" / "toppra_iiwa7_random_paper.json").is_file()
    assert (out / "tables.csv").is_file() and (out / "tables.tex").is_file()
    assert (out / "figures" / "pareto_table_II.png").is_file()
    assert (out / "figures" / "paths_iiwa7_random_track_distill.png").is_file()


def test_training_record_names_the_method_from_the_shipped_config(tmp_path):
    """PPO from scratch or from a warm start for a PPO run, "DAgger from <teacher>" for a distilled student; no
    summary: None."""
    ppo, student = tmp_path / "ppo", tmp_path / "student"
    for d, cfg in ((ppo, {"agent": {"algorithm": {"class_name": "PPO"}}}),
                   (student, {"agent": {"algorithm": {"class_name": "Distillation"}},
                              "teacher": {"name": "law_tracker", "limit_margin": 1.0}})):
        d.mkdir()
        (d / "summary.json").write_text(json.dumps({"iterations": 3}))
        (d / "config.yaml").write_text(yaml.safe_dump(cfg))
    assert training_record(ppo) == {"iterations": 3, "method": "PPO from scratch"}
    ppo_cfg = {"agent": {"algorithm": {"class_name": "PPO"}}, "init_from": "models/tracking/iiwa7_random/"}
    assert training_method(ppo_cfg) == "PPO from iiwa7_random"
    assert training_method({"reward_curriculum": {"term": "path_length", "initial": 1.0, "iterations": 1000}}) \
        == "PPO from scratch, path_length weight curriculum"
    both = {"term": "deviation_max", "also": ["deviation_mean"], "initial": 2.7, "iterations": 200}
    assert training_method({"init_from": "models/tracking/a", "reward_curriculum": both}) \
        == "PPO from a, deviation_max and deviation_mean weight curriculum"
    assert training_method({"residual": {"scale": 0.25, "controller": {"name": "tray"}}}) \
        == "PPO residual over tray, from scratch"
    assert training_record(student)["method"] == "DAgger from law_tracker"
    assert training_method({"agent": {"algorithm": {"class_name": "Distillation"}},
                            "teacher": {"name": "balance", "policy": "models/upper_body"}}) \
        == "DAgger from balance around upper_body"
    assert training_record(tmp_path / "nothing") is None
    assert training_method({"controller": {"name": "greedy"}, "agent": {"algorithm": {"class_name": "PPO"}}}) \
        == "not trained (greedy)"
    assert training_method({"controller": {"name": "balance", "policy": "models/upper_body"}}) \
        == "balance around upper_body"


def test_time_outs_are_counted_from_the_episodes():
    """The time-out share is the episodes whose termination is the time limit; None without episode records."""
    from pathrl.repro.render import time_out_pct

    per = [{"termination": t} for t in ("time_out", "robot_stopped", "time_out", "deviation")]
    assert time_out_pct({"per_episode": per}) == 50.0
    assert time_out_pct({"episodes": 4}) is None and time_out_pct(None) is None
