"""Ball on a plate carried by the iiwa: one PyBullet scene (DIRECT mode) for the sensory-feedback task.

The plate is a thin box rigidly attached at the flange (its centre on the TCP, its z axis along the
flange axis); the ball is a sphere whose radius, mass and rolling / spinning friction are drawn per
episode from the authors' ranges (original_pathtracking.md 8.1). The robot follows joint setpoints at the
control rate with PyBullet's position motors (target position and velocity), as in the original work.

Sensor: the ball centre in plate coordinates (x, y on the plate, z height of the ball's lowest point
above the plate surface), and ``x, y`` relative to the usable half-size of the plate (|rel| = 1 at the
usable edge). The ball counts as on the plate while its centre projects inside the plate and its lowest
point is within ``ON_PLATE_HEIGHT`` of the surface (the authors' check accepted any height below 1 m).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as p

from pathrl.robot.model import RobotSpec
from pathrl.sim.feedback import PLACE_MARGIN, PLATE_SIZE, USABLE_HALF
from pathrl.sim.scene import MotorScene, load_urdf_text, z_tilt_deg

__all__ = ["BallOnPlateScene", "BallParams", "PLATE_SIZE", "USABLE_HALF", "plate_urdf", "sample_ball"]

PLATE_MASS = 0.508  # kg
ON_PLATE_HEIGHT = 0.01  # m


@dataclass(frozen=True)
class BallParams:
    """One episode's ball: radius (m), mass (kg), rolling and spinning friction (lateral friction 1)."""

    radius: float
    mass: float
    rolling_friction: float
    spinning_friction: float


def sample_ball(rng: np.random.Generator) -> BallParams:
    """The authors' ranges: radius 20-36 mm, mass 2-203 g, rolling / spinning friction 1e-4..7e-4."""
    return BallParams(radius=rng.integers(20, 37) / 1000.0, mass=rng.integers(2, 204) / 1000.0,
                      rolling_friction=rng.integers(1, 8) / 10000.0, spinning_friction=rng.integers(1, 8) / 10000.0)


def plate_urdf(robot: RobotSpec) -> str:
    """The robot's URDF with a fixed plate link at its (single) TCP."""
    if len(robot.tcps) != 1:
        raise ValueError(f"ball on plate needs a robot with one TCP, {robot.name} has {len(robot.tcps)}")
    tcp = robot.tcps[0]
    sx, sy, sz = PLATE_SIZE
    ox, oy, oz = tcp.offset
    plate = f"""
  <joint name="plate_joint" type="fixed">
    <parent link="{tcp.link}"/>
    <child link="plate"/>
    <origin xyz="{ox} {oy} {oz + sz / 2}" rpy="0 0 0"/>
  </joint>
  <link name="plate">
    <inertial><mass value="{PLATE_MASS}"/><inertia ixx="0.003" ixy="0" ixz="0" iyy="0.005" iyz="0" izz="0.008"/>
    </inertial>
    <visual><geometry><box size="{sx} {sy} {sz}"/></geometry></visual>
    <collision><geometry><box size="{sx} {sy} {sz}"/></geometry></collision>
  </link>
</robot>"""
    text = Path(robot.urdf).read_text()
    if "</robot>" not in text:
        raise ValueError(f"{robot.urdf}: not a URDF (no </robot>)")
    return text.replace("</robot>", plate, 1)


