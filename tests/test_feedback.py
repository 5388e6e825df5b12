"""Sensory feedback: the analytic ball model against closed forms and PyBullet, the PyBullet worker pool, the
ball task inside the tracking env, warm starts."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from pathrl.dataset.io import load_pathset
from pathrl.envs.rewards import build_reward_terms
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.paths.knots import KnotStrategy
from pathrl.robot.external import load_robot_by_name
from pathrl.sim.feedback import RES_FACTOR, ROLL_FACTOR, AnalyticBall, rolling_resistance
from pathrl.train.warm_start import WarmStartError, widen_inputs

LEVEL = torch.tensor([0.0, 0.5, 0.0, -1.0, 0.0, -1.5, 0.0], dtype=torch.float64)  # plate level, face up
BALL_REWARD = {"path_length": {"weight": 4.0}, "deviation_max": {"weight": 0.9}, "deviation_mean": {"weight": 0.9},
               "ball_centre": {"weight": 1.0}}
ROOT_DATASET = Path(__file__).resolve().parents[1] / "datasets" / "iiwa7" / "ball_balancing"


@pytest.fixture(scope="module")
def iiwa():
    return load_robot_by_name("iiwa7")


def place(ball: AnalyticBall, xy, radius=0.0275, mu=3e-4) -> None:
    ball.xy[:] = torch.as_tensor(xy, dtype=torch.float64)
    ball.vxy[:] = 0.0
    ball.radius[:] = radius
    ball.roll_mu[:] = mu
    ball.prev_rel[:] = ball.xy / ball.half


def test_rolling_resistance_by_hand():
    dt = 0.1
    res = torch.tensor([0.2, 0.2, 0.2])
    v = torch.tensor([[0.0, 0.0], [0.0, 0.0], [0.01, 0.0]])
    drive = torch.tensor([[0.1, 0.0], [0.0, 0.5], [0.0, 0.0]])
    out = rolling_resistance(v, drive, res, dt)
    assert out[0].tolist() == [0.0, 0.0]  # resting, drive below the resistance: stays put
    assert out[1].tolist() == pytest.approx([0.0, (0.5 - 0.2) * dt])  # starts with drive - resistance
    assert out[2].tolist() == [0.0, 0.0]  # 0.01 m/s - 0.02 m/s would reverse: it stops instead


def test_analytic_ball_on_a_tilted_plate(iiwa):
    """A resting ball on a plate tilted by 5 deg: constant acceleration f (g sin - RES mu g cos / r), by hand."""
    tilt = math.radians(5.0)
    q = LEVEL.clone()
    q[5] += tilt
    ball = AnalyticBall(iiwa, 1, model_rate=40.0)
    ball.reset(torch.tensor([0]), q[None])
    place(ball, [[0.0, 0.0]])
    c = 24
    for _ in range(4):  # 0.4 s
        ball.step(q.expand(1, c, 7), torch.zeros(1, c, 7, dtype=torch.float64))
    g = 9.81
    a = ROLL_FACTOR * (g * math.sin(tilt) - RES_FACTOR * 3e-4 * g * math.cos(tilt) / 0.0275)
    n, dt = 16, 1.0 / 40.0  # semi-implicit Euler: x_n = a dt^2 n (n + 1) / 2
    x = float(ball.xy[0].norm())
    assert x == pytest.approx(a * dt * dt * n * (n + 1) / 2, rel=1e-3)
    assert bool(ball.on[0])


def test_analytic_ball_follows_pybullet(iiwa):
    """Same setpoints (a ball-balancing path in 3 s, smooth time scaling) for the model and PyBullet: the ball
    positions agree within 5 mm until it leaves the plate, and both lose it in the same 0.1 s step."""
    from pathrl.sim.ball_plate import BallOnPlateScene, BallParams

    paths = load_pathset(ROOT_DATASET, "test", KnotStrategy("distance", 0.3), robot=iiwa)
    rate, c, period = 240.0, 24, 3.0
    t = np.arange(0.0, period + 1e-9, 1.0 / rate)
    u = t / period
    s = float(paths.length[3]) * (10 * u**3 - 15 * u**4 + 6 * u**5)
    q = paths.position_at(torch.full((len(s),), 3), torch.as_tensor(s)).numpy()
    qd = np.gradient(q, 1.0 / rate, axis=0)
    model = AnalyticBall(iiwa, 1, rate)
    model.reset(torch.tensor([0]), torch.as_tensor(q[:1]))
    with BallOnPlateScene(iiwa, seed=0) as scene:
        scene.reset(q[0], ball_xy=(0.03, -0.02), ball=BallParams(0.0275, 0.1, 3e-4, 3e-4))
        scene.follow(np.repeat(q[:1], 48, 0), np.zeros((48, 7)))  # let the ball settle on the plate
        place(model, scene.ball_on_plate()[None, :2])
        errors, fell = [], (None, None)
        for k in range((len(q) - 1) // c):
            sl = slice(1 + k * c, 1 + (k + 1) * c)
            scene.follow(q[sl], qd[sl])
            model.step(torch.as_tensor(q[sl])[None], torch.as_tensor(qd[sl])[None])
            pb_on, model_on = scene.ball_is_on_plate(), bool(model.on[0])
            if not pb_on or not model_on:
                fell = (pb_on, model_on)
                break
            errors.append(np.linalg.norm(scene.ball_on_plate()[:2] - model.xy[0].numpy()))
    assert len(errors) >= 5 and max(errors) < 0.005, errors
    assert fell == (False, False)  # the ball left the plate in both, in the same step


def test_pybullet_pool_is_deterministic_across_workers(iiwa):
    from pathrl.sim.vec import PyBulletBall

    q = LEVEL.expand(3, 7).clone()
    q[:, 0] += torch.tensor([0.0, 0.2, -0.2], dtype=torch.float64)
    ramp = torch.linspace(0, 1, 24, dtype=torch.float64)[None, :, None]
    qs = q[:, None] + 0.3 * ramp * torch.tensor([1.0, 0, 0, 0, 0, 0, 0], dtype=torch.float64)
    out = []
    for workers in (1, 2):
        pool = PyBulletBall(iiwa, 3, seed=7, workers=workers)
        try:
            pool.reset(torch.arange(3), q)
            first = pool.observe().clone()
            step = pool.step(qs, torch.zeros_like(qs))
            out.append((first, step.obs, step.values["ball_on_plate"]))
        finally:
            pool.close()
    for a, b in zip(out[0], out[1], strict=True):
        torch.testing.assert_close(a, b)
    assert out[0][0].shape == (3, 4) and (out[0][2] == 1.0).all()
    assert not torch.equal(out[0][0][0], out[0][0][1])  # every scene draws its own ball


def test_a_kept_pool_is_handed_on_reseeded_and_reads_as_a_fresh_one(iiwa):
    """kept_pools: the second feedback of the same pool gets the first one's scenes (no new workers), reseeded, and
    its episode reads exactly as on a fresh pool; outside, a closed pool stops its workers."""
    from pathrl.sim.vec import PyBulletBall, kept_pools

    q = LEVEL.expand(2, 7).clone()
    qs = q[:, None] + 0.2 * torch.linspace(0, 1, 12, dtype=torch.float64)[None, :, None]

    def episode(fb) -> tuple[torch.Tensor, torch.Tensor]:
        fb.reset(torch.arange(2), q)
        first = fb.observe().clone()
        return first, fb.step(qs, torch.zeros_like(qs)).obs

    fresh = PyBulletBall(iiwa, 2, seed=3, workers=1)
    want = episode(fresh)
    fresh.close()
    assert fresh.pool.procs == []
    with kept_pools():
        a = PyBulletBall(iiwa, 2, seed=3, workers=1)
        episode(a)
        episode(a)  # the scenes' generators moved on
        a.close()
        procs = list(a.pool.procs)
        assert procs and all(p.is_alive() for p in procs)  # kept
        b = PyBulletBall(iiwa, 2, seed=3, workers=1)
        assert b.pool is a.pool
        got = episode(b)
        other = PyBulletBall(iiwa, 2, seed=4, workers=1)  # another seed: its own pool
        assert other.pool is not a.pool
        other.close()
        b.close()
    assert not any(p.is_alive() for p in procs)  # closed on leaving
    for x, y in zip(want, got, strict=True):
        assert torch.equal(x, y)


def ball_env(iiwa, num_envs=8, feedback=None, **kw) -> PathTrackingEnv:
    paths = load_pathset(ROOT_DATASET, "test", KnotStrategy("distance", 0.3, n_state=5), robot=iiwa)
    cfg = TrackingEnvCfg(num_envs=num_envs, seed=0, segments="full", episode_budget_s=6.0, scale_budget=False,
                         n_state=5, end_obs=True, end_tolerance=0.05, **kw)
    fb = feedback or AnalyticBall(iiwa, num_envs, cfg.control_rate, seed=0)
    return PathTrackingEnv(cfg, iiwa, paths, build_reward_terms(BALL_REWARD), fb)


def test_a_dead_pybullet_worker_is_one_clear_error(iiwa):
    from pathrl.sim.vec import PyBulletBall

    pool = PyBulletBall(iiwa, 2, seed=0, workers=1)
    pool.pool.procs[0].kill()
    with pytest.raises(RuntimeError, match="PyBullet worker process exited"):
        pool.reset(torch.arange(2), LEVEL.expand(2, 7).clone())
    pool.close()


def test_ball_task_env_contract(iiwa):
    env = ball_env(iiwa)
    plain = PathTrackingEnv(env.cfg, iiwa, env.paths, build_reward_terms(
        {k: v for k, v in BALL_REWARD.items() if k != "ball_centre"}))
    assert env.num_obs == plain.num_obs + 4
    obs = env.get_observations()
    assert isinstance(obs, TensorDict) and obs["policy"].shape == (8, env.num_obs)
    for _ in range(5):
        obs, rew, dones, extras = env.step(torch.randn(8, 7))
        assert torch.isfinite(obs["policy"]).all() and (obs["policy"].abs() <= 1).all() and (rew >= 0).all()
        assert set(env.last_step) >= {"task/ball_dist", "task/ball_on_plate", "task_failed"}


def test_the_asymmetric_critic_sees_time_and_arc_left_and_the_ball_parameters(iiwa):
    """task.critic_obs: a group "critic" beside the unchanged policy state: time left / 10 s, arc length left / 10
    rad, the ball's velocity (m/s), radius / 30 mm and rolling friction / 1 mm (hand-checked against the env)."""
    env = ball_env(iiwa, critic_obs=True)
    plain = ball_env(iiwa)
    obs = env.get_observations()
    assert set(obs.keys()) == {"policy", "critic"} and set(plain.get_observations().keys()) == {"policy"}
    torch.testing.assert_close(obs["policy"], plain.get_observations()["policy"])
    for _ in range(3):
        obs, *_ = env.step(torch.zeros(8, 7))
    c, ball = obs["critic"], env.feedback
    assert c.shape == (8, 6) and c.dtype == torch.float32
    steps_left = (env.budget - env.episode_length_buf).to(torch.float64)
    torch.testing.assert_close(c[:, 0].double(), steps_left * env.cfg.dt / 10.0, atol=1e-6, rtol=0)
    assert bool((env.episode_length_buf == 3).all())
    assert bool((c[:, 0] < env.max_episode_length * env.cfg.dt / 10).all())
    torch.testing.assert_close(c[:, 1].double(), (env.end_s - env.s) / 10.0, atol=1e-6, rtol=0)
    torch.testing.assert_close(c[:, 2:4].double(), ball.vxy, atol=1e-6, rtol=0)
    assert bool(((c[:, 4] >= 0.02 / 0.03 - 1e-6) & (c[:, 4] <= 0.036 / 0.03 + 1e-6)).all())
    assert bool(((c[:, 5] >= 0.1 - 1e-6) & (c[:, 5] <= 0.7 + 1e-6)).all())


