"""TrueAdapt (issue 20): reward terms, clipped actions inside the valid range, the env contract, the generator, a
2-iteration training run."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from omegaconf import OmegaConf

from pathrl.cli.common import CONF_DIR
from pathrl.datagen.trueadapt import mirror_variants
from pathrl.dataset.io import DatasetError
from pathrl.dataset.trueadapt import bank_from_arrays, load_trajectories
from pathrl.envs.terminations import TerminationReason
from pathrl.envs.trueadapt import AdaptEnvCfg, TrueAdaptEnv, clip_to_range
from pathrl.envs.trueadapt_rewards import (
    AdaptQuantities,
    acceleration_penalty,
    build_adapt_reward,
    deviation_penalty,
    in_place,
    jerk_penalty,
    on_plate,
)
from pathrl.limits.check import limit_violations
from pathrl.models import model_dir
from pathrl.robot.external import load_robot_by_name

ROBOT = load_robot_by_name("iiwa7")
TERMS = OmegaConf.to_container(OmegaConf.load(CONF_DIR / "reward" / "trueadapt_on_plate.yaml"))["terms"]
T64 = dict(dtype=torch.float64)


def _q(**kw) -> AdaptQuantities:
    n = len(next(iter(kw.values())))
    base = dict(acc_norm=torch.zeros(n, 2, **T64), jerk=torch.zeros(n, 2, **T64),
                jerk_max=torch.tensor([10.0, 10.0], **T64), deviation=torch.zeros(n, **T64),
                ball_rel=torch.zeros(n, **T64), ball_offset=torch.zeros(n, **T64), ball_ok=torch.ones(n, **T64))
    return AdaptQuantities(**{**base, **{k: torch.as_tensor(v, **T64) for k, v in kw.items()}})


# ------------------------------------------------------------------------------------------------ reward terms
def test_acceleration_penalty_by_hand():
    q = _q(acc_norm=[[0.1, 0.2], [0.6, 0.1], [1.0, 0.0]])
    assert acceleration_penalty(q, threshold=0.2).tolist() == pytest.approx([0.0, 0.25, 1.0])


def test_jerk_penalty_by_hand():
    # j_sat = (10^2 + 10^2) / 2 = 100; j_p = 0, 9 + 16 = 25, 200 -> 0, (25/100)^2, 1
    q = _q(jerk=[[0.0, 0.0], [3.0, 4.0], [10.0, 10.0]])
    assert jerk_penalty(q, c=2.0).tolist() == pytest.approx([0.0, 0.0625, 1.0])


def test_deviation_penalty_by_hand():
    q = _q(deviation=[0.01, math.radians(4.0), math.radians(10.0)])
    assert deviation_penalty(q, low=math.radians(2.0), high=math.radians(6.0)).tolist() == pytest.approx([0, 0.25, 1])


def test_task_terms_by_hand():
    q = _q(ball_rel=[0.5, 0.8, 1.2, 0.5], ball_ok=[1.0, 1.0, 1.0, 0.0], ball_offset=[0.0, 0.03, 0.1, 0.0])
    assert on_plate(q, inner=0.6).tolist() == pytest.approx([1.0, 0.75, 0.0, 0.0])
    assert in_place(q, radius=0.06).tolist() == pytest.approx([1.0, 0.25, 0.0, 0.0])


def test_the_reward_is_the_papers_product_and_a_zero_weight_removes_a_penalty():
    values = {"on_plate": torch.tensor([0.75]), "acceleration_penalty": torch.tensor([0.25]),
              "jerk_penalty": torch.tensor([0.0625]), "deviation_penalty": torch.tensor([0.25])}
    r = build_adapt_reward(TERMS)
    assert float(r.combine(values)) == pytest.approx(0.75 * (1 - (0.25 + 0.0625) / 2) * (1 - 0.25))
    no_jerk = build_adapt_reward({**TERMS, "jerk_penalty": {**TERMS["jerk_penalty"], "weight": 0.0}})
    assert float(no_jerk.combine(values)) == pytest.approx(0.75 * (1 - 0.25 / 2) * 0.75)


@pytest.mark.parametrize("terms, msg", [
    ({"acceleration_penalty": {"weight": 1.0}}, "exactly one task term"),
    ({"on_plate": {"weight": 1.0}, "in_place": {"weight": 1.0}}, "exactly one task term"),
    ({"on_plate": {"weight": 1.0}, "path_length": {"weight": 1.0}}, "unknown TrueAdapt reward term"),
    ({"on_plate": {"weight": 1.0, "iner": 0.5}}, "did you mean inner"),
    ({"on_plate": {"weight": 2.0}}, "must be in [0, 1]"),
    ({"on_plate": {}}, "weight is missing"),
    ({"on_plate": {"weight": 1.0}, "deviation_penalty": {"weight": 1.0, "low": 0.1, "high": 0.05}}, "low < high"),
    ({"on_plate": {"weight": 1.0, "inner": 1.0}}, "inner must be in"),
])
def test_bad_reward_configs_are_refused(terms, msg):
    with pytest.raises(ValueError, match=msg.replace("[", r"\[").replace("]", r"\]")):
        build_adapt_reward(terms)


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 5), st.floats(0.0, 5.0), st.floats(0.0, 0.99), st.floats(0.1, 1000.0))
def test_every_term_and_the_reward_stay_in_0_1(n, scale, threshold, c):
    g = torch.Generator().manual_seed(n)
    q = AdaptQuantities(acc_norm=scale * torch.rand(n, 7, generator=g, **T64),
                        jerk=1000.0 * scale * torch.rand(n, 7, generator=g, **T64),
                        jerk_max=torch.as_tensor(ROBOT.jerk_limits),
                        deviation=scale * torch.rand(n, generator=g, **T64),
                        ball_rel=scale * torch.rand(n, generator=g, **T64),
                        ball_offset=0.1 * scale * torch.rand(n, generator=g, **T64),
                        ball_ok=(torch.rand(n, generator=g) > 0.3).to(torch.float64))
    terms = {**TERMS, "acceleration_penalty": {"weight": 1.0, "threshold": threshold},
             "jerk_penalty": {"weight": 1.0, "c": c}}
    r = build_adapt_reward(terms)
    values = r.terms(q)
    for v in [*values.values(), r.combine(values)]:
        assert v.shape == (n,) and bool(((v >= 0.0) & (v <= 1.0)).all())


# ------------------------------------------------------------------------------------------------ env
def _bank(n: int = 4, steps: int = 120, amp: float = 0.35, seed: int = 0):
    """Smooth synthetic trajectories from rest (sin^2 swings from the middle of each joint's range), every 50 ms."""
    rng = np.random.default_rng(seed)
    lim = ROBOT.pos_limits
    t = np.arange(steps + 1)[:, None] * 0.05
    trajs = []
    for _ in range(n):
        f = rng.choice([1.0, 2.0], (1, 7)) / (2.0 * t[-1])  # at rest at both ends
        sign = rng.choice([-1.0, 1.0], (1, 7))
        trajs.append(lim.mean(1) + sign * amp * (lim[:, 1] - lim[:, 0]) / 2 * np.sin(np.pi * f * t) ** 2)
    return bank_from_arrays(trajs, 0.05)


def _env(n=8, bank=None, **kw) -> TrueAdaptEnv:
    return TrueAdaptEnv(AdaptEnvCfg(num_envs=n, **kw), ROBOT, bank or _bank(), build_adapt_reward(
        TERMS if kw.get("mode", "on_plate") == "on_plate" else {"in_place": {"weight": 1.0}}))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=7, max_size=7),
       st.lists(st.floats(-20.0, 20.0), min_size=14, max_size=14))
