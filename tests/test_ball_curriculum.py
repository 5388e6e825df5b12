"""The curriculum on the ball (``task.curriculum``): its schedule by hand, its effect on new balls, and a tiny
training run with it (and the one-line refusal without an analytic ball to apply it to)."""

import math

import pytest
import torch

from pathrl.robot.external import load_robot_by_name
from pathrl.schema import BallCurriculumCfg
from pathrl.sim.feedback import AnalyticBall
from pathrl.train.curricula import curriculum_scales
from tests.test_train import run, train_cmd


def test_schedule_by_hand():
    cur = BallCurriculumCfg(iterations=100, friction_scale=100.0, start_spread=0.2)
    assert curriculum_scales(0, cur) == pytest.approx((100.0, 0.2))
    # half way: log-linear friction 100 ** 0.5 = 10, linear spread 0.2 + 0.8 * 0.5 = 0.6
    assert curriculum_scales(50, cur) == pytest.approx((10.0, 0.6))
    assert curriculum_scales(100, cur) == pytest.approx((1.0, 1.0))
    assert curriculum_scales(5000, cur) == pytest.approx((1.0, 1.0))  # and stays there


def test_new_balls_follow_the_curriculum():
    iiwa = load_robot_by_name("iiwa7")
    q = torch.zeros(64, 7, dtype=torch.float64)
    ids = torch.arange(64)
    ball = AnalyticBall(iiwa, 64, seed=0)
    ball.reset(ids, q)
    authors_mu, authors_xy = ball.roll_mu.clone(), ball.xy.clone()
    assert float(authors_xy.abs().max()) > 0.01  # spread over the placement area
    assert 1e-4 <= float(authors_mu.min()) and float(authors_mu.max()) <= 7e-4
    again = AnalyticBall(iiwa, 64, seed=0)
    again.set_curriculum(30.0, 0.0)
    again.reset(ids, q)
    # the same draws, scaled: every ball at the centre, 30x the rolling friction
    assert torch.equal(again.xy, torch.zeros_like(again.xy))
    assert torch.allclose(again.roll_mu, 30.0 * authors_mu)
    with pytest.raises(ValueError, match="roll_scale"):
        again.set_curriculum(0.5, 0.0)
    assert math.isclose(again.roll_scale, 30.0)  # a refused setting changes nothing


def test_tiny_training_with_the_curriculum_and_its_refusal(tiny_dataset, tmp_path):
    exp, cur = "+experiment=iiwa7_ball_balancing_reward_scratch_curriculum", "task.curriculum.iterations=2"
    r = run(train_cmd(tiny_dataset, tmp_path / "cur", 2, exp, cur))
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "cur" / "model_1.pt").exists()
    r = run(train_cmd(tiny_dataset, tmp_path / "pb", 1, exp, cur, "task.backend=pybullet"))
    assert r.returncode != 0
    assert "task.curriculum needs the analytic ball" in r.stderr.strip().splitlines()[-1]


def test_curriculum_reaches_the_ball_behind_a_frozen_sensor():
    """Open loop (the sensor frozen), the ball is still analytic: the curriculum sets it, now and after updates."""
    from types import SimpleNamespace

    from pathrl.sim.feedback import FrozenSensor
    from pathrl.train.curricula import apply_ball_curriculum

    ball = AnalyticBall(load_robot_by_name("iiwa7"), 8, seed=0)
    hooks = []
    runner = SimpleNamespace(env=SimpleNamespace(generator=None, feedback=FrozenSensor(ball)),
                             current_learning_iteration=50, after_each_update=hooks.append)
    apply_ball_curriculum(runner, BallCurriculumCfg(iterations=100, friction_scale=100.0, start_spread=0.2))
    assert math.isclose(ball.roll_scale, 10.0)  # iteration 50 of 100: 100 ** 0.5
    hooks[0](100)
    assert math.isclose(ball.roll_scale, 1.0)


def test_reward_weight_schedule_by_hand_and_on_the_env():
    """The path-length weight 1 -> 4 over 100 iterations: 2.5 half way, 4 from then on; set on the env's term."""
    from types import SimpleNamespace

    from pathrl.envs.rewards import build_reward_terms
    from pathrl.schema import RewardCurriculumCfg
    from pathrl.train.curricula import apply_reward_curriculum, reward_weight

    cur = RewardCurriculumCfg(term="path_length", initial=1.0, iterations=100)
    assert [reward_weight(it, cur, 4.0) for it in (0, 50, 100, 900)] == pytest.approx([1.0, 2.5, 4.0, 4.0])
    terms = build_reward_terms({"path_length": {"weight": 4.0}, "ball_centre": {"weight": 1.0}})
    hooks = []
    runner = SimpleNamespace(env=SimpleNamespace(generator=None, reward_terms=terms), current_learning_iteration=25,
                             after_each_update=hooks.append)
    apply_reward_curriculum(runner, cur)
    assert terms[0].weight == pytest.approx(1.75) and terms[1].weight == 1.0  # 1 + 3 * 25 / 100; the other kept
    hooks[0](100)
    assert terms[0].weight == pytest.approx(4.0)
    with pytest.raises(ValueError, match="the reward has no term 'ball'; it has path_length, ball_centre"):
        apply_reward_curriculum(runner, RewardCurriculumCfg(term="ball", initial=1.0))


def test_reward_curriculum_moves_every_named_term_to_its_own_weight():
    """deviation_max (0.9) and deviation_mean (0.5) from 2.7 over 100 iterations: at 50 each is half way to its own
    weight (1.8, 1.6), the path-length term untouched; a misspelt extra term is refused."""
    from types import SimpleNamespace

    from pathrl.envs.rewards import build_reward_terms
    from pathrl.schema import RewardCurriculumCfg
    from pathrl.train.curricula import apply_reward_curriculum

    terms = build_reward_terms({"path_length": {"weight": 4.0}, "deviation_max": {"weight": 0.9},
                                "deviation_mean": {"weight": 0.5}})
    hooks = []
    runner = SimpleNamespace(env=SimpleNamespace(generator=None, reward_terms=terms), current_learning_iteration=50,
                             after_each_update=hooks.append)
    cur = RewardCurriculumCfg(term="deviation_max", also=["deviation_mean"], initial=2.7, iterations=100)
    apply_reward_curriculum(runner, cur)
    assert [t.weight for t in terms] == pytest.approx([4.0, 1.8, 1.6])
    hooks[0](0)
    assert [t.weight for t in terms] == pytest.approx([4.0, 2.7, 2.7])
    hooks[0](150)
    assert [t.weight for t in terms] == pytest.approx([4.0, 0.9, 0.5])
    bad = RewardCurriculumCfg(term="deviation_max", also=["deviation_men"], initial=2.7)
    with pytest.raises(ValueError, match="no term 'deviation_men'"):
        apply_reward_curriculum(runner, bad)


def test_tiny_training_with_the_reward_curriculum(tiny_dataset, tmp_path):
    exp = "+experiment=iiwa7_ball_balancing_reward_scratch_length_curriculum"
    r = run(train_cmd(tiny_dataset, tmp_path / "rc", 2, exp, "reward_curriculum.iterations=2"))
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "rc" / "model_1.pt").exists()
    r = run(train_cmd(tiny_dataset, tmp_path / "bad", 1, exp, "reward_curriculum.term=lenght"))
    assert r.returncode != 0
    assert "the reward has no term 'lenght'" in r.stderr.strip().splitlines()[-1]