def test_ball_leaving_the_plate_ends_the_episode(iiwa):
    env = ball_env(iiwa, num_envs=2)
    fb = env.feedback
    fb.xy[0] = torch.tensor([0.165, 0.0], dtype=torch.float64)  # 4 mm from the edge, rolling out at 1 m/s
    fb.vxy[0] = torch.tensor([1.0, 0.0], dtype=torch.float64)
    _, rew, dones, extras = env.step(torch.zeros(2, 7))
    assert dones.tolist() == [True, False]
    assert extras["log"]["Episode_Termination/task_failed"] == 1.0
    assert bool(fb.on[0])  # the finished env was reset with a new ball


def test_ball_reward_needs_the_ball(iiwa):
    paths = load_pathset(ROOT_DATASET, "test", KnotStrategy("distance", 0.3, n_state=5), robot=iiwa)
    with pytest.raises(ValueError, match="ball_centre.*task=ball_on_plate"):
        PathTrackingEnv(TrackingEnvCfg(num_envs=2, n_state=5), iiwa, paths, build_reward_terms(BALL_REWARD))


def test_same_actions_same_setpoints_in_both_backends(iiwa):
    """The backend only senses: for the same actions, kinematic setpoints are identical."""
    from pathrl.sim.vec import PyBulletBall

    pool = PyBulletBall(iiwa, 2, seed=0, workers=1)
    try:
        envs = [ball_env(iiwa, 2, fail_terminates=False), ball_env(iiwa, 2, feedback=pool, fail_terminates=False)]
        gen = torch.Generator().manual_seed(0)
        for _ in range(5):
            a = torch.rand(2, 7, generator=gen) * 2 - 1
            for e in envs:
                e.step(a)
            torch.testing.assert_close(envs[0].pos, envs[1].pos, rtol=0, atol=0)
    finally:
        pool.close()


