"""TrueAdapt termination reasons (issue 23): one ``env.termination`` code per env and step from the pure terms of
pathrl.envs.terminations, read by the episode log and the evaluation."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from pathrl.cli.common import CONF_DIR
from pathrl.dataset.trueadapt import bank_from_arrays
from pathrl.envs.terminations import ADAPT_ENDINGS, TerminationReason, first_reason, task_failed
from pathrl.envs.trueadapt import AdaptEnvCfg, TrueAdaptEnv, ball_lost
from pathrl.envs.trueadapt_rewards import build_adapt_reward
from pathrl.eval.trueadapt import run_trajectories
from pathrl.robot.external import load_robot_by_name

R = TerminationReason
ROBOT = load_robot_by_name("iiwa7")
TERMS = OmegaConf.to_container(OmegaConf.load(CONF_DIR / "reward" / "trueadapt_on_plate.yaml"))["terms"]


def _b(*xs: int) -> torch.Tensor:
    return torch.tensor(xs, dtype=torch.bool)


def _env(n: int, **kw) -> TrueAdaptEnv:
    """n envs without autoreset on a bank of two trajectories: 0 a slow swing of 40 steps of 50 ms, 1 one step
    holding still (it ends after one step, long before the ball can reach the border)."""
    lim = ROBOT.pos_limits
    t = np.arange(41)[:, None] * 0.05
    swing = lim.mean(1) + 0.1 * (lim[:, 1] - lim[:, 0]) * np.sin(np.pi * t / (2.0 * t[-1])) ** 2
    hold = np.repeat(swing[:1], 2, axis=0)
    cfg = AdaptEnvCfg(num_envs=n, autoreset=False, max_joint_deviation=0.05, **kw)
    return TrueAdaptEnv(cfg, ROBOT, bank_from_arrays([swing, hold], 0.05), build_adapt_reward(TERMS))


def _hand_made_step(env: TrueAdaptEnv) -> tuple[torch.Tensor, dict]:
    """Env 0 deviates, 1 loses the ball, 2 reaches the end, 3 goes on, 4 deviates and loses the ball in the
    same step; every env replays the reference. Returns dones and the episode log."""
    env.start(torch.arange(env.num_envs), torch.tensor([0, 0, 1, 0, 0][:env.num_envs]))  # env 2: one step
    env.pos[0, 0] += 0.2  # 0.2 rad off the reference > max_joint_deviation
    env.pos[4, 0] += 0.2
    env.ball.on[[1, 4]] = False  # the ball left the plate
    env._refresh()
    _, _, dones, extras = env.step(env.reference_actions())
    return dones, extras["log"]


def test_pure_terms_by_hand():
    assert ADAPT_ENDINGS == (R.DEVIATION, R.TASK_FAILED, R.TRAJECTORY_END)
    assert R.TRAJECTORY_END.label == "trajectory_end" and int(R.TRAJECTORY_END) == 5
    assert task_failed(_b(1, 0), True).tolist() == [True, False]
    assert task_failed(_b(1, 0), False).tolist() == [False, False]
    on, rel, offset = _b(1, 0, 1, 1), torch.tensor([0.5, 0.5, 1.0, 0.2]), torch.tensor([0.0, 0.0, 0.01, 0.07])
    assert ball_lost(on, rel, offset, "on_plate", 0.06).tolist() == [False, True, True, False]
    assert ball_lost(on, rel, offset, "in_place", 0.06).tolist() == [False, True, False, True]
    masks = (_b(1, 0, 0, 0, 1), _b(0, 1, 0, 0, 1), _b(1, 1, 1, 0, 1))
    r = first_reason(list(zip(ADAPT_ENDINGS, masks, strict=True)))
    assert r.dtype == torch.int8 and r.tolist() == [R.DEVIATION, R.TASK_FAILED, R.TRAJECTORY_END, R.NONE, R.DEVIATION]


def test_one_reason_per_env_in_a_hand_made_step():
    env = _env(5)
    dones, log = _hand_made_step(env)
    assert env.termination.dtype == torch.int8
    assert env.termination.tolist() == [R.DEVIATION, R.TASK_FAILED, R.TRAJECTORY_END, R.NONE, R.DEVIATION]
    assert dones.tolist() == [True, True, True, False, True]
    assert env.last_step["termination"] is env.termination
    assert env.last_step["success"].tolist() == [False, False, True, False, False]
    assert env.last_step["failed"].tolist() == [False, True, False, False, True]
    assert float(log["Episode_Termination/deviation"]) == pytest.approx(0.5)  # shares of the 4 ended episodes
    assert float(log["Episode_Termination/task_failed"]) == pytest.approx(0.25)
    assert float(log["Episode_Termination/trajectory_end"]) == pytest.approx(0.25)
    assert float(log["Metrics/success"]) == pytest.approx(0.25)


def test_without_fail_terminates_a_lost_ball_goes_on_and_is_no_success_at_the_end():
    env = _env(5, fail_terminates=False)
    dones, _ = _hand_made_step(env)
    assert env.termination.tolist() == [R.DEVIATION, R.NONE, R.TRAJECTORY_END, R.NONE, R.DEVIATION]
    assert dones.tolist() == [True, False, True, False, True]
    for _ in range(int(env.bank.steps[0]) - 1):
        env.step(env.reference_actions())
    assert int(env.termination[1]) == R.TRAJECTORY_END and not bool(env.last_step["success"][1])
    assert int(env.termination[3]) == R.TRAJECTORY_END  # a success only if its ball stayed on (the dynamics')
    assert bool(env.last_step["success"][3]) is not bool(env.failed[3])


def test_the_evaluation_reads_the_reason():
    """Env 0 holds still to the end; 1 loses the ball in the last step (task_failed wins over the end); 2 leaves
    the swing at full acceleration."""
    env = _env(3)

    def policy(e: TrueAdaptEnv) -> torch.Tensor:
        if int(e.episode_length_buf[1]) == 0:
            e.ball.on[1] = False
        a = e.reference_actions()
        a[2] = 1.0
        return a

    out = run_trajectories(env, policy, torch.tensor([1, 1, 0]))
    assert out["success"].tolist() == [1.0, 0.0, 0.0]
    assert out["failed"].tolist() == [0.0, 1.0, 0.0]
    assert out["dev_terminated"].tolist() == [0.0, 0.0, 1.0]
