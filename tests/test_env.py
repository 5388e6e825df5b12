"""The batched tracking env: VecEnv contract, MDP details, online path replacement, the numpy oracle."""

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from pathrl.envs.observations import tcp_observation
from pathrl.envs.reference import ReferencePath, ReferenceSettings, ReferenceTrackingEnv
from pathrl.envs.rewards import StepQuantities, build_reward_terms, path_length, tcp_deviation
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.limits.braking import braking_acceleration
from pathrl.limits.feasible import JointLimits
from pathrl.paths.pathset import build_pathset
from pathrl.paths.segments import Segments
from pathrl.robot.external import load_robot_by_name

REWARD = {"path_length": {"weight": 2.0}, "deviation_max": {"weight": 0.9}, "deviation_mean": {"weight": 0.9},
          "action_saturation": {"weight": 0.4}}
ROBOTS = ["iiwa7", "armar6", "armar4", "armar4_legs"]


def smooth_paths(robot, n=4, seed=0):
    rng = np.random.default_rng(seed)
    lim = robot.pos_limits[robot.path_index]
    mid, half = lim.mean(1), 0.35 * (lim[:, 1] - lim[:, 0]) / 2
    t = np.linspace(0, 1, 120)[:, None]
    return [mid + half * np.sin(2 * np.pi * rng.uniform(0.5, 1.5, (1, len(mid))) * t
                                + rng.uniform(0, 6.28, (1, len(mid)))) for _ in range(n)]


def make_env(robot_name="iiwa7", num_envs=16, **kw):
    robot = load_robot_by_name(robot_name)
    knots = smooth_paths(robot)
    paths = build_pathset(knots, [f"p{i}" for i in range(len(knots))])
    cfg = TrackingEnvCfg(num_envs=num_envs, seed=0, **kw)
    return PathTrackingEnv(cfg, robot, paths, build_reward_terms(REWARD)), knots


@pytest.mark.parametrize("robot_name", ROBOTS)
def test_vecenv_contract(robot_name):
    env, _ = make_env(robot_name, num_envs=8)
    robot = env.robot
    obs = env.get_observations()
    assert isinstance(obs, TensorDict) and obs.batch_size == torch.Size([8])
    m, k = robot.path_dof, env.cfg.n_state
    assert obs["policy"].shape == (8, 3 * robot.dof + k * m + 2 + (k - 1))
    assert env.num_actions == robot.dof and env.episode_length_buf.shape == (8,)
    for _ in range(5):
        obs, rew, dones, extras = env.step(torch.randn(8, robot.dof) * 3)  # unclipped actions
        assert rew.shape == (8,) and dones.shape == (8,) and dones.dtype == torch.bool
        assert extras["time_outs"].shape == (8,)
        assert torch.isfinite(obs["policy"]).all() and torch.isfinite(rew).all()
        assert (obs["policy"].abs() <= 1).all() and (rew >= 0).all()


def test_tracking_exact_path_gives_full_reward_terms():
    q = StepQuantities(*(torch.tensor([x], dtype=torch.float64) for x in (0.5, 0.5, 8.0, 0.0, 0.0, 0.5)),
                       close_to_end=torch.tensor([False]))
    assert float(path_length(q)) == pytest.approx(1.0)
    q0 = StepQuantities(*(torch.tensor([x], dtype=torch.float64) for x in (0.0, 0.5, 8.0, 0.0, 0.0, 0.5)),
                        close_to_end=torch.tensor([False]))
    assert float(path_length(q0)) == pytest.approx(0.0)
    q_end = StepQuantities(*(torch.tensor([x], dtype=torch.float64) for x in (0.0, 0.0, 8.0, 0.0, 0.0, 0.5)),
                           close_to_end=torch.tensor([True]))
    assert float(path_length(q_end)) == pytest.approx(1.0)  # standing still at the end


def test_episode_ends_with_stop_after_path_end():
    env, _ = make_env(num_envs=4, segments="full", episode_budget_s=60.0)
    done_seen = torch.zeros(4, dtype=torch.bool)
    for _ in range(400):
        _, _, dones, extras = env.step(torch.ones(4, env.num_actions))  # full speed ahead
        stopped = env.last_step["stopped"]
        done_seen |= stopped
        assert not bool(extras["time_outs"].any())
        if bool(done_seen.all()):
            break
    assert bool(done_seen.all()), "robots must brake to a stop after the path end"