def test_widen_inputs_keeps_the_policy():
    state = {"mlp.0.weight": torch.randn(4, 3), "obs_normalizer._mean": torch.randn(1, 3),
             "obs_normalizer._var": torch.rand(1, 3), "obs_normalizer._std": torch.rand(1, 3)}
    wide = widen_inputs(state, 5)
    assert wide["mlp.0.weight"].shape == (4, 5) and (wide["mlp.0.weight"][:, 3:] == 0).all()
    torch.testing.assert_close(wide["mlp.0.weight"][:, :3], state["mlp.0.weight"])
    assert wide["obs_normalizer._mean"][0, 3:].tolist() == [0.0, 0.0]
    assert wide["obs_normalizer._std"][0, 3:].tolist() == [1.0, 1.0]
    with pytest.raises(WarmStartError, match="only 2"):
        widen_inputs(state, 2)


def test_standing_pool_reads_an_upright_robot():
    from pathrl.sim.vec import PyBulletStanding

    robot = load_robot_by_name("armar4")
    pool = PyBulletStanding(robot, 2, seed=0, workers=1)
    try:
        q = torch.zeros(2, robot.dof, dtype=torch.float64)
        pool.reset(torch.arange(2), q)
        step = pool.step(q[:, None].expand(2, 24, robot.dof), torch.zeros(2, 24, robot.dof, dtype=torch.float64))
        assert step.obs.shape == (2, 8) and (step.obs.abs() <= 1).all()
        assert (step.values["upright"] == 1).all() and not step.failed.any()
        assert (step.values["base_tilt"] < math.radians(2)).all() and (step.values["base_offset"] < 0.02).all()
    finally:
        pool.close()