def test_clipped_action_is_inside_the_valid_range(action, bounds):
    lo = torch.tensor(bounds[:7], **T64)
    hi = torch.maximum(lo, torch.tensor(bounds[7:], **T64))
    a = clip_to_range(torch.tensor([action], **T64), torch.as_tensor(ROBOT.acc_limits), lo[None], hi[None])
    assert bool(((a >= lo) & (a <= hi)).all())


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1), bias=st.lists(st.floats(-1.0, 1.0), min_size=7, max_size=7),
       noise=st.floats(0.0, 1.5))
def test_random_actions_keep_every_limit_on_the_continuous_trajectory(seed, bias, noise):
    """Persistent, noisy (often saturated) actions drive the joints into their limits; the clipped accelerations
    stay in the valid range and the control-rate trajectory keeps position, velocity, acceleration and jerk."""
    env = _env(n=4, bank=_bank(n=2, steps=200, amp=0.9, seed=seed % 7), seed=seed, fail_terminates=False,
               max_joint_deviation=100.0)
    env.record_setpoints = True
    gen = torch.Generator().manual_seed(seed)
    b = torch.tensor(bias, **T64)
    qs, vs, accs = [], [], []
    for _ in range(70):
        lo, hi = env.a_min.clone(), env.a_max.clone()
        env.step((b + noise * torch.randn(4, 7, generator=gen, **T64)).clamp(-1.0, 1.0))
        a1 = env.last_step["a1"]
        assert bool(((a1 >= lo) & (a1 <= hi)).all())
        qs.append(env.last_step["q_control"])
        vs.append(env.last_step["v_control"])
        accs.append(env.last_step["a_control"])
    counts = limit_violations(torch.cat(qs, 1), torch.cat(vs, 1), torch.cat(accs, 1), env.limits, 1.0 / 240.0)
    assert int(counts["total"].sum()) == 0, {k: int(v.sum()) for k, v in counts.items()}


