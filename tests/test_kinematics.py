"""Forward kinematics: pybullet agreement on every robot, iiwa datasheet geometry, quaternion helpers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pybullet as p
import pytest
import torch

from pathrl.robot.external import load_robot_by_name
from pathrl.robot.kinematics import ForwardKinematics, matrix_to_quat, quat_angle_deg

ROBOTS = ["iiwa7", "armar6", "armar4", "armar4_legs"]


@pytest.fixture(scope="module")
def iiwa():
    return load_robot_by_name("iiwa7")


def _pybullet_reference(spec, q: np.ndarray):
    """TCPs and every non-base link frame from pybullet (fixed base at the origin), float64 arrays."""
    cid = p.connect(p.DIRECT)
    try:
        body = p.loadURDF(str(spec.urdf), useFixedBase=True, physicsClientId=cid)
        info = [
            p.getJointInfo(body, j, physicsClientId=cid)
            for j in range(p.getNumJoints(body, physicsClientId=cid))
        ]
        joint = {inf[1].decode(): j for j, inf in enumerate(info)}
        link = {inf[12].decode(): j for j, inf in enumerate(info)}
        links = sorted(link)
        jid = [joint[name] for name in spec.joints]
        n = len(q)
        tcp_pos, tcp_quat = np.zeros((n, len(spec.tcps), 3)), np.zeros((n, len(spec.tcps), 4))
        link_pos, link_quat = np.zeros((n, len(links), 3)), np.zeros((n, len(links), 4))
        for i, qi in enumerate(q):
            for j, v in zip(jid, qi, strict=True):
                p.resetJointState(body, j, float(v), physicsClientId=cid)
            for k, name in enumerate(links):
                st = p.getLinkState(body, link[name], computeForwardKinematics=True, physicsClientId=cid)
                link_pos[i, k], link_quat[i, k] = st[4], st[5]
            for k, tcp in enumerate(spec.tcps):
                st = p.getLinkState(body, link[tcp.link], computeForwardKinematics=True, physicsClientId=cid)
                rot = np.array(p.getMatrixFromQuaternion(st[5])).reshape(3, 3)
                tcp_pos[i, k] = np.array(st[4]) + rot @ np.array(tcp.offset)
                tcp_quat[i, k] = st[5]
        return tcp_pos, tcp_quat, link_pos, link_quat, links
    finally:
        p.disconnect(physicsClientId=cid)


@pytest.mark.parametrize("name", ROBOTS)
def test_fk_matches_pybullet(name):
    spec = load_robot_by_name(name)
    fk = ForwardKinematics(spec)
    rng = np.random.default_rng(0)
    q = rng.uniform(spec.pos_limits[:, 0], spec.pos_limits[:, 1], size=(200, spec.dof))
    q[0] = np.clip(0.0, spec.pos_limits[:, 0], spec.pos_limits[:, 1])
    ref_pos, ref_quat, ref_lpos, ref_lquat, links = _pybullet_reference(spec, q)

    pos, quat = fk.tcp_poses(torch.as_tensor(q))
    assert pos.shape == (200, len(spec.tcps), 3) and quat.shape == (200, len(spec.tcps), 4)
    # pybullet returns float32-rounded frames: ~1e-7 m / ~5e-7 rad is the attainable agreement
    assert np.abs(pos.numpy() - ref_pos).max() <= 1e-6
    assert np.deg2rad(quat_angle_deg(quat, torch.as_tensor(ref_quat)).max().item()) <= 1e-6

    lpos, lquat = fk.link_poses(q, links)  # every link of the URDF, numpy input
    assert np.abs(lpos.numpy() - ref_lpos).max() <= 1e-6
    assert np.deg2rad(quat_angle_deg(lquat, torch.as_tensor(ref_lquat)).max().item()) <= 1e-6

    np.testing.assert_allclose(fk.tcp_positions_np(q), pos.numpy(), atol=0, rtol=0)
    np.testing.assert_allclose(fk.tcp_positions_np(q[3]), pos[3].numpy(), atol=0, rtol=0)


def test_uncontrolled_joints_are_frozen_at_zero(iiwa):
    """A movable URDF joint that is not in spec.joints stays at 0."""
    sub = dataclasses.replace(iiwa, joints=iiwa.joints[:6], pos_limits=iiwa.pos_limits[:6])
    q6 = np.random.default_rng(1).uniform(-1, 1, size=(20, 6))
    q7 = np.concatenate([q6, np.zeros((20, 1))], axis=1)
    np.testing.assert_allclose(
        ForwardKinematics(sub).tcp_positions_np(q6), ForwardKinematics(iiwa).tcp_positions_np(q7), atol=1e-12
    )


def test_iiwa_datasheet_geometry(iiwa):
    fk = ForwardKinematics(iiwa)
    deg90 = math.pi / 2
    q = np.zeros((5, 7))
    q[1, 1] = deg90  # joint 2 (+y): arm horizontal towards +x
    q[2, 3] = deg90  # joint 4 (-y): forearm horizontal towards -x
    q[3, [1, 3]] = deg90  # joint 4 undoes joint 2: forearm vertical again
    q[4, 0] = deg90  # joint 1 (+z): no effect on the upright TCP position
    pos, quat = fk.tcp_poses(q)
    expected = np.array(
        [
            [0.0, 0.0, 0.34 + 0.40 + 0.40 + 0.126],  # 1.266 m above the base
            [0.40 + 0.40 + 0.126, 0.0, 0.34],  # 0.926 m out at joint-2 height
            [-(0.40 + 0.126), 0.0, 0.34 + 0.40],
            [0.40, 0.0, 0.34 + 0.40 + 0.126],
            [0.0, 0.0, 1.266],
        ]
    )
    np.testing.assert_allclose(pos[:, 0].numpy(), expected, atol=1e-12)
    np.testing.assert_allclose(quat[0, 0].numpy(), [0, 0, 0, 1], atol=1e-12)  # link_7 parallel to base at q=0
    # joint 2 = +90 deg turns the flange axis to +x: rotation of 90 deg about +y
    s = math.sqrt(0.5)
    np.testing.assert_allclose(quat[1, 0].numpy(), [0, s, 0, s], atol=1e-12)
    # TCP = flange, joint-6 axis = iiwa_link_7 origin (see the URDF comment)
    l7, _ = fk.link_poses(q[:1], ["iiwa_link_6", "iiwa_link_7"])
    np.testing.assert_allclose(l7[0].numpy(), [[0, 0, 1.14], [0, 0, 1.14]], atol=1e-12)


def test_iiwa_urdf_loads_in_rerun(iiwa):
    rr = pytest.importorskip("rerun")
    tree = rr.urdf.UrdfTree.from_file_path(iiwa.urdf)
    assert tree.root_link().name == "iiwa_link_0"
    assert [j.name for j in tree.joints()] == list(iiwa.joints)


def test_float32_and_shapes(iiwa):
    fk32 = ForwardKinematics(iiwa, dtype=torch.float32)
    fk64 = ForwardKinematics(iiwa)
    q = np.random.default_rng(2).uniform(-2, 2, size=(64, 7))
    p32, q32 = fk32.tcp_poses(torch.as_tensor(q, dtype=torch.float32))
    p64, _ = fk64.tcp_poses(q)
    assert p32.dtype == torch.float32 and q32.dtype == torch.float32
    assert np.abs(p32.numpy() - p64.numpy()).max() < 1e-5
    with pytest.raises(ValueError):
        fk64.tcp_poses(np.zeros((3, 6)))


def test_fk_is_differentiable(iiwa):
    q = torch.zeros(2, 7, dtype=torch.float64, requires_grad=True)
    ForwardKinematics(iiwa).tcp_positions(q)[..., 0].sum().backward()
    # d x_tcp / d q2 at the upright pose = lever arm 0.926 m
    assert q.grad[0, 1].item() == pytest.approx(0.926)


def test_quaternion_helpers():
    rng = np.random.default_rng(3)
    q = torch.as_tensor(rng.normal(size=(100, 4)))
    q = q / q.norm(dim=-1, keepdim=True)
    assert quat_angle_deg(q, q).abs().max().item() < 1e-6
    assert quat_angle_deg(q, -q).abs().max().item() < 1e-6  # double cover
    ref = torch.rad2deg(2 * torch.arccos(torch.clamp((q[:-1] * q[1:]).sum(-1).abs(), max=1.0)))
    torch.testing.assert_close(quat_angle_deg(q[:-1], q[1:]), ref)
    z90 = torch.tensor([0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)], dtype=torch.float64)
    assert quat_angle_deg(z90, torch.tensor([0.0, 0, 0, 1], dtype=torch.float64)).item() == pytest.approx(
        90.0
    )
    small = torch.tensor([math.sin(5e-9), 0, 0, math.cos(5e-9)], dtype=torch.float64)  # 1e-8 rad
    assert quat_angle_deg(small, torch.tensor([0.0, 0, 0, 1], dtype=torch.float64)).item() == pytest.approx(
        math.degrees(1e-8), rel=1e-6
    )
    # matrix -> quaternion round trip through pybullet's convention (xyzw)
    for quat in q[:20]:
        mat = torch.as_tensor(np.array(p.getMatrixFromQuaternion(quat.tolist())).reshape(3, 3))
        back = matrix_to_quat(mat)
        assert back[3] >= 0
        assert quat_angle_deg(back, quat).item() < 1e-5


def test_tcp_poses_of_equals_one_call_per_batch(iiwa):
    """Batched FK over several configuration batches (chunked across batch borders) = one call per batch."""
    fk = ForwardKinematics(iiwa)
    gen = torch.Generator().manual_seed(3)
    qs = [torch.rand(n, iiwa.dof, generator=gen, dtype=torch.float64) * 2 - 1 for n in (5, 1, 17, 9)]
    got = fk.tcp_poses_of(qs, chunk=7)
    assert len(got) == len(qs)
    for q, (pos, quat) in zip(qs, got, strict=True):
        p_ref, q_ref = fk.tcp_poses(q)
        assert pos.shape == p_ref.shape and quat.shape == q_ref.shape
        torch.testing.assert_close(pos, p_ref, rtol=0, atol=1e-12)
        torch.testing.assert_close(quat, q_ref, rtol=0, atol=1e-12)
    assert fk.tcp_poses_of([]) == []


def test_episode_deviations_batched_equal_single(iiwa):
    """The batched deviation metrics of several episodes equal the metrics of each episode alone."""
    from pathrl.eval.metrics import episode_deviation, episode_deviations
    from pathrl.paths.pathset import build_pathset

    fk = ForwardKinematics(iiwa)
    rng = np.random.default_rng(0)
    knots = [np.cumsum(rng.uniform(-0.1, 0.1, (8, iiwa.path_dof)), axis=0) for _ in range(2)]
    paths = build_pathset(knots, ["a", "b"])
    idx = torch.as_tensor(iiwa.path_index)
    eps = []
    for k, path in enumerate((0, 1, 0)):
        s = torch.linspace(0.1, float(paths.length[path]) * 0.9, 300 + 10 * k, dtype=torch.float64)
        q = torch.zeros(len(s), iiwa.dof, dtype=torch.float64)
        q[:, idx] = paths.position_at(torch.full((len(s),), path), s) + 0.01 * k
        eps.append((q, path, float(s[0]), float(s[-1])))
    batched = episode_deviations([e[0] for e in eps], idx, paths, [e[1] for e in eps], [e[2] for e in eps],
                                 [e[3] for e in eps], fk)
    for e, b in zip(eps, batched, strict=True):
        single = episode_deviation(e[0], idx, paths, e[1], e[2], e[3], fk)
        assert single.keys() == b.keys()
        for key in single:
            assert b[key] == pytest.approx(single[key], rel=1e-12, abs=1e-12), key
    # on the path (up to the polyline's chords) vs offset by 0.02 rad in every joint
    assert batched[0]["joint_dev_max_rad"] < 0.005 < 0.04 < batched[2]["joint_dev_mean_rad"]  # 0.02 sqrt(7) = 0.053
