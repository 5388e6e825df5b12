"""Per-joint deviation diagnostics of the evaluation (pathrl.eval.metrics.per_joint_errors): offset, RMS and share
per path joint, hand-computed; the same split of the deviation computation gives the same metrics; pathrl-eval
writes them to metrics.json and names the offset joints under its table."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from pathrl.cli import evaluate as eval_cli
from pathrl.eval.metrics import (
    episode_deviations,
    matched_samples,
    offset_joints,
    per_joint_errors,
    sample_deviations,
)
from pathrl.paths.pathset import build_pathset
from pathrl.robot.external import load_robot_by_name
from pathrl.robot.kinematics import ForwardKinematics

NAMES = ("a", "b", "c")


def test_a_constant_offset_in_one_joint_is_that_offset_with_the_whole_share():
    e = torch.zeros(5, 3, dtype=torch.float64)
    e[:, 1] = -0.05
    pj = per_joint_errors(e, NAMES)
    assert list(pj) == list(NAMES)
    assert pj["b"] == pytest.approx({"offset_rad": -0.05, "rms_rad": 0.05, "share": 1.0}, abs=1e-15)
    for n in ("a", "c"):
        assert pj[n] == {"offset_rad": 0.0, "rms_rad": 0.0, "share": 0.0}


def test_offset_rms_and_share_by_hand():
    # joint a: +0.1, -0.1 -> offset 0, rms 0.1, sum sq 0.02; joint b: 0, 0.2 -> offset 0.1, rms sqrt(0.02), sum sq 0.04
    pj = per_joint_errors(torch.tensor([[0.1, 0.0], [-0.1, 0.2]]), ("a", "b"))
    assert pj["a"]["offset_rad"] == pytest.approx(0.0, abs=1e-9)
    assert pj["b"]["offset_rad"] == pytest.approx(0.1, rel=1e-7)
    assert pj["a"]["rms_rad"] == pytest.approx(0.1, rel=1e-7)
    assert pj["b"]["rms_rad"] == pytest.approx(math.sqrt(0.02), rel=1e-7)
    assert pj["a"]["share"] == pytest.approx(1 / 3, rel=1e-7)
    assert pj["b"]["share"] == pytest.approx(2 / 3, rel=1e-7)


def test_no_error_gives_zero_shares_and_a_wrong_shape_is_refused():
    assert all(v == {"offset_rad": 0.0, "rms_rad": 0.0, "share": 0.0}
               for v in per_joint_errors(torch.zeros(4, 3), NAMES).values())
    with pytest.raises(ValueError, match="one column per joint"):
        per_joint_errors(torch.zeros(4, 2), NAMES)


def test_offset_joints_lists_those_over_the_threshold_largest_first():
    pj = {n: {"offset_rad": o, "rms_rad": abs(o), "share": 0.0} for n, o in zip(NAMES, (0.03, -0.06, 0.01),
                                                                                 strict=True)}
    assert offset_joints(pj, 0.02) == ["b", "a"]
    assert offset_joints(pj, 0.1) == []
    assert eval_cli._offset_line(pj).endswith("b -0.060 (0 %), a +0.030 (0 %)")
    assert eval_cli._offset_line({"a": {"offset_rad": 0.001, "rms_rad": 0.0, "share": 1.0}}).endswith(": none")


def test_an_episode_offset_in_one_joint_shows_in_the_matched_samples():
    """Setpoints on the reference but 0.03 rad off in joint 2: offset 0.03 there (0 elsewhere, up to the chords of
    the polyline), share about 1; the split computation gives the metrics of episode_deviations to the bit."""
    iiwa = load_robot_by_name("iiwa7")
    fk = ForwardKinematics(iiwa)
    rng = np.random.default_rng(0)
    paths = build_pathset([np.cumsum(rng.uniform(-0.1, 0.1, (8, iiwa.path_dof)), axis=0)], ["p"])
    idx = torch.as_tensor(iiwa.path_index)
    s = torch.linspace(0.0, float(paths.length[0]), 400, dtype=torch.float64)
    q = torch.zeros(len(s), iiwa.dof, dtype=torch.float64)
    q[:, idx] = paths.position_at(torch.zeros(len(s), dtype=torch.long), s)
    q[:, idx[2]] += 0.03
    args = ([q], idx, paths, [0], [0.0], [float(s[-1])])
    matched = matched_samples(*args)
    pj = per_joint_errors(torch.cat([e - r for e, r in matched]), iiwa.path_joints)
    name = iiwa.path_joints[2]
    assert pj[name]["offset_rad"] == pytest.approx(0.03, abs=2e-3)
    assert pj[name]["share"] > 0.95
    assert all(abs(v["offset_rad"]) < 2e-3 for n, v in pj.items() if n != name)
    assert sample_deviations([q], matched, idx, fk) == episode_deviations(*args, fk)


def test_pathrl_eval_writes_per_joint_and_prints_the_offset_line(tmp_path, capsys):
    out = tmp_path / "out"
    assert eval_cli.main(["run_dir=models/tracking/iiwa7_random", "episodes=2", "record=false", f"out={out}"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    joints = load_robot_by_name("iiwa7").path_joints
    assert list(m["per_joint"]) == list(joints)
    assert sum(v["share"] for v in m["per_joint"].values()) == pytest.approx(1.0)
    assert all(v["rms_rad"] >= abs(v["offset_rad"]) for v in m["per_joint"].values())
    assert "joint offsets > 0.02 rad" in capsys.readouterr().out
