"""TrueAdapt Table I in the reproduction: the committed test splits, the limit counter, the row plan and the renderer
(hand-checked cells)."""

from __future__ import annotations

import dataclasses
import json
import shlex
from pathlib import Path

import pytest
import torch

from pathrl.models import model_dir, model_path, model_ref
from pathrl.repro import trueadapt as adapt
from pathrl.repro import trueadapt_findings as findings

ROOT = Path(__file__).resolve().parents[1]
REF = "iiwa7_trueadapt_on_plate_reference_in_pybullet"
FAKE = {  # one on-plate row, one in-place row, the validation
    "trueadapt": {
        REF: {"success": 0.05, "fraction": 0.375, "offset": 0.0431, "acc": 0.0224, "jerk": 0.0028, "episodes": 1000,
              "backend": "pybullet", "limit_violations": 0},
        "iiwa7_trueadapt_in_place_tray_controller_in_pybullet": {
            "success": 1.0, "fraction": 1.0, "offset": 0.0099, "acc": 0.038, "jerk": 0.0304, "episodes": 1000,
            "backend": "pybullet", "limit_violations": 2},
    },
    "trueadapt_training": {"iiwa7_trueadapt_in_place_tray_controller": {"method": "not trained (trueadapt_tray)"}},
    "trueadapt_validation": [{"mode": "random", "trajectories": 100000, "steps": 100, "setpoints_checked": 840000000,
                              "violations": {"total": 0}, "seconds": 104.4}],
}


def _line(md: list[str], setting: str) -> str:
    return next(ln for ln in md if ln.startswith(f"| {setting} |"))


def test_renderer_hand_checked_cells():
    md, rows = adapt.markdown(FAKE)
    # ours in percent / the paper's; on plate the error distance is not the task's metric: ours in brackets
    assert _line(md, "on plate: reference trajectories (no adaptations)") == (
        "| on plate: reference trajectories (no adaptations) | the reference replayed | not trained (reference "
        "replayed) | **5.0** / 4.2 | "
        "**37.5** / 40.4 | (4.3) | **2.2** / 1.7 | **0.3** / 0.5 | pybullet | 1000 | 0 |")
    # a row of ours only (no paper value): bold, no slash; in place the error distance is the metric (cm)
    assert _line(md, "in place: model-based tray controller") == (
        "| in place: model-based tray controller | **tray controller: privileged information, not in the paper** | "
        "not trained (trueadapt_tray) | **100.0** | **100.0** | **1.0** | **3.8** | **3.0** | pybullet | 1000 | 2 |")
    # a paper row without a policy of ours: dashes and the paper's value
    assert _line(md, "in place: TrueAdapt, real robot") == (
        "| in place: TrueAdapt, real robot | no real robot | – | – / 82.0 | – / 96.1 | – / 1.7 | – / 6.9 | – / 3.6 "
        "| – | – | – |")
    # a second policy of ours for one paper row: its own line and CSV key, the paper's values of that row beside it
    ppo = next(ln for ln in md if ln.startswith("| on plate: TrueAdapt, test set | distilled policy + PPO"))
    assert ppo.endswith("| – / 89.6 | – / 97.6 | – | – / 7.0 | – / 3.7 | – | – | – |")
    assert (md.index(ppo) == md.index(_line(md, "on plate: TrueAdapt, test set")) + 1)
    assert any("random accelerations: 100000 trajectories x 100 steps, **0 violations** in 8.40e+08 (setpoint, joint) "
               "pairs (104 s)" in ln for ln in md)
    csv = {(r[1], r[2]): (r[3], r[4]) for r in rows}
    assert csv["on_plate/reference", "success_pct"] == ("5", "4.2")
    assert csv["in_place/test_set", "error_distance_cm"] == ("", "1.2")
    assert csv["on_plate/test_set_ppo", "success_pct"] == ("", "89.6")
    assert csv["in_place/tray_controller", "limit_violations"] == ("2", "")
    assert csv["validation/random", "limit_violations"] == ("0", "0")
    tex = "\n".join(adapt.latex(FAKE))
    assert r"on\_plate/reference & 5.0 (4.2) & 37.5 (40.4) & 4.3 (--)" in tex


