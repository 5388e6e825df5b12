"""TrueAdapt episodes -> trueadapt.mcap -> pathrl-view (issue 20): the recorder, its tool and the Rerun recording."""

from __future__ import annotations

import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from pathrl.cli.common import CONF_DIR
from pathrl.cli.view import main as view_main
from pathrl.dataset.trueadapt import bank_from_arrays
from pathrl.envs.trueadapt import AdaptEnvCfg, TrueAdaptEnv
from pathrl.envs.trueadapt_rewards import build_adapt_reward
from pathrl.eval.trueadapt_record import record_trueadapt
from pathrl.logging.mcap_io import read_messages
from pathrl.logging.schema import TRUEADAPT_EPISODE, TRUEADAPT_ROBOT, TRUEADAPT_STEP
from pathrl.robot.external import load_robot_by_name
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.runs import make_controller
from pathrl.sim.feedback import PLATE_SIZE, plate_pose

ROBOT = load_robot_by_name("iiwa7")
TERMS = OmegaConf.to_container(OmegaConf.load(CONF_DIR / "reward" / "trueadapt_on_plate.yaml"))["terms"]
ROOT = Path(__file__).resolve().parents[1]


def _bank(n: int = 3, steps: int = 30, seed: int = 0):
    """Smooth trajectories from rest (sin^2 swings around the middle of each joint's range), every 50 ms."""
    rng = np.random.default_rng(seed)
    lim = ROBOT.pos_limits
    t = np.arange(steps + 1)[:, None] * 0.05
    trajs = [lim.mean(1) + rng.choice([-1.0, 1.0], (1, 7)) * 0.2 * (lim[:, 1] - lim[:, 0]) / 2
             * np.sin(np.pi * t / (2.0 * t[-1])) ** 2 for _ in range(n)]
    return bank_from_arrays(trajs, 0.05)


def _env(n: int = 2, **kw) -> TrueAdaptEnv:
    return TrueAdaptEnv(AdaptEnvCfg(num_envs=n, autoreset=False, **kw), ROBOT, _bank(), build_adapt_reward(TERMS))


def by_topic(path: Path) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = defaultdict(list)
    for topic, _, msg in read_messages(path):
        out[topic].append(msg)
    return out


@pytest.fixture(scope="module")
def reference_file(tmp_path_factory) -> Path:
    """3 episodes replaying the reference, 2 envs at a time (two batches), no failure termination."""
    env = _env(fail_terminates=False)
    out = tmp_path_factory.mktemp("ta") / "trueadapt.mcap"
    stats = record_trueadapt(env, make_controller({"name": "reference"}, env), 3, out)
    assert stats["episodes"] == 3 and stats["steps"] == 3 * 30
    return out


def test_the_recording_has_every_step_of_every_episode(reference_file):
    msgs = by_topic(reference_file)
    assert {k: len(v) for k, v in msgs.items()} == {TRUEADAPT_ROBOT: 1, TRUEADAPT_STEP: 3 * 31, TRUEADAPT_EPISODE: 3}
    robot = msgs[TRUEADAPT_ROBOT][0]
    assert robot["joint_names"] == list(ROBOT.joints) and robot["mode"] == "on_plate"
    assert np.shape(robot["velocity_limits"]) == (7, 2) and robot["velocity_limits"][0][1] == ROBOT.vel_limits[0]
    eps = msgs[TRUEADAPT_EPISODE]
    assert [e["episode"] for e in eps] == [0, 1, 2] and [e["trajectory"] for e in eps] == [0, 1, 2]
    assert all(e["steps"] == 30 and e["fraction"] <= 1.0 for e in eps)
    steps = [m for m in msgs[TRUEADAPT_STEP] if m["episode"] == 1]
    assert [m["step"] for m in steps] == list(range(31)) and steps[-1]["t"] == pytest.approx(1.5)


def test_replaying_the_reference_records_equal_paths_and_consistent_kinematics(reference_file):
    steps = by_topic(reference_file)[TRUEADAPT_STEP]
    ref = np.array([m["reference"] for m in steps])
    q = np.array([m["position"] for m in steps])
    assert np.abs(q - ref).max() < 1e-9 and max(m["deviation"] for m in steps) < 1e-9
    fk = ForwardKinematics(ROBOT)
    tcp = fk.tcp_positions_np(q)[:, 0]
    assert np.allclose(np.array([m["tcp"] for m in steps]), tcp, atol=1e-9)
    assert np.allclose(np.array([m["reference_tcp"] for m in steps]), tcp, atol=1e-9)
    # the ball sits on the plate: centre = plate centre + R (x, y, radius + half the thickness)
    m = steps[10]
    o, r = plate_pose(fk, torch.tensor([m["position"]], dtype=torch.float64))
    local = np.r_[m["ball_xy"], m["ball_radius"] + PLATE_SIZE[2] / 2]
    assert np.allclose(m["ball_position"], o[0].numpy() + r[0].numpy() @ local, atol=1e-9)