def test_reset_and_step_contract():
    env = _env(n=6)
    obs = env.reset()
    assert obs["policy"].shape == (6, env.num_obs) and obs["policy"].dtype == torch.float32
    assert env.num_obs == 3 * 7 + 4 + 7 and env.num_actions == 7 and env.max_episode_length == 120
    assert bool((obs["policy"].abs() <= 1.0).all())
    for _ in range(3):
        obs, rew, dones, extras = env.step(torch.zeros(6, 7))
    assert rew.shape == (6,) and rew.dtype == torch.float32 and bool(((rew >= 0) & (rew <= 1)).all())
    assert dones.dtype == torch.bool and not bool(extras["time_outs"].any())
    # action 0 keeps the acceleration at 0 while the reference moves on: the deviation grows, the reward falls
    assert bool((env.last_step["deviation"] > 0).all())
    big = _env(n=2, n_following=10)
    assert big.num_obs == env.num_obs + 9 * 7
    assert _env(n=2, mode="in_place").num_obs == env.num_obs + 2
    assert _env(n=2, obs_position=False, obs_velocity=False).num_obs == env.num_obs - 14


def test_the_critic_group_holds_the_time_left_and_the_true_ball_and_leaves_the_policy_state_alone():
    plain, env = _env(n=4, seed=5), _env(n=4, seed=5, critic_obs=True)
    obs = env.get_observations()
    assert "critic" not in plain.get_observations().keys() and obs["critic"].shape == (4, 5)
    assert torch.allclose(obs["critic"][:, 0], torch.full((4,), 120 * 0.05 / 10.0))  # 120 steps of 50 ms left
    for _ in range(3):
        prev = env.ball.xy.clone()
        op, *_ = plain.step(torch.full((4, 7), 0.2))
        obs, *_ = env.step(torch.full((4, 7), 0.2))
        assert torch.equal(op["policy"], obs["policy"])  # same episodes, same state: the group is only added
    expected = torch.cat([torch.full((4, 1), 117 * 0.05 / 10.0, **T64), env.ball.xy / env.half,
                          (env.ball.xy - prev) / 0.05], dim=1)
    assert torch.allclose(obs["critic"].double(), expected, atol=1e-6)


