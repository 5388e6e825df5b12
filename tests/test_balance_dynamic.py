"""Dynamic terms of the ARMAR-4 leg balance law: the ZMP of a commanded motion (pathrl.baselines.com.StaticCom.zmp)
against rigid-body kinematics and finite differences by hand, and the law's default-off equality."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest
import torch

from pathrl.baselines.balance import BalanceCfg, BalanceController, urdf_joint_axes
from pathrl.baselines.com import StaticCom
from pathrl.limits.feasible import acceleration_to_action
from pathrl.robot.external import load_robot_by_name
from pathrl.robot.kinematics import ForwardKinematics

G = 9.81
H_ANKLE = BalanceCfg().ankle_height
FEET = ["leg_ank2_r0", "leg_ank2_r1"]


@pytest.fixture(scope="module")
def robot():
    return load_robot_by_name("armar4_legs")


@pytest.fixture(scope="module")
def com(robot):
    return StaticCom(robot, FEET)


def _rigid_zmp(com: StaticCom, robot, joint: str, alpha: float) -> tuple[torch.Tensor, torch.Tensor]:
    """ZMP (2,) and COM acceleration (3,) by hand for the zero posture at rest with joint `joint` accelerating at
    `alpha` rad/s^2: the links it carries turn rigidly about its axis, each point gets alpha * axis x (p - o) and
    the others stand still; then the point-mass ZMP sum m (x (g + zdd) - z xdd) / sum m (g + zdd)."""
    q = torch.zeros(1, robot.dof, dtype=torch.float64)
    j = robot.joints.index(joint)
    bump = q.clone()
    bump[0, j] = 1e-6
    p0 = com.points(q)[0]
    carried = (com.points(bump)[0] - p0).norm(dim=1) > 0.0  # the links this joint moves
    axes, links = urdf_joint_axes(robot, [joint])  # world axes = the offset's axes at the zero posture
    pos, _ = ForwardKinematics(robot).link_transforms(q, links + FEET)
    origin = pos[0, 0] - pos[0, 1:].mean(dim=0)  # the joint's origin relative to the ankles
    axis = torch.as_tensor(axes[0], dtype=torch.float64)
    acc = torch.where(carried[:, None], alpha * torch.linalg.cross(axis.expand_as(p0), p0 - origin), 0.0)
    m = com.point_masses()
    z = p0[:, 2] + H_ANKLE
    w = m * (G + acc[:, 2])
    zmp = torch.stack([(w * p0[:, k] - m * z * acc[:, k]).sum() / w.sum() for k in (0, 1)])
    return zmp, (m[:, None] * acc).sum(0) / m.sum()


def test_points_average_to_the_static_com(robot, com):
    q = 0.3 * torch.randn(5, robot.dof, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    m = com.point_masses()
    assert torch.allclose((m[None, :, None] * com.points(q)).sum(1) / m.sum(), com.offset(q), atol=1e-12)


def test_zmp_at_rest_is_the_static_com(robot, com):
    q = 0.3 * torch.randn(3, robot.dof, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    zmp, acc = com.zmp(q, torch.zeros_like(q), torch.zeros_like(q), H_ANKLE)
    assert torch.allclose(zmp, com.offset(q)[:, :2], atol=1e-9) and torch.allclose(acc, torch.zeros_like(acc))


@pytest.mark.parametrize("joint", ["arm_sho1_joint_r0", "torso_pitch_joint"])
def test_arm_and_torso_acceleration_zmp_by_hand(robot, com, joint):
    """An arm (or the trunk) accelerating at 3 rad/s^2 from rest: the ZMP and the COM acceleration equal the rigid
    rotation's by hand, the COM acceleration equals a finite difference of the static COM, and the ZMP moves
    against the COM's horizontal acceleration by about its height / g (trunk: 1.5 times that)."""
    q = torch.zeros(1, robot.dof, dtype=torch.float64)
    a = q.clone()
    a[0, robot.joints.index(joint)] = 3.0
    zmp, acc = com.zmp(q, torch.zeros_like(q), a, H_ANKLE)
    zmp_hand, acc_hand = _rigid_zmp(com, robot, joint, 3.0)
    assert torch.allclose(zmp[0], zmp_hand, atol=1e-6) and torch.allclose(acc[0], acc_hand, atol=1e-5)
    h = 1e-2  # the static COM along q(t) = a t^2 / 2, second central difference (exact for the COM up to O(h^2))
    fd = (com.offset(0.5 * h * h * a) * 2.0 - 2.0 * com.offset(q)) / (h * h)
    assert torch.allclose(acc, fd, atol=1e-4)
    shift = zmp[0, 0] - com.offset(q)[0, 0]
    assert acc[0, 0].abs() > 0.05 and torch.sign(shift) == -torch.sign(acc[0, 0])  # a push forward: ZMP back
    height = com.offset(q)[0, 2] + H_ANKLE
    # x_zmp ~ x_com - z/g xdd for a point mass; a turning trunk adds its angular momentum (its top moves most)
    assert 0.5 * height / G < (-shift / acc[0, 0]) < 2.0 * height / G