def test_standing_task_refuses_other_robots(iiwa):
    from pathrl.envs.registry import make_feedback

    cfg = {"task": {"feedback": "standing", "backend": "pybullet"}, "env": {"control_rate": 240.0}}
    with pytest.raises(ValueError, match="ARMAR-4"):
        make_feedback(cfg, iiwa, 2, 0)
    with pytest.raises(ValueError, match="ARMAR-4"):  # the analytic model too
        make_feedback({**cfg, "task": {"feedback": "standing", "backend": "analytic"}}, iiwa, 2, 0)


def _actor(num_obs: int, num_actions: int):
    from rsl_rl.models import MLPModel

    obs = TensorDict({"policy": torch.zeros(1, num_obs)}, batch_size=[1])
    return MLPModel(obs, {"actor": ["policy"]}, "actor", num_actions, [16, 8], "elu", True,
                    {"class_name": "GaussianDistribution", "init_std": 0.2, "std_type": "scalar"})


def test_warm_start_onto_more_joints_keeps_the_policy_and_holds_the_new_joints():
    """A 2-joint source (joints b, c; path joint c) onto joints a, b, c plus 3 task inputs: the source's
    actions come out unchanged for b and c whatever the new inputs hold, and the new joint a gets action 0."""
    from pathrl.train.warm_start import input_columns, joint_rows, widen_outputs

    torch.manual_seed(0)
    rest = 5  # knots, progress, ... (path joints only)
    src = _actor(3 * 2 + rest, 2)
    state = src.state_dict()
    state["obs_normalizer._mean"] = torch.randn(1, 11)
    state["obs_normalizer._var"] = torch.rand(1, 11) + 0.5
    state["obs_normalizer._std"] = state["obs_normalizer._var"].sqrt()
    src.load_state_dict(state)
    cols = input_columns(joint_rows(["b", "c"], ["a", "b", "c"]), 3, 11, 3 * 3 + rest + 3)
    assert cols.tolist() == [1, 2, 4, 5, 7, 8, 9, 10, 11, 12, 13]
    new = _actor(17, 3)
    new.load_state_dict(widen_outputs(widen_inputs(state, 17, cols), torch.tensor([1, 2]), 3, 0.05))
    new.eval(), src.eval()
    x_src = torch.randn(4, 11)
    x_new = torch.randn(4, 17)
    x_new[:, cols] = x_src
    with torch.no_grad():
        a_src = src(TensorDict({"policy": x_src}, batch_size=[4]))
        a_new = new(TensorDict({"policy": x_new}, batch_size=[4]))
    torch.testing.assert_close(a_new[:, 1:], a_src)
    assert a_new[:, 0].abs().max() == 0.0
    assert new.state_dict()["distribution.std_param"][0] == pytest.approx(0.05)
    with pytest.raises(WarmStartError, match="lacks"):
        joint_rows(["b", "z"], ["a", "b", "c"])
    with pytest.raises(WarmStartError, match="do not line up"):
        input_columns(joint_rows(["b", "c"], ["a", "b", "c"]), 3, 11, 12)