def test_missing_train_split_renders_as_not_available(tmp_path):
    md, _ = adapt.markdown({"trueadapt": {}})
    line = _line(md, "on plate: TrueAdapt, training set")
    assert adapt.TRAIN_MISSING in line and line.endswith("| – / 90.7 | – / 97.9 | – | – / 7.0 | – / 3.7 | – | – | – |")
    assert "Limit validation (Sec. VI-D): not run." in md
    # the step is skipped (no failure) where data/ lacks the train split; the test rows still run
    train = next(e for e in adapt.evaluations() if e.split == "train")
    root = tmp_path / "checkout"
    model_path(train.model, root / "models").mkdir(parents=True)
    (model_path(train.model, root / "models") / "config.yaml").write_text("{}")
    assert adapt.unavailable(train, root / "models", root / "data") == adapt.TRAIN_MISSING
    assert adapt.eval_command(train, root, root / "results" / "raw", 1000) is None
    test = dataclasses.replace(train, split="test", open_loop=True)
    assert adapt.eval_command(test, root, root / "results" / "raw", 12) == [
        "pathrl-eval", f"run_dir={model_ref(train.model)}", "dataset.path=datasets/iiwa7/trueadapt_on_plate",
        "split=test",
        "episodes=12", "seed=0", "backend=pybullet", "workers=1", "num_envs=250",
        f"out=results/raw/{train.model}_in_pybullet_open_loop", "open_loop=true"]
    (root / "results" / "raw" / test.id).mkdir(parents=True)
    (root / "results" / "raw" / test.id / "metrics.json").write_text("{}")
    assert adapt.eval_command(test, root, root / "results" / "raw", 12, reuse=True) is None


def test_rows_cover_the_paper_and_name_shipped_models():
    paper = adapt.paper()
    assert {r.key for r in adapt.ROWS if r.in_paper} == set(paper["rows"])
    assert all(len(v) == len(paper["columns"]) for v in paper["rows"].values())
    for e in adapt.evaluations():  # the reference's directory too (the controller `reference`)
        assert (model_dir(e.run) / "config.yaml").is_file(), e.run
    assert len({e.id for e in adapt.evaluations()}) == len(adapt.evaluations())
    assert adapt.VALIDATION_ID in adapt.names() and "iiwa7_trueadapt_in_place_reference" in adapt.names()


@pytest.mark.parametrize("task", ["on_plate", "in_place"])
def test_committed_split_holds_the_1000_test_trajectories(task):
    from pathrl.dataset.trueadapt import load_trajectories
    from pathrl.robot.external import load_robot_by_name

    path = ROOT / "datasets" / "iiwa7" / f"trueadapt_{task}"
    meta = json.loads((path / "dataset.json").read_text())
    assert meta["splits"] == {"test": 1000} and meta["kind"] == "trueadapt"
    assert (path / "test.npz").stat().st_size < 8e6
    assert load_trajectories(str(path), "test", load_robot_by_name("iiwa7"), 0.05).num == 1000


def test_a_fresh_checkout_evaluates_on_the_committed_split(tmp_path, monkeypatch):
    from pathrl.runs import committed_split

    (tmp_path / "datasets").symlink_to(ROOT / "datasets")
    monkeypatch.chdir(tmp_path)  # no data/ here
    assert committed_split("data/iiwa7/trueadapt_on_plate", "test") == "datasets/iiwa7/trueadapt_on_plate"
    assert committed_split("data/iiwa7/trueadapt_on_plate", "train") == "data/iiwa7/trueadapt_on_plate"