def test_velocity_counts_centripetal(robot, com):
    """A joint turning at constant speed accelerates its links towards its axis: the ZMP moves although a = 0,
    like a finite difference of the static COM along q + v t."""
    q = torch.zeros(1, robot.dof, dtype=torch.float64)
    v = q.clone()
    v[0, robot.joints.index("torso_pitch_joint")] = 1.5
    _, acc = com.zmp(q, v, torch.zeros_like(q), H_ANKLE)
    h = 1e-2
    fd = (com.offset(h * v) - 2.0 * com.offset(q) + com.offset(-h * v)) / (h * h)
    assert acc.norm() > 0.01 and torch.allclose(acc, fd, atol=1e-4)


def test_ankle_height_matches_pybullet(robot):
    import pybullet as p

    from pathrl.sim.humanoid import StandingScene

    with StandingScene(robot) as s:
        s.reset([0.0] * robot.dof)
        for _ in range(240):  # settle 1 s on the floor
            p.stepSimulation(physicsClientId=s.cid)
        ids = [s.joint_ids[robot.joints.index(f"leg_ank2_joint_{leg}")] for leg in ("r0", "r1")]
        z = [p.getLinkState(s.body, j, physicsClientId=s.cid)[4][2] for j in ids]
    assert z == pytest.approx([H_ANKLE, H_ANKLE], abs=0.005)


def _fake_env(robot):
    n, d = 3, robot.dof
    hold = torch.ones(d, dtype=torch.bool)
    hold[list(robot.path_index)] = False
    reading = torch.zeros(n, 8, dtype=torch.float64)
    reading[:, 6] = 1.0  # upright
    lim = torch.as_tensor(robot.pos_limits, dtype=torch.float64)
    gen = torch.Generator().manual_seed(2)
    pos = (0.2 * torch.randn(n, d, generator=gen, dtype=torch.float64)).clamp(lim[:, 0], lim[:, 1])
    return SimpleNamespace(
        feedback=SimpleNamespace(name="standing", reading=reading), robot=robot, hold=hold, num_envs=n,
        num_actions=d, cfg=SimpleNamespace(free_joint_actions="posture", posture_omega=3.0, dt=0.1),
        pos=pos, vel=0.5 * torch.randn(n, d, generator=gen, dtype=torch.float64),
        acc=torch.randn(n, d, generator=gen, dtype=torch.float64), limits=SimpleNamespace(pos=lim),
        path_index=torch.as_tensor(robot.path_index), a_min=torch.full((n, d), -3.0, dtype=torch.float64),
        a_max=torch.full((n, d), 3.0, dtype=torch.float64), episode_length_buf=torch.ones(n, dtype=torch.long))


def test_default_is_the_static_law(robot):
    """Defaults: no dynamic term; the legs' actions are the static-COM law's, computed here step by step."""
    env = _fake_env(robot)
    upper = torch.rand(3, robot.dof, generator=torch.Generator().manual_seed(3)) * 2.0 - 1.0
    ctrl = BalanceController(env, BalanceCfg(), upper=lambda obs: upper)
    assert not ctrl.cfg.dynamic
    out = ctrl(None)
    f = ctrl.free
    q0 = env.pos.clone()
    q0[:, ctrl.ankles] = 0.0
    zero = torch.zeros(3, 2, dtype=torch.float64)
    a = ctrl.law.acceleration(ctrl.law.posture(zero, zero, ctrl.law.com_lean(ctrl.com.offset(q0))), env.pos[:, f],
                              env.vel[:, f])
    lo, hi = env.a_min[:, f], env.a_max[:, f]
    pull = acceleration_to_action(-9.0 * env.pos[:, f] - 6.0 * env.vel[:, f], lo, hi)
    assert torch.equal(out[:, f], (acceleration_to_action(a, lo, hi) - pull).clamp(-1, 1).float())
    assert torch.equal(out[:, ~env.hold], upper[:, ~env.hold])
    # a ZMP band that the motion never leaves changes nothing, bit for bit
    wide = BalanceController(env, BalanceCfg(zmp_min=-5.0, zmp_max=5.0), upper=lambda obs: upper)
    assert wide.cfg.dynamic and torch.equal(wide(None), out)