def _critic(num_obs: int):
    from rsl_rl.models import MLPModel

    obs = TensorDict({"policy": torch.zeros(1, num_obs)}, batch_size=[1])
    return MLPModel(obs, {"critic": ["policy"]}, "critic", 1, [16, 8], "elu", True)


class _Alg:
    """Stand-in for PPO in a warm start: its critic (`critic_obs` inputs) and what ``load`` received."""

    def __init__(self, critic_obs: int) -> None:
        self._raw_critic = _critic(critic_obs)
        self.loaded: dict = {}

    def load(self, state: dict, cfg: dict, strict: bool) -> bool:
        self.loaded = {"state": state, "cfg": cfg}
        self._raw_critic.load_state_dict(state["critic_state_dict"], strict=strict)
        return False


def test_warm_start_of_an_asymmetric_critic_keeps_its_privileged_inputs(tmp_path):
    """A source whose critic sees 11 policy inputs + 2 privileged ones starts a run of the same layout unchanged (its
    critic is not cut to the policy's 11 inputs); a source with a plain critic gets the 2 new inputs at zero weight."""
    from pathrl.storage.checkpoints import save_checkpoint
    from pathrl.train.warm_start import warm_start

    torch.manual_seed(0)
    actor, critic = _actor(11, 2), _critic(13)
    save_checkpoint({"actor_state_dict": actor.state_dict(), "critic_state_dict": critic.state_dict()},
                    tmp_path / "asym.pt")
    alg = _Alg(13)
    warm_start(alg, tmp_path / "asym.pt", 11, 0.05)
    got = alg.loaded["state"]["critic_state_dict"]
    torch.testing.assert_close(got["mlp.0.weight"], critic.state_dict()["mlp.0.weight"])
    assert alg.loaded["state"]["actor_state_dict"]["mlp.0.weight"].shape == (16, 11)
    save_checkpoint({"actor_state_dict": actor.state_dict(), "critic_state_dict": _critic(11).state_dict()},
                    tmp_path / "plain.pt")
    alg = _Alg(13)
    warm_start(alg, tmp_path / "plain.pt", 11, 0.05)
    w = alg.loaded["state"]["critic_state_dict"]["mlp.0.weight"]
    assert w.shape == (16, 13) and w[:, 11:].abs().max() == 0.0
    with pytest.raises(WarmStartError, match="13 inputs, the new env only 11"):
        warm_start(_Alg(11), tmp_path / "asym.pt", 11, 0.05)


