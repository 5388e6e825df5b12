"""Robots from URDF outside the package (PATHRL_ROBOT_PATH): limits read from the URDF, jerk by the stated rule,
`pathrl-robot check`, and the Franka Panda and the xArm6 (URDFs shipped with pybullet) end to end with tiny budgets:
dataset, one training iteration, evaluation (without the variable: the run stores the expanded robot), TOPP-RA."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pathrl.cli.robot import main as robot_main
from pathrl.robot.external import (
    JERK_PER_ACCELERATION,
    ROBOT_PATH_ENV,
    expand_robot_file,
    load_robot_by_name,
    robot_files,
)
from pathrl.robot.model import RobotConfigError

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = ROOT / "examples" / "robots"
BIN = Path(sys.executable).parent


def test_limits_from_the_urdf_and_the_jerk_rule():
    cfg = expand_robot_file(ROBOTS / "panda.yaml")
    assert cfg["position_limits"][3] == [-3.1416, 0.0]  # panda_joint4 in panda.urdf
    assert cfg["velocity_limits"] == [2.175] * 4 + [2.61] * 3
    assert cfg["jerk_limits"] == [JERK_PER_ACCELERATION * a for a in cfg["acceleration_limits"]]
    x = expand_robot_file(ROBOTS / "xarm6.yaml")
    assert x["acceleration_limits"] == [10.0] * 6 and x["path_joints"] == x["joints"]
    assert x["position_limits"][1] == [-2.059, 2.0944]  # joint2, not the <joint> of a <transmission>


def test_found_by_name_through_the_variable(monkeypatch):
    monkeypatch.setenv(ROBOT_PATH_ENV, str(ROBOTS))
    assert set(robot_files()) == {"panda", "xarm6"}
    spec = load_robot_by_name("xarm6")
    assert spec.dof == 6 and np.allclose(spec.pos_limits[0], [-6.28318530718 + 0.035, 6.28318530718 - 0.035])
    monkeypatch.setenv(ROBOT_PATH_ENV, str(ROBOTS / "nowhere"))
    with pytest.raises(RobotConfigError, match="no such file or directory"):
        robot_files()


@pytest.mark.parametrize(("text", "message"), [
    ("urdf: pybullet_data:xarm/xarm6_robot.urdf\njoints: [joint1]\ntcps: []\nworkspace: {}\n",
     "acceleration_limits is required"),
    ("urdf: nothere.urdf\njoints: [joint1]\nacceleration_limits: 1\ntcps: []\nworkspace: {}\n", "URDF not found"),
    ("urdf: pybullet_data:xarm/xarm6_robot.urdf\njoints: [joint9]\nacceleration_limits: 1\ntcps: []\n"
     "workspace: {}\n", "no joint 'joint9'"),
    ("urdf: pybullet_data:xarm/xarm6_robot.urdf\njoints: [joint1, joint2]\nacceleration_limits: [1, 2, 3]\n"
     "tcps: []\nworkspace: {}\n", "expected 2 values"),
])
def test_bad_robot_files_are_one_line_errors(tmp_path, capsys, text, message):
    f = tmp_path / "bot.yaml"
    f.write_text(text)
    assert robot_main(["check", str(f)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    (tmp_path / "iiwa7.yaml").write_text(text)
    with pytest.raises(RobotConfigError, match="shipped robot"):
        robot_files(str(tmp_path))


@pytest.mark.parametrize("robot", ["panda", "xarm6"])
def test_a_new_robot_end_to_end_with_tiny_budgets(tmp_path, capsys, monkeypatch, robot):
    from pathrl.cli.dataset import main as dataset_main
    from pathrl.cli.evaluate import main as eval_main
    from pathrl.cli.toppra import main as toppra_main

    assert robot_main(["check", str(ROBOTS / f"{robot}.yaml")]) == 0
    assert "ok" in capsys.readouterr().out
    monkeypatch.setenv(ROBOT_PATH_ENV, str(ROBOTS))
    data, run = tmp_path / "data", tmp_path / "run"
    assert dataset_main(["generate", f"robot={robot}", "dataset=random", "dataset.num_train=2", "dataset.num_test=1",
                         f"dataset.path={data}", "workers=1"]) == 0
    env = {**os.environ, ROBOT_PATH_ENV: str(ROBOTS), "OMP_NUM_THREADS": "1"}
    done = subprocess.run([str(BIN / "pathrl-train"), f"robot={robot}", "dataset=random", f"dataset.path={data}",
                           f"run_dir={run}", "iterations=1", "env.num_envs=16", "agent.num_steps_per_env=8",
                           "compile_limits=false", "threads=1"], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    monkeypatch.delenv(ROBOT_PATH_ENV)  # the run's config holds the expanded robot
    assert eval_main([f"run_dir={run}", f"dataset.path={data}", "segments=full", "episodes=1",
                      f"out={tmp_path / 'eval'}"]) == 0
    monkeypatch.setenv(ROBOT_PATH_ENV, str(ROBOTS))
    assert toppra_main([f"robot={robot}", f"dataset.path={data}", "segments=full", "workers=1",
                        f"out={tmp_path / 'toppra.json'}"]) == 0
    capsys.readouterr()