def test_zmp_guard_holds_the_band(robot):
    """The guard moves the legs' forward-lean acceleration so that the next step's ZMP lands on the band's edge
    (first order: within 2 mm), backwards lean for a ZMP behind zmp_min."""
    env = _fake_env(robot)
    ctrl = BalanceController(env, BalanceCfg(zmp_min=0.0, zmp_max=0.04), upper=lambda obs: torch.zeros(3, 30))
    f = ctrl.free
    upper_acc = torch.zeros_like(env.pos)
    upper_acc[:, robot.joints.index("arm_sho1_joint_r0")] = torch.tensor([3.0, -3.0, 0.0], dtype=torch.float64)
    a_legs = torch.zeros(3, len(f), dtype=torch.float64)
    guarded = ctrl.zmp_guard(a_legs, upper_acc)
    acc = upper_acc.clone()
    before, after = acc.clone(), acc.clone()
    after[:, f] = guarded
    x0 = ctrl.com.zmp(*ctrl.next_state(before), before, H_ANKLE)[0][:, 0]
    x1 = ctrl.com.zmp(*ctrl.next_state(after), after, H_ANKLE)[0][:, 0]
    inside = (x0 >= 0.0) & (x0 <= 0.04)
    assert torch.equal(guarded[inside], a_legs[inside])
    assert torch.allclose(x1, x0.clamp(0.0, 0.04), atol=2e-3)
    lean = guarded @ ctrl.lean_dir / ctrl.lean_dir.dot(ctrl.lean_dir)  # rad/s^2 of forward lean
    assert torch.all(torch.sign(lean[~inside]) == torch.where(x0[~inside] < 0.0, -1.0, 1.0))


def test_bad_dynamic_gains():
    with pytest.raises(ValueError, match="zmp_min < zmp_max"):
        BalanceCfg(zmp_min=0.05, zmp_max=0.0)
    with pytest.raises(ValueError, match="preview >= 0"):
        BalanceCfg(preview=-0.1)
    assert math.isinf(BalanceCfg().zmp_min)


def test_lean_direction_is_the_ankle_pitch(robot):
    """+1 rad of forward lean is +1 rad on both ankle pitch joints (their axes point along world -y)."""
    ctrl = BalanceController(_fake_env(robot), BalanceCfg(zmp_min=-0.05), upper=lambda obs: torch.zeros(3, 30))
    names = [robot.joints[i] for i in ctrl.free.tolist()]
    pitch = [names.index("leg_ank1_joint_r0"), names.index("leg_ank1_joint_r1")]
    assert torch.allclose(ctrl.lean_dir[pitch], torch.ones(2, dtype=torch.float64), atol=1e-3)
    assert ctrl.lean_dir.abs().sum() == pytest.approx(2.0, abs=1e-3)


def test_preview_takes_the_static_com_ahead(robot):
    """``preview``: the static COM of the path joints' posture q + v preview (legs as commanded, ankles at 0);
    at rest it is the static law's."""
    env = _fake_env(robot)
    ctrl = BalanceController(env, BalanceCfg(preview=0.3), upper=lambda obs: torch.zeros(3, 30))
    p = env.path_index
    ahead = env.pos.clone()
    ahead[:, ctrl.ankles] = 0.0
    ahead[:, p] = torch.minimum(torch.maximum(ahead[:, p] + 0.3 * env.vel[:, p], env.limits.pos[p, 0]),
                                env.limits.pos[p, 1])
    assert torch.allclose(ctrl.com_offset(), ctrl.com.offset(ahead), atol=1e-12)
    env.vel.zero_()
    still = env.pos.clone()
    still[:, ctrl.ankles] = 0.0
    assert torch.equal(ctrl.com_offset(), ctrl.com.offset(still))