class _SlidingPlate:
    """Stand-in forward kinematics: the plate sits at x = q[0] (m), y = q[1], level, rotated by q[2] about z."""

    def tcp_transforms(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        pos = torch.zeros(len(q), 1, 3, dtype=q.dtype)
        pos[:, 0, :2] = q[:, :2]
        c, s = torch.cos(q[:, 2]), torch.sin(q[:, 2])
        rot = torch.zeros(len(q), 1, 3, 3, dtype=q.dtype)
        rot[:, 0, 0, 0], rot[:, 0, 0, 1], rot[:, 0, 1, 0], rot[:, 0, 1, 1] = c, -s, s, c
        rot[:, 0, 2, 2] = 1.0
        return pos, rot


def test_plate_imu_by_hand(iiwa):
    """Level plate accelerating at 2 m/s^2 along world x: in-plane specific force -2/g along x (rotated into
    the plate frame), no tilt; a plate tilted by 5 deg at rest reads sin(5 deg) twice."""
    from pathrl.sim.feedback import PlateIMU

    imu = PlateIMU(iiwa, 2, 240.0, fk=_SlidingPlate())
    t = torch.arange(24, dtype=torch.float64) / 240.0
    q = torch.zeros(2, 24, 3, dtype=torch.float64)
    q[:, :, 0] = 0.5 * 2.0 * t**2  # x = a t^2 / 2
    q[1, :, 2] = math.pi / 2  # the second plate is turned by 90 deg: world x is its -y
    reading = imu.step(q)
    g = 9.81
    assert reading[0].tolist() == pytest.approx([-2.0 / g, 0.0, 0.0, 0.0], abs=1e-9)
    assert reading[1].tolist() == pytest.approx([0.0, 2.0 / g, 0.0, 0.0], abs=1e-9)

    real = PlateIMU(iiwa, 1, 240.0)
    tilted = LEVEL.clone()
    tilted[5] += math.radians(5.0)
    real.reset(torch.tensor([0]), LEVEL[None])
    assert real.reading.abs().max().item() < 1e-9  # level plate at rest reads 0
    r = real.step(tilted.expand(1, 24, 7).clone())[0]
    assert float(r[:2].norm()) == pytest.approx(math.sin(math.radians(5.0)), abs=1e-9)
    assert r[:2].tolist() == pytest.approx(r[2:].tolist(), abs=1e-9)  # at rest: force = gravity


def test_plate_imu_joins_the_ball_state_in_both_backends(iiwa):
    """task.imu adds the same 4 values to the analytic and the PyBullet ball observation."""
    from pathrl.sim.vec import PyBulletBall

    q = LEVEL.clone()
    q[5] += 0.1
    qs = q.expand(2, 24, 7).clone()
    model = AnalyticBall(iiwa, 2, seed=0, imu=True)
    pyb = PyBulletBall(iiwa, 2, seed=0, workers=1, imu=True)
    try:
        assert model.num_obs == pyb.num_obs == 8
        for fb in (model, pyb):
            fb.reset(torch.arange(2), LEVEL.expand(2, 7).clone())
        a, b = model.step(qs, torch.zeros_like(qs)).obs, pyb.step(qs, torch.zeros_like(qs)).obs
        assert torch.allclose(a[:, 4:], b[:, 4:], rtol=0.0, atol=1e-12)
        assert float(a[0, 6:].norm()) == pytest.approx(math.sin(0.1), abs=1e-9)
    finally:
        pyb.close()


def test_plate_drive_by_hand(iiwa):
    """The drive is the in-plane specific force (g): 0 for a level plate at rest or sliding at constant
    velocity, a/g for a level plate accelerating at a, sin(tilt) for a tilted plate at rest, and 0 again
    for a plate tilted into its acceleration by atan(a/g) (the waiter's tray)."""
    from pathrl.sim.feedback import PlateDrive

    g, a = 9.81, 2.0
    t = torch.arange(1, 25, dtype=torch.float64) / 240.0
    q = torch.zeros(3, 24, 3, dtype=torch.float64)
    q[0, :, 0] = 0.7 * t  # constant velocity
    q[1, :, 0] = 0.5 * a * t**2
    q[2, :, 1] = 0.5 * a * t**2  # along world y, the plate turned by 30 deg: magnitude unchanged
    q[2, :, 2] = math.radians(30.0)
    drive = PlateDrive(iiwa, 3, 240.0, fk=_SlidingPlate())
    start = torch.zeros(3, 3, dtype=torch.float64)
    start[2, 2] = math.radians(30.0)
    drive.reset(torch.arange(3), start)
    # the first step starts from rest: its first interior instant sees the jump in velocity of env 0
    drive.step(q)
    q2 = q.clone()
    q2[0, :, 0] = 0.7 * (t + 0.1)
    q2[1:, :, :2] = (0.5 * a * (t + 0.1) ** 2)[None, :, None] * (q[1:, -1:, :2] != 0)
    value = drive.step(q2)
    assert value.tolist() == pytest.approx([0.0, a / g, a / g], abs=1e-9)

    real = PlateDrive(iiwa, 2, 240.0)
    tilted = LEVEL.clone()
    tilted[5] += math.radians(5.0)
    real.reset(torch.arange(2), torch.stack([LEVEL, tilted]))
    value = real.step(torch.stack([LEVEL, tilted])[:, None].expand(2, 24, 7).clone())
    assert value.tolist() == pytest.approx([0.0, math.sin(math.radians(5.0))], abs=1e-9)


def test_waiter_tray_does_not_drive_the_ball():
    """A plate tilted by atan(a/g) into a horizontal acceleration a feels no in-plane force."""
    from pathrl.sim.feedback import inplane_force

    a, g, h = 3.0, 9.81, 1.0 / 40.0
    tilt = math.atan(a / g)
    t = torch.arange(5, dtype=torch.float64) * h
    o = torch.zeros(1, 5, 3, dtype=torch.float64)
    o[0, :, 0] = 0.5 * a * t**2
    c, s = math.cos(tilt), math.sin(tilt)
    r = torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]], dtype=torch.float64)  # normal leans to +x
    f = inplane_force(o, r.expand(1, 5, 3, 3), h)
    assert f.abs().max().item() < 1e-12
    level = inplane_force(o, torch.eye(3, dtype=torch.float64).expand(1, 5, 3, 3), h)
    assert level[0, :, 0].tolist() == pytest.approx([-a / g] * 3, abs=1e-9)


