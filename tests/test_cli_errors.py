"""Every bad input a user can give a CLI is one line on stderr, exit code 2, no traceback and no partial output.

Each case names what it breaks; the train cases run the real ``pathrl-train`` (Hydra's own error paths are part
of what is tested), the others call the CLI's ``main`` in-process.
"""

from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path

import pytest
import torch
from test_storage import _flip_tensor_bytes
from test_train import run, train_cmd

from pathrl.cli import evaluate as eval_cli
from pathrl.cli import export as export_cli
from pathrl.cli import toppra as toppra_cli
from pathrl.dataset.io import save_dataset
from pathrl.dataset.synthetic import smooth_paths
from pathrl.models import model_dir
from pathrl.robot.external import load_robot_by_name

#: (overrides, separated by spaces; expected text in the one line)
TRAIN_CASES = {
    "negative iterations": ("iterations=-5", "iterations must be >= 1"),
    "zero envs": ("env.num_envs=0", "env.num_envs must be"),
    "negative envs": ("env.num_envs=-4", "env.num_envs must be"),
    "zero dt": ("env.dt=0", "env.dt must be > 0"),
    "negative dt": ("env.dt=-0.1", "env.dt must be > 0"),
    "zero substeps": ("env.substeps=0", "env.substeps must be"),
    "unknown segments": ("env.segments=bogus", "env.segments must be one of"),
    "zero threads": ("threads=0", "threads must be >= 1"),
    "misspelt device": ("device=cdua", "device=cdua: expected cpu, cuda or cuda:N"),
    "cuda index beyond the devices": (f"device=cuda:{max(torch.cuda.device_count(), 7)}",
                                      f"device=cuda:{max(torch.cuda.device_count(), 7)} but"),
    "PyBullet task on a GPU": ("task=ball_on_plate task.backend=pybullet device=cuda",
                               "task ball_on_plate simulates in PyBullet, on the CPU only"),
    "added key typo": ("+env.num_env=5", "did you mean env.num_envs"),
    "added top-level key": ("+iteration=3", "did you mean iterations"),
    "removed reward weight": ("~reward.terms.path_length.weight", "weight is missing"),
    "reward parameter typo": ("+reward.terms.path_length.wieght=2", "did you mean weight"),
    "override of a missing key": ("reward.terms.path_length.wieght=2", "not in struct"),
    "not a number": ("iterations=abc", "iterations=abc"),
    "unknown group option": ("env=nope", "env/nope"),
    "lr_decay under adaptive PPO": ("lr_decay.final=1e-5", "lr_decay needs agent.algorithm.schedule=fixed"),
    "lr_decay start past the end": ("lr_decay={final:1e-5,start:1.0}", "lr_decay: final must be > 0 and start in"),
}
if not torch.cuda.is_available():  # where CUDA exists, device=cuda is a valid run
    TRAIN_CASES["cuda without cuda"] = ("device=cuda", "no CUDA")


def _one_line(stderr: str) -> str:
    lines = [ln for ln in stderr.strip().splitlines() if not ln.startswith("pybullet build time")]
    assert len(lines) == 1 and "Traceback" not in stderr, stderr[-1500:]
    return lines[0]


#: Cases run end to end through the ``pathrl-train`` process (the rest are checked in-process, below): a value,
#: a Hydra composition error, an added key, and an error found only when the run builds its env.
SUBPROCESS_CASES = ("negative iterations", "override of a missing key", "added key typo", "reward parameter typo",
                    "misspelt device", "PyBullet task on a GPU")


@pytest.mark.parametrize("case", SUBPROCESS_CASES)
def test_train_bad_config_end_to_end(case, tiny_dataset, tmp_path):
    override, msg = TRAIN_CASES[case]
    run_dir = tmp_path / "run"
    r = run(train_cmd(tiny_dataset, run_dir, 1, *override.split(" ")))
    line = _one_line(r.stderr)
    assert r.returncode == 2 and line.startswith("error:") and msg in line, (case, line)
    assert not run_dir.exists()  # nothing written, no directory made


@pytest.mark.parametrize("case", list(TRAIN_CASES))
def test_train_bad_config(case, tiny_dataset, tmp_path, capsys):
    """``pathrl-train``'s check before Hydra runs anything (pathrl.cli.train._precheck)."""
    from pathrl.cli.train import _precheck

    override, msg = TRAIN_CASES[case]
    run_dir = tmp_path / "run"
    with pytest.raises(SystemExit) as exc:
        _precheck([f"dataset.path={tiny_dataset}", f"run_dir={run_dir}", "iterations=1", *override.split(" ")])
    line = _one_line(capsys.readouterr().err)
    assert exc.value.code == 2 and line.startswith("error:") and msg in line, (case, line)
    assert not run_dir.exists()