def test_same_seed_same_episodes_and_a_deviation_ends_the_episode():
    a, b = _env(seed=3), _env(seed=3)
    for _ in range(4):
        oa, _, da, _ = a.step(torch.full((8, 7), 0.3))
        ob, _, db, _ = b.step(torch.full((8, 7), 0.3))
        assert torch.equal(oa["policy"], ob["policy"]) and torch.equal(da, db)
    env = _env(n=3, max_joint_deviation=0.01, fail_terminates=False)
    for _ in range(40):
        _, _, dones, _ = env.step(torch.ones(3, 7))
        if bool(dones.any()):
            break
    deviated = env.termination == TerminationReason.DEVIATION
    assert bool(deviated.any())
    assert int(env.episode_length_buf[deviated].max()) == 0  # reset on the spot


def test_replaying_the_reference_follows_it_exactly_to_the_end():
    env = _env(n=4, fail_terminates=False, autoreset=False)
    env.start(torch.arange(4), torch.arange(4))
    for k in range(120):
        _, _, dones, _ = env.step(env.reference_actions())
        assert float(env.last_step["deviation"].max()) < 1e-9
        assert float(env.last_step["term/deviation_penalty"].max()) == 0.0
        assert bool(dones.all()) == (k == 119)


def test_open_loop_freezes_the_ball_measurement_and_noise_is_applied():
    env = _env(n=4, obs_ball=False, sensor_noise=0.0, fail_terminates=False)
    m0 = env.meas.clone()
    for _ in range(5):
        env.step(env.reference_actions())
    moved = env.ball.xy - env.start_xy
    assert torch.equal(env.meas, m0) and float(moved.abs().max()) > 0.0
    noisy = _env(n=64, sensor_noise=0.01)
    assert 0.005 < float((noisy.meas - noisy.ball.xy).std()) < 0.02


def test_evaluation_runs_each_trajectory_once_and_reports_the_papers_metrics():
    from pathrl.eval.trueadapt import evaluate, reference_policy

    with pytest.raises(ValueError, match="autoreset=False"):
        evaluate(_env(n=2), reference_policy, torch.arange(2))
    env = _env(n=4, autoreset=False, fail_terminates=False)
    m = evaluate(env, reference_policy, torch.tensor([0, 1, 2, 3, 0, 1]))
    assert all(v.shape == (6,) for v in m.values())
    assert bool(((m["fraction"] >= 0) & (m["fraction"] <= 1)).all()) and bool((m["acc"] > 0).all())
    assert bool((m["fraction"][m["success"] == 1] == 1).all())  # a success executes the whole trajectory
    assert torch.allclose(m["acc"][:2], m["acc"][4:], rtol=0, atol=1e-12)  # the same replay, whole trajectories


@pytest.mark.parametrize("kw, key", [({"mode": "x"}, "mode"), ({"n_following": -1}, "n_following"),
                                     ({"ball_radius": (0.03, 0.02)}, "ball_radius"), ({"dt": 0.051}, "control_rate")])
def test_bad_env_settings_are_refused(kw, key):
    with pytest.raises(ValueError, match=key):
        AdaptEnvCfg(**kw)


@pytest.mark.parametrize("mode", ["random", "max"])
def test_random_and_maximal_accelerations_from_the_valid_range_keep_every_limit(mode):
    """TrueAdapt Sec. VI-D at a small count (docs/trueadapt.md: 10^5 trajectories)."""
    from pathrl.eval.trueadapt_validation import validate
    from pathrl.limits.feasible import JointLimits

    res = validate(JointLimits.from_robot(ROBOT), 300, 80, mode=mode, seed=5)
    assert res.violations["total"] == 0, res.violations
    assert res.setpoints_checked == 300 * 80 * 12 * 7
    assert min(res.max_ratio.values()) > 0.99  # the limits are reached, not avoided


