"""Ball-on-plate PyBullet scene: sensor values, a level plate keeps the ball, a tilted plate loses it."""

from __future__ import annotations

import numpy as np
import pytest

from pathrl.robot.external import load_robot_by_name
from pathrl.sim.ball_plate import PLATE_SIZE, USABLE_HALF, BallOnPlateScene, BallParams, plate_urdf, sample_ball

LEVEL = np.array([0.0, 0.5, 0.0, -1.0, 0.0, -1.5, 0.0])  # q6 = q4 - q2: plate level, face up
BALL = BallParams(radius=0.0275, mass=0.102, rolling_friction=3e-4, spinning_friction=3e-4)


@pytest.fixture(scope="module")
def scene():
    with BallOnPlateScene(load_robot_by_name("iiwa7"), seed=0) as sc:
        yield sc


def hold(scene, q, seconds):
    n = int(round(seconds / scene.control_dt))
    scene.follow(np.tile(q, (n, 1)), np.zeros((n, len(q))))


def test_sensor_reads_the_placed_ball(scene):
    scene.reset(LEVEL, ball_xy=(0.05, -0.03), ball=BALL)
    assert scene.plate_tilt_deg() == pytest.approx(0.0, abs=1e-3)
    b = scene.ball_on_plate()
    np.testing.assert_allclose(b, [0.05, -0.03, 0.0], atol=1e-6)
    np.testing.assert_allclose(scene.ball_relative(), [0.05 / USABLE_HALF[0], -0.03 / USABLE_HALF[1]], atol=1e-5)
    assert scene.ball_is_on_plate()


def test_level_plate_keeps_the_ball(scene):
    scene.reset(LEVEL, ball_xy=(0.02, 0.01), ball=BALL)
    hold(scene, LEVEL, 2.0)
    b = scene.ball_on_plate()
    assert np.hypot(b[0] - 0.02, b[1] - 0.01) < 2e-3 and abs(b[2]) < 1e-3
    assert np.abs(scene.joint_positions() - LEVEL).max() < 1e-4  # the motors hold the setpoint


def test_tilted_plate_loses_the_ball(scene):
    tilted = LEVEL + np.array([0, 0, 0, 0, 0, 0.26, 0])  # ~15 deg
    scene.reset(LEVEL, ball_xy=(0.0, 0.0), ball=BALL)
    hold(scene, LEVEL, 0.2)
    scene.follow(np.linspace(LEVEL, tilted, 48), np.tile((tilted - LEVEL) / 0.2, (48, 1)))
    assert scene.plate_tilt_deg() == pytest.approx(np.degrees(0.26), abs=0.5)
    left = False
    for _ in range(30):  # 3 s
        hold(scene, tilted, 0.1)
        left = left or not scene.ball_is_on_plate()
    assert left
    assert np.abs(scene.ball_on_plate()[:2]).max() > max(PLATE_SIZE[:2]) / 2


def test_acceleration_moves_the_ball_on_a_level_plate(scene):
    """Turning joint 1 quickly keeps the plate level but pushes the ball: the sensor must see it move."""
    scene.reset(LEVEL, ball_xy=(0.0, 0.0), ball=BALL)
    t = np.arange(1, 73) / 240.0  # 0.3 s, 1 rad/s^2 ... up to 1.2 rad/s
    q = np.tile(LEVEL, (72, 1))
    qd = np.zeros_like(q)
    q[:, 0] += 2.0 * t**2
    qd[:, 0] = 4.0 * t
    scene.follow(q, qd)
    assert scene.plate_tilt_deg() < 0.1
    assert np.hypot(*scene.ball_on_plate()[:2]) > 5e-3


def test_same_seed_same_episode():
    runs = []
    for _ in range(2):
        with BallOnPlateScene(load_robot_by_name("iiwa7"), seed=7) as sc:
            bp = sc.reset(LEVEL + np.array([0, 0, 0, 0, 0, 0.1, 0]))
            hold(sc, LEVEL + np.array([0, 0, 0, 0, 0, 0.1, 0]), 0.5)
            runs.append((bp, sc.ball_on_plate()))
    assert runs[0][0] == runs[1][0]
    np.testing.assert_array_equal(runs[0][1], runs[1][1])


