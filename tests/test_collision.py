"""PyBullet collision checker: iiwa self/floor collisions, collision-free neutral poses, bookkeeping."""

from __future__ import annotations

import dataclasses

import numpy as np
import pybullet as p
import pytest

from pathrl.robot.collision import CollisionChecker
from pathrl.robot.external import load_robot_by_name

UPRIGHT = [0.0] * 7
FOLDED_INTO_BASE = [0.0, 2.0, 0.0, -2.05, 0.0, 0.0, 0.0]  # elbow up, forearm folded back into link_0
ARM_DOWN = [0.0, 2.05, 0.0, 0.0, 0.0, 0.0, 0.0]  # straight arm tilted 117 deg: flange 9 cm below the floor
ARM_LOW = [0.0, 1.8, 0.0, 0.0, 0.0, 0.0, 0.0]  # straight arm tilted 103 deg: lowest point ~8.6 cm above it


@pytest.fixture(scope="module")
def iiwa():
    return load_robot_by_name("iiwa7")


@pytest.fixture(scope="module")
def iiwa_checker(iiwa):
    with CollisionChecker(iiwa) as cc:
        yield cc


def test_iiwa_upright_free_and_folded_detected(iiwa_checker):
    q = np.array([UPRIGHT, FOLDED_INTO_BASE, ARM_DOWN, ARM_LOW])
    np.testing.assert_array_equal(iiwa_checker.in_collision(q), [False, True, True, False])
    assert not iiwa_checker.in_collision(np.array(UPRIGHT))  # (D,) -> scalar bool
    folded = iiwa_checker.colliding_pairs(np.array(FOLDED_INTO_BASE))
    assert ("iiwa_link_0", "iiwa_link_5") in {(a, b) for a, b, _ in folded}
    down = iiwa_checker.colliding_pairs(np.array(ARM_DOWN))
    assert {b for _, b, _ in down} == {"floor"}
    assert all(d < 0 for _, _, d in folded + down)


def test_iiwa_self_collision_without_floor(iiwa):
    """With the floor out of reach only the self-collision remains."""
    with CollisionChecker(dataclasses.replace(iiwa, floor_z=-10.0)) as cc:
        np.testing.assert_array_equal(
            cc.in_collision(np.array([UPRIGHT, FOLDED_INTO_BASE, ARM_DOWN])), [0, 1, 0]
        )


def test_iiwa_floor_margin(iiwa):
    with CollisionChecker(iiwa, floor_margin=0.1) as cc:
        assert cc.in_collision(np.array([ARM_LOW]))[0]
        assert not cc.in_collision(np.array([UPRIGHT]))[0]
        assert cc.floor_exempt_links == ["iiwa_link_0"]  # the base stands on the (raised) floor


def test_iiwa_exclusions_are_adjacent_only(iiwa_checker):
    assert iiwa_checker.default_contact_pairs == []
    assert len(iiwa_checker.excluded_pairs) == 7  # 7 joints -> 7 parent/child pairs


def test_results_do_not_depend_on_history(iiwa_checker, iiwa):
    q = np.random.default_rng(0).uniform(iiwa.pos_limits[:, 0], iiwa.pos_limits[:, 1], size=(300, 7))
    a = iiwa_checker.in_collision(q)
    b = iiwa_checker.in_collision(q[::-1])[::-1]
    np.testing.assert_array_equal(a, b)
    assert 0.02 < a.mean() < 0.5


def test_joint_reset_matches_single_joint_resets(iiwa_checker, iiwa):
    """The one-call resetJointStatesMultiDof gives the same link frames as per-joint resetJointState."""
    q = np.random.default_rng(1).uniform(iiwa.pos_limits[:, 0], iiwa.pos_limits[:, 1], size=7)
    cc = iiwa_checker
    cc._set(q)
    fast = [p.getLinkState(cc._body, j, physicsClientId=cc._cid)[4:6] for j in cc._joint_ids]
    for j, v in zip(cc._joint_ids, q, strict=True):
        p.resetJointState(cc._body, j, v, physicsClientId=cc._cid)
    slow = [p.getLinkState(cc._body, j, physicsClientId=cc._cid)[4:6] for j in cc._joint_ids]
    np.testing.assert_allclose(
        np.array([a + b for a, b in fast]), np.array([a + b for a, b in slow]), atol=1e-7
    )


@pytest.mark.parametrize("name", ["armar6", "armar4", "armar4_legs"])
def test_armar_neutral_poses_are_free(name):
    spec = load_robot_by_name(name)
    with CollisionChecker(spec) as cc:
        neutral = np.stack([cc.q_default, spec.pos_limits.mean(axis=1)])
        np.testing.assert_array_equal(cc.in_collision(neutral), [False, False])
        # the check is not vacuous: some random configurations collide, most pass
        q = np.random.default_rng(0).uniform(
            spec.pos_limits[:, 0], spec.pos_limits[:, 1], size=(100, spec.dof)
        )
        assert 0.02 < cc.in_collision(q).mean() < 0.6
        assert "world" in cc.floor_exempt_links or "base" in cc.floor_exempt_links


def test_close_and_context_manager(iiwa):
    cc = CollisionChecker(iiwa)
    cc.close()
    cc.close()  # idempotent
    with pytest.raises(RuntimeError):
        cc.in_collision(np.zeros((1, 7)))
    with CollisionChecker(iiwa) as cc2:
        assert cc2.in_collision(np.zeros((2, 7))).shape == (2,)
        with pytest.raises(ValueError):
            cc2.in_collision(np.zeros((2, 6)))
    assert cc2._cid is None