def test_a_traced_trajectory_is_continuous_and_within_the_limits():
    from pathrl.eval.trueadapt_validation import trace
    from pathrl.limits.feasible import JointLimits

    limits = JointLimits.from_robot(ROBOT)
    tr = trace(limits, 40, mode="max", seed=2)
    assert tr["p"].shape == (1 + 40 * 12, 7) and tr["t"][-1] == pytest.approx(2.0)
    assert float(tr["v"][0].abs().max()) == 0.0 and float(tr["a"][0].abs().max()) == 0.0
    assert float((tr["p"][1:] - tr["p"][:-1]).abs().max()) < limits.vel.max() / 240 * 1.001  # no jumps
    assert int(limit_violations(tr["p"], tr["v"], tr["a"], limits, 1 / 240)["total"]) == 0


# ------------------------------------------------------------------------------------------------ generator
def test_generator_tiny(tiny_trueadapt):
    from pathrl.robot.kinematics import ForwardKinematics

    ds = tiny_trueadapt
    p = ds.meta["generator"]["params"]
    assert ds.meta["kind"] == "trueadapt" and ds.meta["sample_dt"] == 0.05
    assert [len(s) for s in ds.splits.values()] == [4, 4]  # one drawn trajectory per split, mirrored x4
    assert ds.splits["train"].names == tuple(f"train_00000_m{k}" for k in range(4))
    fk = ForwardKinematics(ROBOT)
    areas = np.asarray(p["areas"])
    tcps = []
    for q in ds.splits["train"].knots:
        assert np.all(q >= ROBOT.pos_limits[:, 0]) and np.all(q <= ROBOT.pos_limits[:, 1])
        pos, rot = fk.tcp_transforms(q)
        assert float((rot[:, 0, :, 2] - torch.tensor([0.0, 0.0, 1.0], **T64)).abs().max()) < 1e-9  # plate level
        speed = np.abs(np.diff(q, axis=0)) / 0.05  # mean velocity between samples <= the TOPP-RA limit
        assert np.all(speed <= p["vel_scale"] * ROBOT.vel_limits * (1 + 1e-6))
        assert np.allclose(q[-1], q[-2], atol=0.02)  # comes to rest
        tcps.append(pos[:, 0].numpy())
    start, end = tcps[0][0], tcps[0][-1]
    assert np.all((start[:2] >= areas[0, :, 0] - 1e-4) & (start[:2] <= areas[0, :, 1] + 1e-4))
    assert np.all((end[:2] >= areas[-1, :, 0] - 1e-4) & (end[:2] <= areas[-1, :, 1] + 1e-4))
    expect = mirror_variants(np.stack([start, end]), p["mirror_x"])
    for k in range(4):
        assert np.allclose(tcps[k][[0, -1]], expect[k], atol=1e-4)


def test_trajectories_load_and_info_prints_their_statistics(tiny_trueadapt, tiny_dataset):
    from pathrl.cli.dataset import print_info

    bank = load_trajectories(str(tiny_trueadapt.path), "test", ROBOT, 0.05)
    assert bank.num == 4 and bank.pos.shape[2] == 7
    with pytest.raises(DatasetError, match="sampled every"):
        load_trajectories(str(tiny_trueadapt.path), "test", ROBOT, 0.1)
    with pytest.raises(DatasetError, match="not a trueadapt trajectory set"):
        load_trajectories(str(tiny_dataset), "train", ROBOT, 0.05)
    out = io.StringIO()
    print_info(tiny_trueadapt.meta, str(tiny_trueadapt.path), out)
    assert "train 4 trajectories, duration" in out.getvalue()


