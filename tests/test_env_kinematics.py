"""One env owns one robot spec and one forward kinematics: its feedback, TCP observations and rewards, controllers
and evaluation metrics read the env's (``env.fk``), which a plain tracking env builds only when first used."""

import pytest
import torch

from pathrl.cli.common import compose, to_container
from pathrl.envs.registry import EVAL_ENV, EnvRequest, make_env
from pathrl.robot import model
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.runs import make_controller
from pathrl.schema import TrainAppCfg


@pytest.fixture
def built(monkeypatch):
    """Counts of robot loads and ForwardKinematics constructions from now on."""
    counts = {"robot": 0, "fk": 0}
    resolve, init = model.resolve_urdf, ForwardKinematics.__init__

    def counting_resolve(*a, **k):
        counts["robot"] += 1  # load_robot resolves the URDF once per spec it builds
        return resolve(*a, **k)

    def counting_init(self, *a, **k):
        counts["fk"] += 1
        init(self, *a, **k)

    monkeypatch.setattr(model, "resolve_urdf", counting_resolve)
    monkeypatch.setattr(ForwardKinematics, "__init__", counting_init)
    return counts


def _cfg(overrides):
    return to_container(compose("train", overrides, TrainAppCfg))


def test_a_tracking_env_builds_its_kinematics_once_when_first_used(tiny_dataset, built):
    cfg = _cfg(["+experiment=iiwa7_random", f"dataset.path={tiny_dataset}"])
    env = make_env(cfg, EnvRequest("test", num_envs=2), **EVAL_ENV)
    assert built == {"robot": 1, "fk": 0}  # no TCP observation, reward or feedback: none needed yet
    assert env.fk is env.fk and built == {"robot": 1, "fk": 1}  # the metrics' (pathrl.eval.evaluate)


def test_the_ball_env_its_ball_tcp_terms_and_controller_share_one(tiny_dataset, built):
    cfg = _cfg(["+experiment=iiwa7_ball_balancing_tcp", f"dataset.path={tiny_dataset}", "task.backend=analytic",
                "task.imu=true", "init_from=null"])
    env = make_env(cfg, EnvRequest("test", num_envs=2), **EVAL_ENV)
    env.step(torch.zeros(env.num_envs, env.num_actions))  # TCP observations of the stepped state
    controller = make_controller({"name": "tray"}, env)
    assert env.feedback.fk is env.fk and env.feedback.imu.fk is env.fk and controller.fk is env.fk
    assert built == {"robot": 1, "fk": 1}


def test_a_trueadapt_env_its_ball_and_controller_share_one(tiny_trueadapt, built):
    cfg = _cfg(["+experiment=iiwa7_trueadapt_on_plate_ppo", f"dataset.path={tiny_trueadapt.path}"])
    env = make_env(cfg, EnvRequest("test", num_envs=2), autoreset=False)
    controller = make_controller({"name": "trueadapt_tray"}, env)
    assert env.ball.fk is env.fk and controller.fk is env.fk
    assert built == {"robot": 1, "fk": 1}