def test_replace_path_mid_episode():
    env, _ = make_env(num_envs=2)
    ids = torch.tensor([0, 1])
    env.start_segments(ids, Segments(torch.tensor([0, 0]), torch.zeros(2, dtype=torch.float64),
                                     env.paths.length[[0, 0]].clone(), env.paths.num_knots[[0, 0]] - 1))
    for _ in range(3):
        env.step(torch.zeros(2, env.num_actions))
    before = env.get_observations()["policy"].clone()
    env.replace_path(torch.tensor([1]), torch.tensor([2]), torch.tensor([0.3], dtype=torch.float64))
    after = env.get_observations()["policy"]
    d, m = env.robot.dof, env.robot.path_dof
    knots_now = after[1, 3 * d: 3 * d + m]
    expect, _ = env.paths.window(torch.tensor([2]), torch.tensor([0.3], dtype=torch.float64), env.end_knot[[1]], 9)
    rel = ((expect[0, 0] - env.pos[1, env.path_index]) / env.horizon).clamp(-1, 1)  # relative to the robot
    np.testing.assert_allclose(knots_now.double().numpy(), rel.numpy(), atol=1e-6)
    assert torch.equal(after[0], before[0])  # untouched env keeps its observation
    assert int(env.seg_path[1]) == 2 and int(env.seg_path[0]) == 0
    env.step(torch.zeros(2, env.num_actions))  # and keeps running


@pytest.mark.parametrize(("end_obs", "end_tol"), [(False, None), (True, 0.05)])
def test_matches_numpy_reference_oracle(end_obs, end_tol):
    """Same path, same actions: states, rewards and terminations of the batched env match the oracle.

    Tolerances: limits (torch vs klimits) and reference lookup (table vs spline) differ by < 1e-6.
    """
    env, knots = make_env(num_envs=1, segments="full", episode_budget_s=30.0, end_obs=end_obs,
                          end_tolerance=end_tol)
    robot = env.robot
    lim = JointLimits.from_robot(robot)

    def brake(p, v, a):
        t = [torch.as_tensor(x).unsqueeze(0) for x in (p, v, a)]
        return braking_acceleration(*t, lim, 0.1)[0].numpy()

    path = ReferencePath(knots[0])
    env.start_segments(torch.tensor([0]), Segments(torch.tensor([0]), torch.zeros(1, dtype=torch.float64),
                                                   env.paths.length[[0]].clone(), env.paths.num_knots[[0]] - 1))
    settings = ReferenceSettings(env.knot_gap, budget_steps=int(env.budget[0]), end_obs=end_obs,
                                 end_tolerance=end_tol)
    ref = ReferenceTrackingEnv(robot, path, 0.0, len(path.knots) - 1, build_reward_terms(REWARD), settings, brake)
    rng = np.random.default_rng(0)
    np.testing.assert_allclose(env.get_observations()["policy"][0].numpy(), ref.observation(), atol=1e-5)
    for k in range(300):
        a = rng.uniform(-0.6, 0.6, robot.dof)  # away from the position limits (limits have their own tests)
        _, rew, dones, extras = env.step(torch.as_tensor(a).unsqueeze(0))
        r = ref.step(a)
        assert bool(dones[0]) == (r.terminated or r.time_out), f"step {k}"
        np.testing.assert_allclose(float(env.last_step["moved"][0]), r.moved, atol=1e-6)
        np.testing.assert_allclose(float(env.last_step["dev_max"][0]), r.dev_max, atol=1e-4)
        np.testing.assert_allclose(float(rew[0]), r.reward, rtol=1e-3, atol=1e-3)
        if r.terminated or r.time_out:
            break
        np.testing.assert_allclose(env.pos[0].numpy(), ref.pos, atol=1e-6, err_msg=f"step {k}")
        np.testing.assert_allclose(env.vel[0].numpy(), ref.vel, atol=1e-6)
        np.testing.assert_allclose(env.get_observations()["policy"][0].numpy(), ref.observation(), atol=1e-4)
    assert r.terminated, "the oracle episode should end with a stop"


def test_end_tolerance_counts_arrival_at_the_end_knot():
    """A robot resting within end_tolerance of the end knot, with arc length still uncovered (it cut a
    corner), has reached the end: it brakes and the episode ends with a stop; without the tolerance it stalls."""
    for tol, expect in ((0.05, True), (None, False)):
        env, _ = make_env(num_envs=1, segments="full", end_tolerance=tol, end_obs=True, scale_budget=False)
        end_s = env.paths.length[[0]].clone()
        seg = Segments(torch.tensor([0]), end_s - 0.03, end_s, env.paths.num_knots[[0]] - 1)
        env.start_segments(torch.tensor([0]), seg)
        env.pos[0, env.path_index] = env.end_q[0] + 0.01  # 0.01 rad per joint from the end knot
        env._update_window()
        stopped = False
        for _ in range(5):
            _, _, done, _ = env.step(torch.zeros(1, env.num_actions))
            stopped = stopped or bool(env.last_step["stopped"][0])
            if bool(done[0]):
                break
        assert bool(env.last_step["reached"][0]) is expect
        assert stopped is expect


