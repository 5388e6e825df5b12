"""The model-based TrueAdapt controller (pathrl/baselines/trueadapt_tray.py): hand-checked pieces, zero adaptation at
rest, the tilt feed-forward on the analytic ball, every limit kept, one-line config errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from omegaconf import OmegaConf

from pathrl.baselines.trueadapt_tray import (
    AdaptTrayCfg,
    AdaptTrayController,
    cap_tilt,
    pd_gains,
    reference_velocities,
)
from pathrl.cli.common import CONF_DIR
from pathrl.dataset.trueadapt import bank_from_arrays
from pathrl.envs.trueadapt import AdaptEnvCfg, TrueAdaptEnv
from pathrl.envs.trueadapt_rewards import build_adapt_reward
from pathrl.limits.check import limit_violations
from pathrl.robot.external import load_robot_by_name
from pathrl.runs import make_controller
from pathrl.sim.feedback import GRAVITY, plate_pose

ROBOT = load_robot_by_name("iiwa7")
TERMS = OmegaConf.to_container(OmegaConf.load(CONF_DIR / "reward" / "trueadapt_on_plate.yaml"))["terms"]
LEVEL = np.array([0.0, 0.5, 0.0, -1.2, 0.0, -1.7, 0.0])  # q6 = q4 - q2: the plate faces up, 0.59 m in front
T64 = dict(dtype=torch.float64)


def _swing(alpha: float = 0.4, steps: int = 40) -> np.ndarray:
    """LEVEL with joint 1 accelerating at alpha (rad/s^2) for half the time and braking for the other half."""
    t = np.arange(steps + 1) * 0.05
    half = t[-1] / 2
    traj = np.tile(LEVEL, (steps + 1, 1))
    traj[:, 0] = np.where(t <= half, 0.5 * alpha * t**2, alpha * half**2 - 0.5 * alpha * (2 * half - t) ** 2)
    return traj


def _env(trajs: list[np.ndarray], n: int = 1, **kw) -> TrueAdaptEnv:
    cfg = AdaptEnvCfg(num_envs=n, sensor_noise=kw.pop("sensor_noise", 0.0), rolling_friction=(1e-4, 1e-4),
                      ball_radius=(0.025, 0.025), autoreset=False, **kw)
    env = TrueAdaptEnv(cfg, ROBOT, bank_from_arrays(trajs, 0.05), build_adapt_reward(TERMS))
    env.start(torch.arange(n), torch.arange(n) % len(trajs))
    return env


def _centre_ball(env: TrueAdaptEnv) -> None:
    for x in (env.ball.xy, env.start_xy, env.meas, env.prev_meas, env.start_meas, env.ball.prev_rel):
        x.zero_()


# ------------------------------------------------------------------------------------------------ by hand
def test_pd_gains_and_reference_velocities_by_hand():
    assert pd_gains(0.7, 0.5) == pytest.approx((0.49, 0.7))
    acc = torch.tensor([[[0.0], [1.0], [1.0], [-2.0]]], **T64)
    # trapezoids of 0.1 s: 0.05, 0.1, -0.05
    assert reference_velocities(acc, 0.1)[0, :, 0].tolist() == pytest.approx([0.0, 0.05, 0.15, 0.10])


def test_a_steep_normal_is_capped_at_max_tilt_and_a_flat_one_kept():
    steep = torch.tensor([[math.sin(0.5), 0.0, math.cos(0.5)], [0.0, 0.0, 1.0]], **T64)
    out = cap_tilt(steep, 0.1)
    assert math.atan2(float(out[0, :2].norm()), float(out[0, 2])) == pytest.approx(0.1)
    assert out[1].tolist() == pytest.approx([0.0, 0.0, 1.0])


# ------------------------------------------------------------------------------------------------ behaviour
def test_a_plate_at_rest_with_a_centred_ball_is_not_adapted():
    env = _env([np.tile(LEVEL, (21, 1))])
    _centre_ball(env)
    ctl = AdaptTrayController(env)
    for _ in range(20):
        action = ctl()
        assert float(action.abs().max()) < 1e-6
        env.step(action)
    assert float(ctl.correction.abs().max()) < 1e-6
    assert float((env.pos - torch.as_tensor(LEVEL)).abs().max()) < 1e-6


def test_the_tilt_feed_forward_holds_the_ball_that_the_reference_loses():
    """Joint 1 swings the plate sideways at about 0.24 m/s^2: the reference (level plate) lets a centred ball roll
    more than 10 cm; the feed-forward alone (kp = kd = 0) tilts the plate towards the acceleration by about
    atan(a / g) and the ball stays within 2 cm."""
    ref = _env([_swing()])
    _centre_ball(ref)
    far = 0.0
    for _ in range(40):
        ref.step(ref.reference_actions())
        far = max(far, float(ref.ball.xy.norm()))
    assert far > 0.10

    env = _env([_swing()])
    _centre_ball(env)
    ctl = AdaptTrayController(env, AdaptTrayCfg(kp=0.0, kd=0.0))
    far = 0.0
    for k in range(40):
        if k == 10:
            a_p = ctl.plate_acceleration()[0][0, :2]
        env.step(ctl())
        if k == 10:
            normal = plate_pose(ctl.fk, env.pos)[1][0, :, 2]
            tilt = math.atan2(float(normal[:2].norm()), float(normal[2]))
            assert float(normal[:2] @ a_p) / float(normal[:2].norm() * a_p.norm()) > 0.99  # towards a_p
            assert tilt == pytest.approx(math.atan(float(a_p.norm()) / GRAVITY), rel=0.25)
        far = max(far, float(env.ball.xy.norm()))
    assert far < 0.02
    assert bool(env.last_step["success"].all())


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kp=st.floats(0.0, 50.0), kd=st.floats(0.0, 20.0), u_max=st.floats(0.0, 5.0), omega=st.floats(0.5, 30.0),
       tilt=st.floats(0.01, 0.5), seed=st.integers(0, 1000))
def test_any_gains_keep_every_limit(kp, kd, u_max, omega, tilt, seed):
    """Whatever the gains, the controller's actions are finite, in [-1, 1], their accelerations inside the valid
    range, and the control-rate trajectory keeps position, velocity, acceleration and jerk limits."""
    env = _env([_swing(0.4), _swing(-1.5)], n=2, seed=seed, sensor_noise=0.002, fail_terminates=False,
               max_joint_deviation=100.0)
    env.record_setpoints = True
    ctl = AdaptTrayController(env, AdaptTrayCfg(kp=kp, kd=kd, max_ball_acc=u_max, track_omega=omega, max_tilt=tilt))
    qs, vs, accs = [], [], []
    for _ in range(40):
        lo, hi = env.a_min.clone(), env.a_max.clone()
        action = ctl()
        assert bool(torch.isfinite(action).all()) and float(action.abs().max()) <= 1.0
        env.step(action)
        a1 = env.last_step["a1"]
        assert bool(((a1 >= lo) & (a1 <= hi)).all())
        qs.append(env.last_step["q_control"])
        vs.append(env.last_step["v_control"])
        accs.append(env.last_step["a_control"])
    counts = limit_violations(torch.cat(qs, 1), torch.cat(vs, 1), torch.cat(accs, 1), env.limits, 1.0 / 240.0)
    assert int(counts["total"].sum()) == 0, {k: int(v.sum()) for k, v in counts.items()}


# ------------------------------------------------------------------------------------------------ errors
@pytest.mark.parametrize("spec, msg", [
    ({"name": "trueadapt_tray", "gain": 1.0}, "unknown keys ['gain']"),
    ({"name": "trueadapt_tray", "kp": "high"}, "must be numbers"),
    ({"name": "trueadapt_tray", "kp": -1.0}, "kp must be >= 0"),
    ({"name": "trueadapt_tray", "max_tilt": 2.0}, "max_tilt must be < pi/2"),
    ({"name": "trueadapt_tray", "track_omega": 0.0}, "track_omega must be > 0"),
    ({"name": "trueadapt_trays"}, "unknown name 'trueadapt_trays'"),
])
def test_bad_controller_specs_are_one_line_errors(spec, msg):
    env = _env([np.tile(LEVEL, (5, 1))])
    with pytest.raises(ValueError) as err:
        make_controller(spec, env)
    assert msg in str(err.value) and "\n" not in str(err.value)


def test_the_controller_refuses_an_env_without_a_reference():
    with pytest.raises(ValueError, match="needs a trajectory-adaptation env"):
        make_controller({"name": "trueadapt_tray"}, object())