def test_an_adapting_actor_departs_from_the_reference(tmp_path):
    env = _env(n=1, fail_terminates=False, max_joint_deviation=10.0)
    out = tmp_path / "trueadapt.mcap"
    record_trueadapt(env, lambda obs: torch.zeros(1, 7), 1, out)  # zero acceleration: the arm stays put
    steps = by_topic(out)[TRUEADAPT_STEP]
    q, ref = np.array([m["position"] for m in steps]), np.array([m["reference"] for m in steps])
    assert np.abs(q - q[0]).max() < 0.05 and np.abs(ref - q).max() > 0.1
    assert steps[-1]["deviation"] == pytest.approx(np.abs(ref[-1] - q[-1]).max())


def test_view_converts_it_with_the_robot(reference_file, capsys):
    assert view_main([str(reference_file)]) == 0
    out = reference_file.with_suffix(".rrd")
    assert "3 TrueAdapt episodes" in capsys.readouterr().out and out.stat().st_size > 10_000
    from rerun.chunk import RrdReader

    ents = {str(c.entity_path) for c in RrdReader(out).stream().to_chunks()}
    for ent in ("/world/reference", "/world/adapted", "/world/ball", "/world/plate", "/plate/ball",
                "/plate/border", "/joints/iiwa_joint_1/reference", "/joints/iiwa_joint_1/adapted",
                "/ball/border", "/metrics/summary", "/world/joint_transforms"):
        assert ent in ents, ent


def test_bad_input_is_refused(tmp_path):
    with pytest.raises(ValueError, match="autoreset=False"):
        env = TrueAdaptEnv(AdaptEnvCfg(num_envs=1), ROBOT, _bank(), build_adapt_reward(TERMS))
        record_trueadapt(env, lambda obs: torch.zeros(1, 7), 1, tmp_path / "x.mcap")
    with pytest.raises(ValueError, match="episodes must be >= 1"):
        record_trueadapt(_env(), lambda obs: torch.zeros(2, 7), 0, tmp_path / "x.mcap")
    with pytest.raises(ValueError, match="bank indices"):
        record_trueadapt(_env(), lambda obs: torch.zeros(2, 7), 1, tmp_path / "x.mcap", torch.tensor([3]))
    assert not (tmp_path / "x.mcap").exists()


@pytest.fixture(scope="module")
def tiny_dataset(tiny_trueadapt) -> Path:
    return Path(tiny_trueadapt.path)


def _tool():
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import trueadapt_record
    finally:
        sys.path.pop(0)
    return trueadapt_record


def test_the_tool_records_a_controller(tiny_dataset, tmp_path, capsys):
    tool = _tool()
    out = tmp_path / "view"
    assert tool.main(["--controller", "reference", "--episodes", "2", "--dataset", str(tiny_dataset),
                      "--out", str(out)]) == 0
    assert f"pathrl-view {out}" in capsys.readouterr().out
    assert len(by_topic(out / "trueadapt.mcap")[TRUEADAPT_EPISODE]) == 2


def test_the_tool_records_a_trained_run(tiny_dataset, tmp_path, capsys):
    """--run loads the run's config (its dataset) and newest checkpoint, as tools/trueadapt_eval.py does."""
    from pathrl.cli.common import compose, to_container
    from pathrl.schema import TrainAppCfg
    from pathrl.train.runner import train

    run = tmp_path / "run"
    cfg = to_container(compose("train", ["+experiment=iiwa7_trueadapt_on_plate", f"dataset.path={tiny_dataset}",
                                         "iterations=1", "env.num_envs=8", f"run_dir={run}", "compile_limits=false",
                                         "threads=1"], TrainAppCfg))
    train(cfg, run)
    assert _tool().main(["--run", str(run), "--episodes", "2", "--out", str(tmp_path / "view")]) == 0
    msgs = by_topic(tmp_path / "view" / "trueadapt.mcap")
    assert len(msgs[TRUEADAPT_EPISODE]) == 2 and len(msgs[TRUEADAPT_STEP]) == sum(
        e["steps"] + 1 for e in msgs[TRUEADAPT_EPISODE])


@pytest.mark.parametrize("args, msg", [
    (["--controller", "nonsense"], "unknown name 'nonsense'"),
    (["--run", "runs/no_such_run"], "run_dir not found"),
    (["--controller", "reference", "--episodes", "0"], "--episodes must be >= 1"),
])
def test_the_tool_refuses_bad_input_in_one_line(args, msg, tiny_dataset, tmp_path, capsys):
    tool = _tool()
    assert tool.main([*args, "--dataset", str(tiny_dataset), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and "\n" not in err and not (tmp_path / "trueadapt.mcap").exists()