def test_plan_runs_the_trueadapt_steps_through_the_family_registry(tmp_path, monkeypatch):
    """The table plan's TrueAdapt steps (an evaluation, the limit validation, the time per decision) run the TrueAdapt
    family's registry steps: pathrl-eval for the evaluation, pathrl.cli.family_step for the others; no tools/
    script."""
    from pathrl.families import family
    from pathrl.repro import steps
    from pathrl.repro.layout import PROFILES, Layout
    from pathrl.repro.plan import build_plan

    runs: list[list[str]] = []

    def fake_sh(cmd: list[str], log: Path) -> None:
        batch = [a[6:] for a in cmd if a.startswith("batch=")]  # pathrl-eval batch=FILE: one evaluation per line
        if batch:
            cmd = [cmd[0], *shlex.split(Path(batch[0]).read_text())]
        runs.append(cmd)
        for out in (Path(a[4:]) for a in cmd if a.startswith("out=")):  # the evaluation's output directory
            out = out if out.is_absolute() else steps.ROOT / out
            out.mkdir(parents=True)
            (out / "metrics.json").write_text("{}")

    monkeypatch.setattr(steps, "sh", fake_sh)
    lay = Layout(tmp_path, ROOT / "models", tmp_path / "runs", ROOT / "datasets", tmp_path / "data")
    plan = build_plan(PROFILES["quick"], lay, {"iiwa7_trueadapt_on_plate_reference", adapt.VALIDATION_ID})
    for step in plan.steps:
        step.run()
    assert len(runs) == 3 and not any("tools/" in arg for cmd in runs for arg in cmd)
    evaluation, validation, timing = runs
    assert (tmp_path / "raw" / adapt.AdaptEval("on_plate").id / "inputs.json").is_file()  # recorded after the batch
    assert Path(evaluation[0]).name == "pathrl-eval"
    assert "run_dir=models/trueadapt/iiwa7_trueadapt_on_plate_reference" in evaluation
    for cmd, name in ((validation, "validate"), (timing, "timing")):
        assert cmd[1:6] == ["-m", adapt.FAMILY_STEP, "trueadapt", name, cmd[5]], cmd
        fn = family(cmd[3]).step(cmd[4])
        assert (fn.__module__, fn.__name__) == ("pathrl.families.trueadapt", name)


def test_family_step_validates_the_robot_of_the_run(tmp_path, capsys):
    """`python -m pathrl.cli.family_step trueadapt validate` (what the plan runs): the iiwa7's limits, as
    pathrl.eval.trueadapt_validation counts them; the result as JSON."""
    from pathrl.cli.family_step import main
    from pathrl.eval.trueadapt_validation import MODES, validate
    from pathrl.limits.feasible import JointLimits
    from pathrl.robot.external import load_robot_by_name

    out = tmp_path / "v.json"
    cmd = adapt.validation_command(ROOT, tmp_path, 20)
    assert main([*cmd[3:5], str(ROOT / cmd[5]), str(out), "num_envs=20", "episodes=5", "seed=0"]) == 0
    got = json.loads(out.read_text())
    limits = JointLimits.from_robot(load_robot_by_name("iiwa7"))
    want = [dataclasses.asdict(validate(limits, 20, 5, mode=m, seed=0)) for m in MODES]
    strip = [{k: v for k, v in r.items() if k != "seconds"} for r in got]
    assert strip == [{k: v for k, v in r.items() if k != "seconds"} for r in json.loads(json.dumps(want))]
    assert main(["trueadapt", "validate", str(ROOT / cmd[5]), str(out), "episodes=0"]) == 2
    assert "episodes must be an integer >= 1" in capsys.readouterr().err

def test_limit_counter_checks_every_setpoint_and_finds_violations():
    """The reference replayed on 4 committed trajectories: no violation of the robot's limits; against velocity
    limits at 10 % (the references reach up to 50 %) the same setpoints violate."""
    from pathrl.dataset.trueadapt import load_trajectories
    from pathrl.envs.trueadapt import AdaptEnvCfg, TrueAdaptEnv
    from pathrl.envs.trueadapt_rewards import build_adapt_reward
    from pathrl.eval.trueadapt import evaluate, reference_policy
    from pathrl.eval.trueadapt_limits import LimitCounter
    from pathrl.robot.external import load_robot_by_name

    robot = load_robot_by_name("iiwa7")
    bank = load_trajectories(str(ROOT / "datasets/iiwa7/trueadapt_on_plate"), "test", robot, 0.05)
    counts = []
    for scale in (1.0, 0.1):
        env = TrueAdaptEnv(AdaptEnvCfg(num_envs=4, autoreset=False, fail_terminates=False), robot, bank,
                           build_adapt_reward({"on_plate": {"weight": 1.0}}))
        lim = dataclasses.replace(env.limits, vel=env.limits.vel * scale)
        counter = LimitCounter(env, lim)
        evaluate(env, reference_policy, torch.arange(4), counter)
        steps = int(bank.steps[:4].sum())
        assert counter.checked == steps * 12 * 7  # 12 setpoints per 50 ms step at 240 Hz, 7 joints
        counts.append(counter.counts)
    assert counts[0]["total"] == 0
    assert counts[1]["velocity"] > 0 and counts[1]["total"] == counts[1]["velocity"]


