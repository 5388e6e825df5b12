"""Leg balance law of the free-standing ARMAR-4 (pathrl.baselines.balance): hand-checkable signs and zeros."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from pathrl.baselines.balance import (
    BalanceCfg,
    BalanceController,
    BalanceLaw,
    chain_matrix,
    correction_matrix,
    lean_vector,
    leg_groups,
    urdf_joint_axes,
)
from pathrl.baselines.com import StaticCom
from pathrl.robot.external import load_robot_by_name
from pathrl.runs import make_controller


@pytest.fixture(scope="module")
def robot():
    return load_robot_by_name("armar4_legs")


@pytest.fixture(scope="module")
def legs(robot):
    """Free-joint indices, names, world axes and child links of the leg joints."""
    free = [i for i, n in enumerate(robot.joints) if n not in robot.path_joints]
    names = [robot.joints[i] for i in free]
    axes, links = urdf_joint_axes(robot, names)
    return free, names, axes, links


def _law(legs, **gains) -> BalanceLaw:
    _, names, axes, _ = legs
    return BalanceLaw(BalanceCfg(**gains), correction_matrix(axes, leg_groups(names, "ank")),
                      correction_matrix(axes, leg_groups(names, "hip")), chain_matrix(axes, leg_groups(names, "_")))


def _quat_about(axis: tuple[float, float, float], angle: float) -> torch.Tensor:
    s = math.sin(angle / 2.0)
    return torch.tensor([[axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2.0)]], dtype=torch.float64)


def test_lean_vector_by_hand():
    no_lean = torch.zeros(1, 2, dtype=torch.float64)
    assert torch.allclose(lean_vector(_quat_about((0, 0, 1), 1.0)), no_lean, atol=1e-12)  # a yaw does not lean
    # +0.1 rad about world +y turns z towards +x: leaning forward; about +x turns z towards -y: leaning right
    assert torch.allclose(lean_vector(_quat_about((0, 1, 0), 0.1)), torch.tensor([[0.1, 0.0]], dtype=torch.float64))
    assert torch.allclose(lean_vector(_quat_about((1, 0, 0), 0.1)), torch.tensor([[0.0, -0.1]], dtype=torch.float64))


def test_leg_axes_of_the_urdf(legs):
    _, names, axes, _ = legs
    pitch = [names.index("leg_ank1_joint_r0"), names.index("leg_ank1_joint_r1")]
    assert np.allclose(axes[pitch], [[0, -1, 0], [0, -1, 0]], atol=1e-3)  # both ankle pitch joints turn about -y
    assert [len(g) for g in leg_groups(names, "ank")] == [2, 2] and [len(g) for g in leg_groups(names, "hip")] == [3, 3]


def test_zero_tilt_gives_zero_correction(legs):
    law = _law(legs, kp_ankle=2.0, kd_ankle=0.3, kp_hip=1.0, kd_hip=0.2)
    zero = torch.zeros(3, 2, dtype=torch.float64)
    assert torch.equal(law.posture(zero, zero), torch.zeros(3, 12, dtype=torch.float64))
    q = torch.zeros(3, 12, dtype=torch.float64)
    assert torch.equal(law.acceleration(law.posture(zero, zero), q, q), q)


def test_backward_tilt_leans_the_ankles_forward(legs):
    _, names, _, _ = legs
    law = _law(legs, kp_ankle=2.0, kd_ankle=0.0)
    q = law.posture(torch.tensor([[-0.05, 0.0]], dtype=torch.float64), torch.zeros(1, 2, dtype=torch.float64))[0]
    for leg in ("r0", "r1"):
        # ankle pitch about -y: the foot on the floor turns the body by -q about -y, i.e. +q about +y (forward)
        assert q[names.index(f"leg_ank1_joint_{leg}")] == pytest.approx(0.1)
        assert q[names.index(f"leg_ank2_joint_{leg}")] == pytest.approx(0.0, abs=1e-4)
        assert q[names.index(f"leg_knee_joint_{leg}")] == 0.0
    assert torch.all(law.posture(torch.tensor([[0.05, 0.0]], dtype=torch.float64), torch.zeros(1, 2))[0] == -q)


def test_tilt_removes_the_lean_the_legs_give(legs):
    _, names, _, _ = legs
    law = _law(legs)
    q = torch.zeros(1, 12, dtype=torch.float64)
    q[0, [names.index("leg_ank1_joint_r0"), names.index("leg_ank1_joint_r1")]] = 0.04  # body 0.04 rad forward
    lean = torch.tensor([[0.04, 0.0]], dtype=torch.float64)
    assert torch.allclose(law.tilt(lean, q), torch.zeros(1, 2, dtype=torch.float64), atol=1e-6)
    assert torch.allclose(law.tilt(torch.zeros(1, 2, dtype=torch.float64), q), -lean, atol=1e-6)


def test_com_lean_sign(legs):
    law = _law(legs, k_com=1.0, com_forward=0.03)
    behind = torch.tensor([[0.0, 0.01, 0.9]], dtype=torch.float64)  # COM 3 cm behind its place, 1 cm left
    assert torch.allclose(law.com_lean(behind), torch.tensor([[0.03 / 0.9, 0.0]], dtype=torch.float64))  # forward only


def test_static_com_matches_pybullet(robot, legs):
    import pybullet as p

    from pathrl.sim.humanoid import StandingScene

    _, names, _, links = legs
    feet = [links[names.index("leg_ank2_joint_r0")], links[names.index("leg_ank2_joint_r1")]]
    com = StaticCom(robot, feet)
    q = np.zeros(robot.dof)
    q[robot.joints.index("torso_pitch_joint")] = -0.5
    q[robot.joints.index("arm_sho2_joint_r0")] = 1.0
    with StandingScene(robot) as s:
        s.reset(q)
        ids = range(-1, p.getNumJoints(s.body, physicsClientId=s.cid))
        m = np.array([p.getDynamicsInfo(s.body, j, physicsClientId=s.cid)[0] for j in ids])
        x = np.array([p.getBasePositionAndOrientation(s.body, physicsClientId=s.cid)[0] if j < 0 else
                      p.getLinkState(s.body, j, computeForwardKinematics=True, physicsClientId=s.cid)[0] for j in ids])
        feet_ids = [s.joint_ids[robot.joints.index(f"leg_ank2_joint_{leg}")] for leg in ("r0", "r1")]
        ankles = np.mean([p.getLinkState(s.body, j, physicsClientId=s.cid)[4] for j in feet_ids], axis=0)
    expected = (m[:, None] * x).sum(0) / m.sum() - ankles
    assert np.allclose(com.offset(torch.as_tensor(q)[None])[0].numpy(), expected, atol=1e-4)


def _fake_env(robot, free_joint_actions: str):
    n, d = 2, robot.dof
    hold = torch.ones(d, dtype=torch.bool)
    hold[list(robot.path_index)] = False
    reading = torch.zeros(n, 8, dtype=torch.float64)
    reading[:, 3:7] = _quat_about((0, 0, 1), math.pi / 2)  # the pelvis' upright orientation (a yaw)
    return SimpleNamespace(
        feedback=SimpleNamespace(name="standing", reading=reading), robot=robot, hold=hold, num_envs=n,
        num_actions=d, cfg=SimpleNamespace(free_joint_actions=free_joint_actions, posture_omega=3.0, dt=0.1),
        pos=torch.zeros(n, d, dtype=torch.float64), vel=torch.zeros(n, d, dtype=torch.float64),
        a_min=torch.full((n, d), -3.0, dtype=torch.float64), a_max=torch.full((n, d), 3.0, dtype=torch.float64),
        episode_length_buf=torch.zeros(n, dtype=torch.long))


@pytest.mark.parametrize("mode", ["posture", "centred"])
def test_controller_composes_upper_body_and_legs(robot, mode):
    env = _fake_env(robot, mode)
    upper = torch.linspace(-0.9, 0.9, robot.dof).repeat(2, 1)
    ctrl = BalanceController(env, BalanceCfg(kp_ankle=2.0, kd_ankle=0.3, k_com=0.0), upper=lambda obs: upper)
    out = ctrl(None)
    legs = env.hold
    assert torch.equal(out[:, ~legs], upper[:, ~legs].float())  # the upper body is the policy's
    assert torch.allclose(out[:, legs], torch.zeros(2, int(legs.sum())), atol=1e-6)  # upright at rest: no correction
    env.feedback.reading[0, 3:7] = _quat_about((0, 1, 0), -0.05)  # env 0 leans back 0.05 rad
    env.episode_length_buf[:] = 1
    out = ctrl(None)
    a1 = [robot.joints.index("leg_ank1_joint_r0"), robot.joints.index("leg_ank1_joint_r1")]
    assert torch.all(out[0, a1] > 0.0) and torch.allclose(out[1, legs], torch.zeros(int(legs.sum())), atol=1e-6)


def test_com_feedforward_leans_the_standing_robot_forward(robot):
    """At the zero posture the static COM is 0.2 cm ahead of the ankles; com_forward 2 cm wants it further forward."""
    env = _fake_env(robot, "posture")
    ctrl = BalanceController(env, BalanceCfg(k_com=1.0, com_forward=0.02), upper=lambda obs: torch.zeros(2, 30))
    assert ctrl.law.com_lean(ctrl.com.offset(env.pos))[:, 0].gt(0.0).all()
    out = ctrl(None)
    a1 = [robot.joints.index("leg_ank1_joint_r0"), robot.joints.index("leg_ank1_joint_r1")]
    assert torch.all(out[:, a1] > 0.0)


def test_make_controller_checks_the_balance_spec(robot):
    env = _fake_env(robot, "posture")
    with pytest.raises(ValueError, match="must be numbers"):
        make_controller({"name": "balance", "kp_ankle": "2"}, env)
    with pytest.raises(ValueError, match="must be numbers"):
        make_controller({"name": "balance", "policy": 3}, env)
    with pytest.raises(ValueError, match="omega must be > 0"):
        make_controller({"name": "balance", "policy": "", "omega": 0.0}, env)
    assert make_controller({"name": "balance", "policy": ""}, env).upper is None