def test_train_missing_dataset(tmp_path):
    r = run(train_cmd(tmp_path / "missing_dataset", tmp_path / "run", 1))
    assert r.returncode == 2 and "dataset directory not found" in _one_line(r.stderr)
    assert not (tmp_path / "run").exists()  # a failed start leaves no directory to block the next one


@pytest.fixture(scope="module")
def off_limits_dataset(tmp_path_factory):
    """Knots 10x outside the joint limits (a unit slip; 1000x, mrad for rad, is refused when saved: beyond 100 rad)."""
    robot = load_robot_by_name("iiwa7")
    paths = smooth_paths(robot, 3, 0)
    paths[0] = (paths[0][0], paths[0][1] * 10.0)
    dest = tmp_path_factory.mktemp("off") / "d"
    meta = {"robot": "iiwa7", "kind": "synthetic", "path_joints": list(robot.path_joints), "seed": 0}
    save_dataset(dest, {"train": paths, "test": paths}, meta)
    return dest


def test_train_on_paths_outside_the_limits(off_limits_dataset, tmp_path):
    r = run(train_cmd(off_limits_dataset, tmp_path / "run", 1))
    line = _one_line(r.stderr)
    assert r.returncode == 2 and "leave robot 'iiwa7'" in line and "out_of_limits=clip" in line
    assert not (tmp_path / "run" / "config.yaml").exists()


def test_toppra_on_paths_outside_the_limits(off_limits_dataset, tmp_path, capsys):
    out = tmp_path / "t.json"
    assert toppra_cli.main(["robot=iiwa7", f"dataset.path={off_limits_dataset}", f"out={out}"]) == 2
    assert "leave robot 'iiwa7'" in _one_line(capsys.readouterr().err) and not out.exists()
    assert toppra_cli.main(["robot=iiwa7", f"dataset.path={off_limits_dataset}", "+dataset.out_of_limit=clip"]) == 2
    assert "did you mean dataset.out_of_limits" in _one_line(capsys.readouterr().err)


def _model_copy(tmp_path: Path) -> Path:
    model = tmp_path / "model"
    shutil.copytree(model_dir("iiwa7_random"), model)
    return model


def _damage(model: Path, case: str) -> None:
    if case == "empty checkpoint":
        (model / "model.pt").write_bytes(b"")
    elif case == "truncated checkpoint":
        (model / "model.pt").write_bytes((model / "model.pt").read_bytes()[:5000])
    elif case == "flipped bytes":
        _flip_tensor_bytes(model / "model.pt")
    elif case == "pickled callable":
        (model / "model.pt").write_bytes(pickle.dumps(print))
    elif case == "config is a list":
        (model / "config.yaml").write_text("- a\n- b\n")
    elif case == "config is not yaml":
        (model / "config.yaml").write_text("robot: [unclosed\n")
    elif case == "broken summary":
        (model / "summary.json").write_text("{not json")
    elif case == "no checkpoint":
        (model / "model.pt").unlink()


EVAL_CASES = {"empty checkpoint": "unreadable checkpoint", "truncated checkpoint": "unreadable checkpoint",
              "flipped bytes": "sha256", "pickled callable": "unreadable checkpoint",
              "config is a list": "expected a mapping", "config is not yaml": "invalid YAML",
              "broken summary": "invalid JSON", "no checkpoint": "no checkpoint"}


@pytest.mark.filterwarnings("ignore:Detected pickle protocol")
@pytest.mark.parametrize("case", list(EVAL_CASES))
def test_eval_damaged_model(case, tmp_path, capsys):
    model = _model_copy(tmp_path)
    _damage(model, case)
    out = tmp_path / "out"
    code = eval_cli.main([f"run_dir={model}", "episodes=2", f"out={out}", "dataset.path=datasets/iiwa7/random"])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and EVAL_CASES[case] in line, (case, line)
    assert not out.exists()