def test_every_seed_of_the_from_scratch_runs_and_the_method_column(tmp_path):
    """The committed per-seed evaluations are found by name (other files ignored) and rendered one line per
    experiment, seeds in order, with the mean success; a row's method is its shipped config's."""
    m = {"success": 0.5, "fraction": 0.9, "acc": 0.03, "jerk": 0.01, "limit_violations": 0}
    for name, success in (("exp_a_seed1", 0.9), ("exp_a_seed0", 0.6), ("exp_b_seed0", 0.2)):
        (tmp_path / f"{name}_pybullet_metrics.json").write_text(json.dumps({**m, "success": success}))
    (tmp_path / "exp_a_seed0.csv").write_text("iteration\n0\n")
    (tmp_path / "notes_pybullet_metrics.json").write_text("{}")
    seeds = adapt.seed_results(tmp_path)
    assert {k: sorted(v) for k, v in seeds.items()} == {"exp_a": [0, 1], "exp_b": [0]}
    md = adapt.seeds_markdown(seeds)
    assert "| `exp_a` | 0, 1 | 60.0 / 90.0 | 75.0 | 90.0 / 90.0 | 3.0 / 3.0 | 1.0 / 1.0 | 0 |" in md
    assert adapt.seeds_markdown({}) == [] and adapt.seed_results(tmp_path / "missing") == {}
    row = adapt._scratch_row("no_current_position", "state without current position", "no_position")
    assert row.evaluation.model == "iiwa7_trueadapt_on_plate_ppo_scratch_no_position"
    assert adapt.method({"training": {row.evaluation.model: {"method": "PPO from scratch"}}}, row) == "PPO from scratch"
    assert adapt.method({}, row) == "–"
    # every from-scratch ablation row names an experiment that exists
    for r in adapt.ROWS:
        if r.key.endswith("_scratch"):
            assert (ROOT / "pathrl" / "conf" / "experiment" / f"{r.evaluation.model}.yaml").is_file(), r.key


def test_findings_class_the_paper_and_ours_the_same_way():
    # ratio classes: success fails < 0.25 <= partly < 0.9 <= keeps; a penalised quantity rises > 2x
    assert [findings.outcome(r, "success_pct") for r in (0.1, 0.25, 0.89, 0.9, 1.2)] == [
        "fails", "partly", "partly", "keeps", "keeps"]
    assert [findings.outcome(r, "jerk_pct") for r in (2.0, 2.01)] == ["stays", "rises"]
    scratch = {"success": 0.99, "fraction": 1.0, "offset": 0.04, "acc": 0.03, "jerk": 0.01, "episodes": 1000}
    no_pos = {**scratch, "success": 0.30}  # 30 / 99 = 0.30: partly, where the paper's 0.1 / 89.6 fails
    no_jerk = {**scratch, "success": 0.98, "jerk": 0.05}  # jerk 5 / 1 = 5x: rises, as the paper's 18.1 / 3.7
    results = {"trueadapt": {"iiwa7_trueadapt_on_plate_ppo_scratch_in_pybullet": scratch,
                             "iiwa7_trueadapt_on_plate_ppo_scratch_no_position_in_pybullet": no_pos,
                             "iiwa7_trueadapt_on_plate_ppo_scratch_no_jerk_penalty_in_pybullet": no_jerk}}
    md = findings.markdown(results)
    pos = next(ln for ln in md if ln.startswith("| on plate: state without current position |"))
    assert pos == ("| on plate: state without current position | success | 0.1 / 89.6 (fails) | 30.0 / 99.0 (partly) "
                   "| **no** | – | – |")
    jerk = next(ln for ln in md if ln.startswith("| on plate: no jerk penalty | \\|jerk\\|"))
    assert jerk == ("| on plate: no jerk penalty | \\|jerk\\| | 18.1 / 3.7 (rises) | 5.0 / 1.0 (rises) | yes | – | – |")
    # in place, against the in-place full policies: trained open loop from scratch 50 / 100 = 0.5 is partly, as the
    # paper's 61.7 / 98.6
    results["trueadapt"] |= {"iiwa7_trueadapt_in_place_ppo_scratch_in_pybullet": {**scratch, "success": 1.0},
                             "iiwa7_trueadapt_in_place_ppo_scratch_open_loop_in_pybullet_open_loop":
                                 {**scratch, "success": 0.5}}
    md = findings.markdown(results)
    ol = next(ln for ln in md if ln.startswith("| in place: open loop, training and evaluation |"))
    assert ol == ("| in place: open loop, training and evaluation | success | 61.7 / 98.6 (partly) | 50.0 / 100.0 "
                  "(partly) | yes | – | – |")