# ------------------------------------------------------------------------------------------------ training
def test_two_iteration_training_run(tiny_trueadapt, tmp_path):
    from pathrl.cli.common import compose, to_container
    from pathrl.schema import TrainAppCfg
    from pathrl.train.runner import train

    run_dir = tmp_path / "run"
    cfg = to_container(compose("train", ["+experiment=iiwa7_trueadapt_on_plate", f"dataset.path={tiny_trueadapt.path}",
                                         "iterations=2", "env.num_envs=16", f"run_dir={run_dir}",
                                         "compile_limits=false", "threads=1"], TrainAppCfg))
    summary = train(cfg, Path(run_dir))
    assert summary["iterations"] == 2 and summary["env_steps"] == 2 * 16 * cfg["agent"]["num_steps_per_env"]
    assert (run_dir / "model_1.pt").is_file() and (run_dir / "run.mcap").is_file()


def test_the_pybullet_ball_runs_the_same_env(tiny_trueadapt):
    """task.backend=pybullet (evaluation): the PyBullet scene replaces the analytic ball behind the same env."""
    from pathrl.cli.common import compose, to_container
    from pathrl.envs.trueadapt import build_trueadapt_env
    from pathrl.eval.trueadapt import evaluate, reference_policy
    from pathrl.schema import TrainAppCfg

    cfg = to_container(compose("train", ["+experiment=iiwa7_trueadapt_in_place", f"dataset.path={tiny_trueadapt.path}",
                                         "task.backend=pybullet", "task.workers=1"], TrainAppCfg))
    env = build_trueadapt_env(cfg, "test", num_envs=2, autoreset=False)
    try:
        m = evaluate(env, reference_policy, torch.arange(2))
        assert type(env.ball).__name__ == "PyBulletBall"
        assert bool((m["acc"] > 0).all()) and bool((m["offset"] > 0).all())  # the plate moves, so does the ball
    finally:
        env.close()


ROOT = Path(__file__).resolve().parents[1]
SCRATCH = "iiwa7_trueadapt_on_plate_ppo_scratch"
#: Each from-scratch ablation: how many policy inputs it drops (7 joints per state part; reward ablations drop none).
ABLATIONS = {"": 0, "_no_position": 7, "_no_velocity": 7, "_no_acceleration": 7, "_no_following": 7,
             "_no_acc_penalty": 0, "_no_jerk_penalty": 0, "_open_loop": 0, "_f10": -63}  # f10: 9 more positions
IN_PLACE = "iiwa7_trueadapt_in_place_ppo_scratch"


def _input_dims(checkpoint: Path) -> tuple[int, int]:
    """(actor, critic) input widths of a checkpoint, from their observation normalisers."""
    sd = torch.load(checkpoint, weights_only=True)
    return tuple(int(sd[f"{net}_state_dict"]["obs_normalizer._mean"].shape[1]) for net in ("actor", "critic"))


@pytest.mark.parametrize("full,variant", [(SCRATCH, v) for v in ABLATIONS] + [(IN_PLACE, ""), (IN_PLACE, "_open_loop")])
def test_each_from_scratch_recipe_trains(full, variant, tiny_trueadapt, tmp_path):
    """The TrueAdapt table's from-scratch rows of both tasks, each for 2 tiny iterations: no warm start, the critic
    sees the policy's state plus its privileged part, and a state ablation drops its part from both."""
    from pathrl.cli.common import compose, to_container
    from pathrl.schema import TrainAppCfg
    from pathrl.train.runner import train

    run_dir = tmp_path / "run"
    cfg = to_container(compose("train", [f"+experiment={full}{variant}", f"dataset.path={tiny_trueadapt.path}",
                                         "iterations=2", "env.num_envs=16", f"run_dir={run_dir}",
                                         "compile_limits=false", "threads=1"], TrainAppCfg))
    assert cfg.get("init_from") is None
    assert cfg["task"]["observe"] is (variant != "_open_loop")
    assert train(cfg, Path(run_dir))["iterations"] == 2
    actor, critic = _input_dims(run_dir / "model_1.pt")
    full_actor, full_critic = _input_dims(model_dir(full) / "model.pt")
    assert critic > actor  # the asymmetric critic
    assert (full_actor - actor, full_critic - critic) == (ABLATIONS[variant], ABLATIONS[variant])