@pytest.mark.parametrize("argv, msg", [
    (["run_dir=models/tracking/iiwa7_random", "num_envs=0"], "num_envs must be >= 1"),
    (["run_dir=models/tracking/iiwa7_random", "episodes=zero"], "integer"),
    (["run_dir=models/nope"], "not found"),
    (["run_dir=models/tracking/iiwa7_random", "segments=some"], "segments must be"),
    (["run_dir=models/tracking/iiwa7_random", "dataset.out_of_limits=ignore", "episodes=1"], "must be refuse or clip"),
    (["run_dir=models/tracking/iiwa7_random", "bogus=1"], "unknown argument"),
    (["run_dir=models/tracking/iiwa7_random", "~num_envs=1200"], "unknown argument '~num_envs'"),
    (["run_dir=models/tracking/iiwa7_random", "+seed=1"], "unknown argument '+seed'"),
])
def test_eval_bad_arguments(argv, msg, tmp_path, capsys):
    assert eval_cli.main([*argv, f"out={tmp_path / 'out'}"]) == 2
    assert msg in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv, msg", [
    (["run_dir=models/tracking/iiwa7_random", "observations=0"], "observations must be >= 1"),
    (["run_dir=models/tracking/iiwa7_random", "observations=abc"], "observations must be an integer, got 'abc'"),
    (["run_dir=models/nope"], "not found"),
    (["run_dir=models/tracking/iiwa7_ball_tray_controller"], "no network to export"),
    (["run_dir=models/tracking/iiwa7_random", "bogus=1"], "unknown argument 'bogus'"),
    (["run_dir=models/tracking/iiwa7_random", "dataset=random"], "unknown argument 'dataset'"),
    (["run_dir=models/tracking/iiwa7_random", "dataset.path=/nonexistent"], "dataset directory not found"),
    (["models/tracking/iiwa7_random"], "expected key=value"),
    ([], "run_dir is required"),
])
def test_export_bad_arguments(argv, msg, tmp_path, capsys):
    assert export_cli.main([*argv, f"out={tmp_path / 'out'}"]) == 2
    assert msg in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "out").exists()


def test_eval_on_a_fresh_checkout_uses_the_committed_test_split(tmp_path, capsys):
    """models/*/config.yaml name data/<robot>/<kind> (generated, not committed): the committed copy is used."""
    model = _model_copy(tmp_path)
    cfg = (model / "config.yaml").read_text().replace("path: data/iiwa7/random", "path: data/iiwa7/not_here")
    (model / "config.yaml").write_text(cfg)
    assert eval_cli.main([f"run_dir={model}", "episodes=2", "record=false", f"out={tmp_path / 'o'}"]) == 2
    assert "data/iiwa7/not_here" in _one_line(capsys.readouterr().err)


def test_eval_batch_lines_skip_comments_and_refuse_a_nested_batch():
    text = "# header\n\nrun_dir=a out='/tmp/x y'  # why\nrun_dir=b\n"
    assert eval_cli.batch_lines(text) == [(3, ["run_dir=a", "out=/tmp/x y"]), (4, ["run_dir=b"])]
    with pytest.raises(eval_cli.UserError, match="line 2: a batch cannot name another batch"):
        eval_cli.batch_lines("run_dir=a\nbatch=other.txt\n")
    with pytest.raises(eval_cli.UserError, match="line 1"):
        eval_cli.batch_lines("run_dir='unclosed\n")


def test_eval_batch_checks_every_line_before_any_work(tmp_path, capsys):
    good = f"run_dir=models/tracking/iiwa7_random episodes=2 record=false out={tmp_path / 'a'}"
    batch = tmp_path / "b.txt"
    batch.write_text(f"{good}\nrun_dir=models/tracking/iiwa7_random num_envs=0 out={tmp_path / 'b'}\n")
    assert eval_cli.main([f"batch={batch}"]) == 2
    assert "batch line 2: num_envs must be >= 1" in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "a").exists()
    batch.write_text(f"{good}\n{good}\n")
    assert eval_cli.main([f"batch={batch}"]) == 2
    assert "two lines write the same output directory" in _one_line(capsys.readouterr().err)
    assert eval_cli.main([f"batch={batch}", "episodes=2"]) == 2
    assert "takes no other arguments" in _one_line(capsys.readouterr().err)


def test_eval_batch_runs_the_other_lines_when_one_fails(tmp_path, capsys):
    """A damaged checkpoint fails its line only (exit code 1); the next line is evaluated, as it is alone."""
    model = _model_copy(tmp_path)
    _damage(model, "empty checkpoint")
    batch = tmp_path / "b.txt"
    args = "episodes=3 num_envs=3 record=false dataset.path=datasets/iiwa7/random"
    batch.write_text(f"run_dir={model} {args} out={tmp_path / 'bad'}\n"
                     f"run_dir=models/tracking/iiwa7_random {args} out={tmp_path / 'good'}\n")
    assert eval_cli.main([f"batch={batch}"]) == 1
    err = capsys.readouterr().err
    assert "batch line 1: " in err and "unreadable checkpoint" in err and "1 of 2 evaluations failed" in err
    assert not (tmp_path / "bad" / "metrics.json").exists()
    assert eval_cli.main([*args.split(), "run_dir=models/tracking/iiwa7_random", f"out={tmp_path / 'alone'}"]) == 0
    got, alone = (json.loads((tmp_path / d / "metrics.json").read_text()) for d in ("good", "alone"))
    assert {k: v for k, v in got.items() if "wall" not in k} == {k: v for k, v in alone.items() if "wall" not in k}
