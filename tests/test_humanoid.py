"""Free-standing ARMAR-4 scene: it stands still when left alone, falls when pushed, sensors are relative to reset."""

from __future__ import annotations

import numpy as np
import pytest

from pathrl.robot.model import load_robot_by_name
from pathrl.sim.humanoid import StandingScene


@pytest.fixture(scope="module", params=["armar4", "armar4_legs"])
def scene(request):
    with StandingScene(load_robot_by_name(request.param)) as sc:
        yield sc


def hold(scene, q, seconds):
    n = int(round(seconds / scene.control_dt))
    scene.follow(np.tile(q, (n, 1)), np.zeros((n, len(q))))


def test_sensors_start_at_zero_and_robot_stands(scene):
    q0 = np.zeros(len(scene.joint_ids))
    scene.reset(q0)
    np.testing.assert_allclose(scene.pelvis_offset(), 0.0, atol=1e-12)
    assert scene.tilt_deg() < 0.5
    assert scene.pelvis_pose()[0][2] > 0.9  # pelvis about 1 m above the floor
    hold(scene, q0, 2.0)
    assert not scene.fallen()
    assert scene.tilt_deg() < 2.0 and np.linalg.norm(scene.pelvis_offset()) < 0.02


def test_push_makes_it_fall(scene):
    q0 = np.zeros(len(scene.joint_ids))
    scene.reset(q0)
    hold(scene, q0, 0.2)
    scene.push((400.0, 0.0, 0.0), 0.3)
    fell = False
    for _ in range(30):
        hold(scene, q0, 0.1)
        fell = fell or scene.fallen()
    assert fell
    assert scene.pelvis_offset()[0] > 0.2  # fell forward, in the push direction