def test_ball_ranges_and_single_tcp():
    rng = np.random.default_rng(0)
    balls = [sample_ball(rng) for _ in range(500)]
    assert min(b.radius for b in balls) >= 0.020 and max(b.radius for b in balls) <= 0.036
    assert min(b.mass for b in balls) >= 0.002 and max(b.mass for b in balls) <= 0.203
    assert all(1e-4 <= b.rolling_friction <= 7e-4 for b in balls)
    with pytest.raises(ValueError, match="one TCP"):
        plate_urdf(load_robot_by_name("armar6"))


def _roll_down_incline(c, ball_id: int, start: tuple[float, float, float], seconds: float = 1.0) -> float:
    import pybullet as p

    for _ in range(int(round(seconds * 240))):
        p.stepSimulation(physicsClientId=c)
    pos, _ = p.getBasePositionAndOrientation(ball_id, physicsClientId=c)
    return float(np.linalg.norm(np.subtract(pos, start)))


@pytest.mark.parametrize("mass", [0.002, 0.2])
def test_a_ball_loaded_like_the_authors_rolls_like_ours(tmp_path, mass):
    """The authors load a unit sphere URDF (mass 0.1, inertia 1: 25x a solid sphere's) scaled to the radius, then
    set the mass with changeDynamics. PyBullet ignores URDF inertia unless asked to, and changeDynamics recomputes
    it from the shape: on a 3 deg incline their ball and ours (a sphere shape) cover the same distance, 5/7 g sin
    minus rolling friction, not the 1/26 g sin a large inertia would give."""
    import pybullet as p

    urdf = tmp_path / "unit_sphere.urdf"
    urdf.write_text('<robot name="s"><link name="b"><inertial><mass value="0.1"/><inertia ixx="1" ixy="0" ixz="0" '
                    'iyy="1" iyz="0" izz="1"/></inertial><collision><geometry><sphere radius="1"/></geometry>'
                    '</collision></link></robot>')
    theta, r = np.radians(3.0), BALL.radius
    normal = (np.sin(theta), 0.0, np.cos(theta))
    start = tuple(float(x) * (0.001 + r) for x in normal)
    dist = []
    for authors in (True, False):
        c = p.connect(p.DIRECT)
        try:
            p.setGravity(0, 0, -9.81, physicsClientId=c)
            box = p.createCollisionShape(p.GEOM_BOX, halfExtents=[2, 2, 0.001], physicsClientId=c)
            p.createMultiBody(0, box, baseOrientation=p.getQuaternionFromEuler([0, theta, 0]), physicsClientId=c)
            if authors:
                ball = p.loadURDF(str(urdf), basePosition=start, globalScaling=r, physicsClientId=c)
                p.changeDynamics(ball, -1, mass=mass, lateralFriction=1.0, rollingFriction=BALL.rolling_friction,
                                 spinningFriction=BALL.spinning_friction, physicsClientId=c)
            else:
                shape = p.createCollisionShape(p.GEOM_SPHERE, radius=r, physicsClientId=c)
                ball = p.createMultiBody(mass, shape, basePosition=start, physicsClientId=c)
                p.changeDynamics(ball, -1, lateralFriction=1.0, rollingFriction=BALL.rolling_friction,
                                 spinningFriction=BALL.spinning_friction, physicsClientId=c)
            inertia = p.getDynamicsInfo(ball, -1, physicsClientId=c)[2]
            assert inertia[0] == pytest.approx(0.4 * mass * r * r, rel=1e-6)
            dist.append(_roll_down_incline(c, ball, start))
        finally:
            p.disconnect(c)
    solid = 0.5 * 5 / 7 * 9.81 * np.sin(theta)  # no rolling friction, 1 s
    assert dist[0] == pytest.approx(dist[1], abs=1e-6)
    assert 0.8 * solid < dist[0] < solid