def test_ball_drive_is_the_same_in_both_backends(iiwa):
    """The analytic model and the PyBullet backend report the same drive for the same setpoints, and the
    reward term rates it: 1 at no drive, 0 beyond the threshold."""
    from pathrl.envs.rewards import StepQuantities, ball_drive
    from pathrl.sim.vec import PyBulletBall

    t = torch.arange(1, 25, dtype=torch.float64) / 240.0
    qs = LEVEL.expand(2, 24, 7).clone()
    qs[1, :, 0] += 0.5 * 1.5 * t**2  # joint 1 accelerates: the plate swings round the base
    model = AnalyticBall(iiwa, 2, seed=0)
    pyb = PyBulletBall(iiwa, 2, seed=0, workers=1)
    try:
        for fb in (model, pyb):
            fb.reset(torch.arange(2), LEVEL.expand(2, 7).clone())
        a = model.step(qs, torch.zeros_like(qs)).values["ball_drive"]
        b = pyb.step(qs, torch.zeros_like(qs)).values["ball_drive"]
    finally:
        pyb.close()
    assert torch.allclose(a, b, rtol=0.0, atol=1e-12)
    assert a[0].item() < 1e-9 < 0.05 < a[1].item()
    zero = torch.zeros(2, dtype=torch.float64)
    task = {"ball_drive": torch.tensor([0.0, 0.05, 0.2]), "ball_on_plate": torch.tensor([1.0, 1.0, 1.0])}
    q = StepQuantities(zero, zero, zero, zero, zero, zero, zero.bool(), task=task)
    assert ball_drive(q, threshold=0.1).tolist() == pytest.approx([1.0, 0.25, 0.0])


def test_task_failure_time_and_after_end():
    from types import SimpleNamespace

    from pathrl.eval.evaluate import _task_failure

    def rec(ok, finish_step):
        return SimpleNamespace(extra={"dt": 0.1, "task_series": {"up": torch.tensor(ok)}}, finish_step=finish_step)

    # the ok flag drops in the 3rd step: failed 0.3 s after the start; the end was reached in step 1 -> after it
    f = _task_failure(rec([1.0, 1.0, 0.0, 0.0], 1), "up")
    assert f["task_failed"] and abs(f["task_failed_at_s"] - 0.3) < 1e-12 and f["task_failed_after_end"]
    assert not _task_failure(rec([1.0, 1.0, 0.0, 0.0], 3), "up")["task_failed_after_end"]  # same step: not after
    assert not _task_failure(rec([1.0, 1.0, 0.0, 0.0], -1), "up")["task_failed_after_end"]  # never reached
    assert _task_failure(rec([1.0, 1.0, 1.0], 2), "up") == {"task_failed": False, "task_failed_at_s": None,
                                                            "task_failed_after_end": False}