@pytest.mark.parametrize("mapping", ["centred", "posture", "linear"])
def test_free_joints_hold_still_on_action_zero(mapping):
    """ARMAR-4's legs are not on the path and start at 0, the knees on their lower limit: with the centred
    mapping action 0 keeps every leg joint at rest while the arms track; the paper's linear mapping sends the
    knees to half their admissible acceleration."""
    env, _ = make_env("armar4_legs", num_envs=8, free_joint_actions=mapping, autoreset=False)
    free = torch.ones(env.robot.dof, dtype=torch.bool)
    free[env.path_index] = False
    g = torch.Generator().manual_seed(0)
    for _ in range(5):
        act = torch.rand(8, env.robot.dof, generator=g) * 2 - 1
        act[:, free] = 0.0
        env.step(act)
    legs = env.pos[:, free]
    if mapping != "linear":
        # (the knees' admissible range starts a hair above 0 on their limit: 6e-8 rad/s^2)
        assert legs.abs().max() < 1e-6 and env.vel[:, free].abs().max() < 1e-6
    else:
        knees = [env.robot.joints.index(n) for n in ("leg_knee_joint_r0", "leg_knee_joint_r1")]
        assert (env.pos[:, knees] > 0.01).all()
    assert env.pos[:, env.path_index].abs().sum() > 0  # the arms did move


def test_posture_pulls_biased_free_joints_back():
    """A constant small bias on the leg actions: with ``centred`` it integrates twice (the legs drift away),
    with ``posture`` the critically damped pull holds them near the start posture."""
    drift = {}
    for mapping in ("centred", "posture"):
        env, _ = make_env("armar4_legs", num_envs=4, free_joint_actions=mapping, autoreset=False)
        free = torch.ones(env.robot.dof, dtype=torch.bool)
        free[env.path_index] = False
        for _ in range(40):
            act = torch.zeros(4, env.robot.dof)
            act[:, free] = 0.02
            env.step(act)
        drift[mapping] = float(env.pos[:, free].abs().max())
    assert drift["centred"] > 0.2 and drift["posture"] < 0.02, drift


def test_free_joint_mapping_is_validated():
    with pytest.raises(ValueError, match="free_joint_actions"):
        make_env("armar4_legs", num_envs=2, free_joint_actions="tanh")


def test_passed_knots_follow_a_search_over_the_path():
    """The env's running knot index (advanced as the robot progresses, reset with the segment) equals a
    search of each env's knot row, through resets and a path replaced mid-episode."""
    env, _ = make_env(num_envs=64)
    gen = torch.Generator().manual_seed(1)
    for k in range(60):
        env.step(torch.rand(64, env.num_actions, generator=gen) * 2 - 1)
        if k == 20:
            env.replace_path(torch.tensor([3, 5]), torch.tensor([1, 2]), torch.tensor([0.4, 1.1], dtype=torch.float64))
        assert torch.equal(env.knot_i, env.paths.knot_index_at(env.seg_path, env.s))


def test_tcp_observation_by_hand():
    box = torch.tensor([[-1.0, 1.0], [-1.0, 1.0], [-0.7, 1.3]], dtype=torch.float64)
    ref = torch.tensor([[[0.5, -1.0, 0.3]]], dtype=torch.float64)  # (N=1, T=1, 3)
    cmd = torch.tensor([[[0.45, -1.0, 0.4]]], dtype=torch.float64)
    out = tcp_observation(ref, cmd, box, 0.1)
    # z: 2 (0.3 + 0.7) / 2 - 1 = 0; error (0.05, 0, -0.1) / 0.1
    np.testing.assert_allclose(out.numpy(), [[0.5, -1.0, 0.0, 0.5, 0.0, -1.0]], atol=1e-12)


def test_tcp_obs_appends_reference_tcp_and_its_error():
    base, _ = make_env(num_envs=4)
    env, _ = make_env(num_envs=4, tcp_obs=True)
    n0 = base.num_obs
    assert env.num_obs == n0 + 6
    obs = env.get_observations()["policy"]
    assert torch.equal(obs[:, :n0], base.get_observations()["policy"])  # the rest of the state is unchanged
    assert float(obs[:, n0 + 3:].abs().max()) < 1e-6  # at the start the robot is on its path: no error
    for _ in range(3):
        obs = env.step(torch.full((4, env.num_actions), 0.3))[0]["policy"]
    ref = env.pos.clone()
    ref[:, env.path_index] = env.paths.position_at(env.seg_path, env.s)
    fk = env.fk
    err = (fk.tcp_positions(ref) - fk.tcp_positions(env.pos))[:, 0] / 0.1
    np.testing.assert_allclose(obs[:, n0 + 3:].double().numpy(), err.clamp(-1, 1).numpy(), atol=1e-5)
    assert float(err.abs().max()) > 1e-3  # the robot has left its path: the error is seen


