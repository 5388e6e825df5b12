"""Output-bias search (pathrl.train.bias_search): the optimiser on known objectives, the training return of a fixed
plan, the search on a real actor and env, and pathrl-train's bias_search group."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from test_env import make_env
from test_train import run, train_cmd

from pathrl.paths.segments import evaluation_plan
from pathrl.train.bias_search import BiasSearchCfg, episode_returns, output_layer, search_bias, search_output_bias
from pathrl.train.ship import ship


def test_search_finds_the_maximum_of_a_quadratic_inside_the_bounds():
    c = np.array([0.3, -0.55, 0.0])
    best, value, start, evals = search_bias(lambda x: -float(((x - c) ** 2).sum()), 3, max_evals=300, bound=1.0)
    np.testing.assert_allclose(best, c, atol=0.02)
    assert value == pytest.approx(0.0, abs=1e-3) and evals <= 302 and start == pytest.approx(-(c**2).sum())


def test_search_stays_at_zero_when_zero_is_best_and_respects_the_bound():
    best, value, _, _ = search_bias(lambda x: -float(np.abs(x).sum()), 4, max_evals=100, bound=0.5)
    assert np.array_equal(best, np.zeros(4)) and value == 0.0
    best, _, _, _ = search_bias(lambda x: float(x[0]), 1, max_evals=100, bound=0.5)  # the maximum is on the bound
    assert 0.45 <= best[0] <= 0.5


def _policy(env, bias: float):
    """An actor whose action is a constant: zero weights, `bias` on every output."""
    net = torch.nn.Sequential(torch.nn.Linear(env.num_obs, 8), torch.nn.ELU(), torch.nn.Linear(8, env.num_actions))
    with torch.no_grad():
        for p in net.parameters():
            p.zero_()
        net[-1].bias.fill_(bias)
    return lambda obs: net(obs["policy"]), net


def test_episode_returns_sum_each_episodes_rewards_to_its_end():
    env, _ = make_env(num_envs=6)
    policy, _ = _policy(env, 0.3)
    plan = evaluation_plan(env.paths, 6, "paper", seed=1)
    got, steps = episode_returns(env, policy, plan)
    env.start_segments(torch.arange(6), plan)  # the same pass, by hand: rewards until each env's first done
    total, ended, taken = torch.zeros(6, dtype=torch.float64), torch.zeros(6, dtype=torch.bool), 0
    while not bool(ended.all()):
        taken += 1
        _, r, dones, _ = env.step(policy(env.get_observations()))
        total += torch.where(ended, 0.0, r.double())
        ended |= dones
    torch.testing.assert_close(got, total)
    assert bool((got > 0).all()) and steps == 6 * taken
    torch.testing.assert_close(episode_returns(env, policy, plan)[0], got)  # a deterministic function of the plan


def test_search_moves_the_output_bias_in_place_and_never_lowers_the_return():
    env, _ = make_env(num_envs=8)
    _, net = _policy(env, -0.8)  # brakes hard everywhere: a poor start

    class Actor(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.net = net

        def forward(self, obs):
            return self.net(obs["policy"])

    actor = Actor()
    before = output_layer(actor).bias.detach().clone()
    rec = search_output_bias(env, actor, BiasSearchCfg(episodes=8, max_evals=40))
    assert rec["mean_return_after"] > rec["mean_return_before"] and rec["evaluations"] <= 42
    assert rec["env_steps"] >= 8 * rec["evaluations"]
    torch.testing.assert_close(output_layer(actor).bias.detach(), before + torch.tensor(rec["offsets"]))
    assert max(abs(x) for x in rec["offsets"]) <= 1.0


def test_bias_search_config_is_validated():
    with pytest.raises(ValueError, match="bias_search.episodes"):
        BiasSearchCfg(episodes=0)
    with pytest.raises(ValueError, match="bias_search.bound"):
        BiasSearchCfg(bound=0.0)


def test_train_runs_the_search_before_ppo_and_records_it(tiny_dataset, tmp_path):
    run_dir = tmp_path / "bias"
    r = run(train_cmd(tiny_dataset, run_dir, 1, "+bias_search.episodes=8", "+bias_search.max_evals=5"))
    assert r.returncode == 0, r.stderr[-2000:]
    assert "bias_search: mean training return" in r.stderr
    summary = json.loads((run_dir / "summary.json").read_text())
    rec = summary["bias_search"]
    assert rec["episodes"] == 8 and 1 <= rec["evaluations"] <= 7 and len(rec["offsets"]) == 7
    assert rec["mean_return_after"] >= rec["mean_return_before"]
    # the search is training time: in the wall time and the env steps (1 PPO iteration = 32 envs x 8 steps)
    assert summary["wall_time_s"] >= rec["wall_time_s"] and summary["env_steps"] == 32 * 8 + rec["env_steps"]
    shipped = json.loads((ship(run_dir, tmp_path / "model") / "summary.json").read_text())
    assert shipped["env_steps"] == summary["env_steps"] and shipped["wall_time_s"] >= rec["wall_time_s"]