def test_the_authors_signed_ball_term_by_hand(iiwa):
    """ball_reach reads the authors' board axes (board x = plate -y, board y = plate +x) and ball_signed rates
    only offsets toward their +x / +y: min(1, (1 - m) / 0.94)^2, 0 off the plate; both backends report it."""
    from pathrl.envs.rewards import StepQuantities, ball_signed
    from pathrl.sim.feedback import ball_reach
    from pathrl.sim.vec import PyBulletBall

    rel = torch.tensor([[0.5, 0.0], [-0.5, 0.0], [0.0, 0.5], [0.0, -0.5], [0.2, -0.7]], dtype=torch.float64)
    assert ball_reach(rel).tolist() == pytest.approx([0.5, 0.0, 0.0, 0.5, 0.7])
    zero = torch.zeros(5, dtype=torch.float64)
    task = {"ball_reach": torch.tensor([0.5, 0.0, -0.5, 1.0, 0.5]),
            "ball_on_plate": torch.tensor([1.0, 1.0, 1.0, 1.0, 0.0])}
    q = StepQuantities(zero, zero, zero, zero, zero, zero, zero.bool(), task=task)
    assert ball_signed(q, margin=0.06).tolist() == pytest.approx([(0.5 / 0.94) ** 2, 1.0, 1.0, 0.0, 0.0])
    model = AnalyticBall(iiwa, 1, seed=0)
    model.reset(torch.arange(1), LEVEL.expand(1, 7).clone())
    place(model, [[-0.05, 0.05]])  # toward the plate's -x and +y: free in the authors' axes
    assert model.values()["ball_reach"].item() == pytest.approx(max(-0.05 / 0.10575, -0.05 / 0.13965))
    pyb = PyBulletBall(iiwa, 1, seed=0, workers=1)
    try:
        assert "ball_reach" in pyb.value_names and set(pyb.values()) == set(model.values())
    finally:
        pyb.close()


def test_bias_search_draws_the_same_balls_at_every_evaluation(iiwa, monkeypatch):
    """With a ball, the search's objective must not depend on how often it was evaluated: every pass restores the
    env's and the ball model's generators (pathrl.train.bias_search.env_generators) to their state at the start."""
    import numpy as np

    from pathrl.paths.segments import evaluation_plan
    from pathrl.train import bias_search
    from pathrl.train.bias_search import BiasSearchCfg, env_generators, episode_returns, search_output_bias

    class Actor(torch.nn.Module):  # the rsl-rl models take the observation TensorDict
        def __init__(self, n_obs: int, n_act: int) -> None:
            super().__init__()
            self.net = torch.nn.Sequential(torch.nn.Linear(n_obs, 8), torch.nn.ELU(), torch.nn.Linear(8, n_act))

        def forward(self, obs):
            return self.net(obs["policy"])

    torch.manual_seed(0)
    env = ball_env(iiwa, num_envs=6)
    assert env_generators(env) == [env.generator, env.feedback.generator]
    actor = Actor(env.num_obs, env.num_actions)
    plan = evaluation_plan(env.paths, 6, "full", seed=0)
    first, _ = episode_returns(env, actor, plan)
    radius = env.feedback.radius.clone()
    second, _ = episode_returns(env, actor, plan)
    assert not torch.equal(radius, env.feedback.radius)  # left alone, each pass draws other balls...
    assert not torch.equal(first, second)  # ...and the same policy scores differently

    values = []

    def twice(objective, dim, max_evals, bound):  # the objective at the start point, evaluated twice
        values.extend([objective(np.zeros(dim)), objective(np.zeros(dim))])
        return np.zeros(dim), values[0], values[0], 2

    monkeypatch.setattr(bias_search, "search_bias", twice)
    search_output_bias(env, actor, BiasSearchCfg(episodes=6, max_evals=2, bound=0.1))
    assert values[0] == values[1]