def test_tcp_obs_box_is_validated():
    with pytest.raises(ValueError, match="tcp_obs_box"):
        make_env(num_envs=2, tcp_obs=True, tcp_obs_box=(1.0, -1.0, -1.0, 1.0, 0.0, 1.0))


def test_tcp_deviation_term_by_hand():
    z = torch.zeros(3, dtype=torch.float64)
    q = StepQuantities(z, z, z, z, z, z, close_to_end=z.bool(),
                       task={"tcp_dev": torch.tensor([0.0, 0.05, 0.3], dtype=torch.float64)})
    # (1 - min(1, d / 0.1))^2: 1, 0.25, 0
    np.testing.assert_allclose(tcp_deviation(q, threshold=0.1).numpy(), [1.0, 0.25, 0.0], atol=1e-12)


def test_tcp_deviation_reward_uses_the_hands_distance_at_the_step_end():
    reward = {**REWARD, "tcp_deviation": {"weight": 1.0, "threshold": 0.1}}
    robot = load_robot_by_name("armar4")
    knots = smooth_paths(robot)
    paths = build_pathset(knots, [f"p{i}" for i in range(len(knots))])
    env = PathTrackingEnv(TrackingEnvCfg(num_envs=4, seed=0), robot, paths, build_reward_terms(reward))
    assert env.tcp_reward and env.fk is not None and env.num_obs == make_env("armar4", num_envs=4)[0].num_obs
    for _ in range(3):
        env.step(torch.full((4, env.num_actions), 0.4))
    ref = env.pos.clone()
    ref[:, env.path_index] = env.paths.position_at(env.seg_path, env.s)
    d = (env.fk.tcp_positions(ref) - env.fk.tcp_positions(env.pos)).norm(dim=2).mean(dim=1)  # (N,) m, two hands
    assert float(d.min()) > 1e-3  # the robot has left its path
    before = env.ep_reward["tcp_deviation"].clone()
    env.step(torch.zeros(4, env.num_actions))
    ref = env.pos.clone()
    ref[:, env.path_index] = env.paths.position_at(env.seg_path, env.s)
    d = (env.fk.tcp_positions(ref) - env.fk.tcp_positions(env.pos)).norm(dim=2).mean(dim=1)
    expected = (1.0 - (d / 0.1).clamp(max=1.0)) ** 2
    got = env.ep_reward["tcp_deviation"] - before
    alive = env.episode_length_buf > 0  # no episode ended in this step
    np.testing.assert_allclose(got[alive].numpy(), expected[alive].numpy(), atol=1e-9)


def test_tcp_deviation_needs_no_feedback_but_ball_terms_do():
    with pytest.raises(ValueError, match="ball_centre"):
        robot = load_robot_by_name("iiwa7")
        paths = build_pathset(smooth_paths(robot), ["a", "b", "c", "d"])
        PathTrackingEnv(TrackingEnvCfg(num_envs=2), robot, paths, build_reward_terms({"ball_centre": {"weight": 1.0}}))


def test_error_obs_appends_the_joint_tracking_error():
    base, _ = make_env(num_envs=4)
    env, _ = make_env(num_envs=4, error_obs=True, error_obs_scale=0.05)
    n0, m = base.num_obs, env.robot.path_dof
    assert env.num_obs == n0 + m and env.observation_layout()[-1] == ("error", n0, n0 + m)
    obs = env.get_observations()["policy"]
    assert torch.equal(obs[:, :n0], base.get_observations()["policy"])
    assert float(obs[:, n0:].abs().max()) < 1e-6  # at the start the robot is on its path
    for _ in range(3):
        obs = env.step(torch.full((4, env.num_actions), 0.3))[0]["policy"]
    err = (env.paths.position_at(env.seg_path, env.s) - env.pos[:, env.path_index]) / 0.05
    np.testing.assert_allclose(obs[:, n0:].double().numpy(), err.clamp(-1, 1).numpy(), atol=1e-6)
    assert float(err.abs().max()) > 1e-2  # the robot has left its path: the error is seen


def test_error_obs_scale_is_validated():
    with pytest.raises(ValueError, match="error_obs_scale"):
        make_env(num_envs=2, error_obs=True, error_obs_scale=0.0)
