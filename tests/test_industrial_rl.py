"""Learned waypoint adjustment (issue 21): features (eqs. 7-13), actions (eq. 14), rewards (eqs. 15-18), the
prioritized buffer, and a tiny TD3 run that checkpoints and resumes."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pathrl.industrial.features import (
    N_FEATURES,
    SLICES,
    Matched,
    action_steps,
    features,
    local_max,
    pca_shape,
    regions,
    rewards,
)
from pathrl.industrial.iwa_env import IWAEpisode, IWASettings
from pathrl.industrial.per import PrioritizedBuffer
from pathrl.industrial.trajectories import evaluation_targets

pytest.importorskip("torchrl")


def test_regions_and_position_feature_are_hand_computed():
    psi = np.array([0, 10, 30, 40])
    lo, hi = regions(psi)
    np.testing.assert_array_equal(lo, [0, 0, 10, 30])
    np.testing.assert_array_equal(hi, [10, 30, 40, 40])


def test_pca_of_a_straight_line_is_its_own_axis():
    pts = np.linspace([0.0, 0, 0], [30.0, 40, 0], 50)[None]  # one waypoint's region, chord 50 mm
    shape = pca_shape(pts)[0]
    np.testing.assert_allclose(shape[:, 0], np.linspace(-0.5, 0.5, 50), atol=1e-12)
    np.testing.assert_allclose(shape[:, 1:], 0.0, atol=1e-12)


def test_feature_vector_layout():
    n, m = 200, 5
    target = np.stack([np.linspace(0, 199, n), np.zeros(n), np.zeros(n)], 1)
    err = np.zeros((n, 3))
    err[:, 1] = 0.5  # executed path 0.5 mm beside the target everywhere
    psi = np.linspace(0, n - 1, m).round().astype(int)
    q = np.tile([0.0, 0.3, 0.0, 0.0, 1.0, 0.0], (m, 1))
    f = features(target, psi, Matched(err, np.zeros(n)), q)
    assert f.shape == (m, N_FEATURES)
    np.testing.assert_allclose(f[:, SLICES["p_error"]].reshape(m, 50, 3)[:, :, 1], 1.0)  # normalised by |e^i|
    np.testing.assert_allclose(f[:, SLICES["e"]], [[0.0, 0.5, 0.0]] * m)
    np.testing.assert_allclose(f[:, SLICES["f_position"]][:, 0], [0.0, 0.5, 0.5, 0.5, 1.0], atol=0.01)
    np.testing.assert_array_equal(f[:, SLICES["f_flag"]], [[1, 0], [0, 0], [0, 0], [0, 0], [0, 1]])
    pos, _ = local_max(Matched(err, np.zeros(n)), psi)
    np.testing.assert_allclose(pos, 0.5)


def test_action_frame_and_rewards_are_hand_computed():
    positions = np.array([[0.0, 0, 0], [10.0, 0, 0], [20.0, 0, 0]])
    e = np.array([[0.0, 2.0, 0.0]] * 3)
    # a = (1, 0, 0): move by |e| along e; a = (0, 1, 0): by |e| towards the previous waypoint; a3: e x prev
    np.testing.assert_allclose(action_steps(np.array([[1.0, 0, 0]] * 3), positions, e), e)
    np.testing.assert_allclose(action_steps(np.array([[0.0, 1, 0]] * 3), positions, e)[1], [-2.0, 0, 0])
    np.testing.assert_allclose(action_steps(np.array([[0.0, 0, 1]] * 3), positions, e)[1], [0, 0, 2.0])
    r, done = rewards(np.array([0.5, 6.0, 0.2]), np.zeros(3), np.array([1.0, 1.0, 0.4]), np.zeros(3),
                      np.array([2.0, 2.0, 2.0]), np.ones(3))
    np.testing.assert_allclose(r, [0.25, -2.5 - 100.0, 0.1 + 10.0])
    np.testing.assert_array_equal(done, [False, True, True])


def test_prioritized_buffer_samples_by_priority_with_importance_weights():
    buf = PrioritizedBuffer(8, 2, 1, alpha=1.0, beta=1.0, generator=torch.Generator().manual_seed(0))
    buf.add(torch.zeros(4, 2), torch.zeros(4, 1), torch.arange(4.0), torch.zeros(4, 2), torch.zeros(4))
    buf.update_priority(torch.arange(4), torch.tensor([0.0, 0.0, 1.0, 3.0]))
    batch = buf.sample(4000)
    counts = torch.bincount(batch["index"], minlength=4).double() / 4000
    assert counts[:2].sum() < 1e-3 and counts[3] / counts[2] == pytest.approx(3.0, rel=0.15)
    w = batch["priority_weight"]
    assert w.max() == pytest.approx(1.0) and w[batch["index"] == 3].max() < w[batch["index"] == 2].min()
    buf.add(torch.ones(6, 2), torch.zeros(6, 1), torch.zeros(6), torch.zeros(6, 2), torch.zeros(6))
    assert len(buf) == 8 and buf.cursor == 2  # ring buffer wrapped


def test_error_feedback_actions_lower_the_error_in_the_episode():
    t = evaluation_targets()[3]
    env = IWAEpisode(t, t.speed, settings=IWASettings(k_max=3))
    obs = env.reset()
    assert obs.shape == (100, N_FEATURES) and np.isfinite(obs).all()
    res = env.step(np.tile([0.5, 0.0, 0.0], (100, 1)))
    assert res.errors.max_pos_mm < 0.8 * env.best[0] or res.errors.max_pos_mm == env.best[0]
    assert res.obs.shape == (100, N_FEATURES) and res.reward.shape == (100,)


def test_tiny_td3_run_checkpoints_and_resumes(tmp_path):
    from pathrl.industrial.controller import ControllerParams
    from pathrl.industrial.rl import RLParams
    from pathrl.industrial.rl_train import load_agent, train

    params = RLParams(iterations=3, batch=64, warmup=1, buffer=2000, hidden=[16, 16], n_train=3, log_every=1,
                      checkpoint_every=2, k_max=2)
    out = train(tmp_path, params, ControllerParams())
    assert out["started_at"] == 0 and (tmp_path / "model_2.pt").exists() and (tmp_path / "model_3.pt").exists()
    agent, it = load_agent(tmp_path)
    assert it == 3 and agent.updates == 3 * 2  # 100 transitions per iteration: a batch from the first one
    more = RLParams(**{**params.__dict__, "iterations": 4})
    assert train(tmp_path, more, ControllerParams(), resume=True)["started_at"] == 3
    assert sorted(p.name for p in tmp_path.glob("train_*.mcap")) == ["train_000000.mcap", "train_000003.mcap"]
    act = agent.act(np.zeros((5, N_FEATURES)))
    assert act.shape == (5, 3) and np.all(np.abs(act) <= 1.0)


def test_training_is_deterministic_by_seed(tmp_path):
    from pathrl.industrial.controller import ControllerParams
    from pathrl.industrial.rl import RLParams
    from pathrl.industrial.rl_train import train
    from pathrl.storage import load_checkpoint

    params = RLParams(iterations=2, batch=64, warmup=1, buffer=1000, hidden=[16, 16], n_train=3, k_max=2)
    states = []
    for run in ("a", "b"):
        train(tmp_path / run, params, ControllerParams())
        states.append(load_checkpoint(tmp_path / run / "model_2.pt")["agent"]["loss"])
    assert states[0].keys() == states[1].keys()
    assert all(torch.equal(states[0][k], states[1][k]) for k in states[0])