class BallOnPlateScene(MotorScene):
    """iiwa + plate + ball in its own PyBullet DIRECT client; deterministic for a given seed."""

    def __init__(self, robot: RobotSpec, seed: int = 0, control_rate: float = 240.0, motor_force: float = 500.0):
        super().__init__(control_rate, motor_force)
        self.robot = robot
        self.rng = np.random.default_rng(seed)
        self.body = load_urdf_text(self.cid, plate_urdf(robot), f"{robot.name}_plate.urdf", fixed_base=True)
        names = {p.getJointInfo(self.body, j, physicsClientId=self.cid)[1].decode(): j
                 for j in range(p.getNumJoints(self.body, physicsClientId=self.cid))}
        self.joint_ids = [names[n] for n in robot.joints]
        self.plate_link = names["plate_joint"]
        for j in self.joint_ids:  # no joint damping: the motors alone follow the setpoints
            p.changeDynamics(self.body, j, linearDamping=0, angularDamping=0, jointDamping=0,
                             physicsClientId=self.cid)
        self.ball: int | None = None
        self.ball_params: BallParams | None = None

    # ------------------------------------------------------------------ episode
    def reseed(self, seed: int) -> None:
        """Draw the next balls and placements as a scene built with `seed` does."""
        self.rng = np.random.default_rng(seed)

    def reset(self, q: np.ndarray, ball_xy: tuple[float, float] | None = None,
              ball: BallParams | None = None) -> BallParams:
        """Pose the robot at rest at `q` (D,), put a new ball on the plate at `ball_xy` (plate frame, m;
        default: uniform in the placement area) and return its parameters."""
        for j, x in zip(self.joint_ids, np.asarray(q, dtype=float), strict=True):
            p.resetJointState(self.body, j, float(x), 0.0, physicsClientId=self.cid)
        self._hold(q, np.zeros(len(self.joint_ids)))
        if self.ball is not None:
            p.removeBody(self.ball, physicsClientId=self.cid)
        self.ball_params = bp = ball or sample_ball(self.rng)
        if ball_xy is None:
            hx, hy = USABLE_HALF[0] - PLACE_MARGIN, USABLE_HALF[1] - PLACE_MARGIN
            ball_xy = (self.rng.uniform(-hx, hx), self.rng.uniform(-hy, hy))
        pos, orn = self.plate_pose()
        local = (float(ball_xy[0]), float(ball_xy[1]), PLATE_SIZE[2] / 2 + bp.radius)
        world, _ = p.multiplyTransforms(pos, orn, local, (0, 0, 0, 1))
        shape = p.createCollisionShape(p.GEOM_SPHERE, radius=bp.radius, physicsClientId=self.cid)
        self.ball = p.createMultiBody(bp.mass, shape, basePosition=world, physicsClientId=self.cid)
        p.changeDynamics(self.ball, -1, lateralFriction=1.0, rollingFriction=bp.rolling_friction,
                         spinningFriction=bp.spinning_friction, physicsClientId=self.cid)
        return bp

    # ------------------------------------------------------------------ sensors
    def plate_pose(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """World position and xyzw orientation of the plate centre."""
        s = p.getLinkState(self.body, self.plate_link, computeForwardKinematics=True, physicsClientId=self.cid)
        return s[4], s[5]

    def plate_tilt_deg(self) -> float:
        """Angle between the plate normal and world z (deg)."""
        return z_tilt_deg(self.plate_pose()[1])

    def ball_on_plate(self) -> np.ndarray:
        """Ball in plate coordinates (3,): centre x, y (m) and the height of its lowest point above the surface."""
        if self.ball is None or self.ball_params is None:
            raise RuntimeError("reset() first")
        pos, orn = self.plate_pose()
        ball, _ = p.getBasePositionAndOrientation(self.ball, physicsClientId=self.cid)
        inv_pos, inv_orn = p.invertTransform(pos, orn)
        local, _ = p.multiplyTransforms(inv_pos, inv_orn, ball, (0, 0, 0, 1))
        return np.array([local[0], local[1], local[2] - PLATE_SIZE[2] / 2 - self.ball_params.radius])

    def ball_relative(self) -> np.ndarray:
        """Ball x, y relative to the usable half-size of the plate (2,): 0 at the centre, +-1 at the usable edge."""
        b = self.ball_on_plate()
        return np.array([b[0] / USABLE_HALF[0], b[1] / USABLE_HALF[1]])

    def ball_is_on_plate(self, b: np.ndarray | None = None) -> bool:
        """True if the ball (`b`: :meth:`ball_on_plate`, read now if not given) is within the plate's outline and
        near its surface."""
        b = self.ball_on_plate() if b is None else b
        inside = abs(b[0]) <= PLATE_SIZE[0] / 2 and abs(b[1]) <= PLATE_SIZE[1] / 2
        return bool(inside and -ON_PLATE_HEIGHT <= b[2] <= ON_PLATE_HEIGHT)
