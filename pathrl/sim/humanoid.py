"""ARMAR-4 standing free on the floor: one PyBullet scene (DIRECT mode) for the balance task.

The base is not fixed: the robot stands on a floor plane and only its joint motors (position control
with target velocities, at the control rate) keep it up. Sensors: the pelvis (URDF link ``root``)
position relative to its pose after :meth:`StandingScene.reset` and the tilt, the angle between the
pelvis z axis and world z. The robot has fallen when the tilt exceeds ``fall_tilt_deg`` (30 deg, the
authors' ``check_if_robot_lost_balance`` threshold).
"""

from __future__ import annotations

import numpy as np
import pybullet as p

from pathrl.robot.model import RobotSpec
from pathrl.sim.scene import MotorScene, load_urdf, z_tilt_deg

__all__ = ["StandingScene"]

PELVIS_LINK = "root"
FALL_TILT_DEG = 30.0


class StandingScene(MotorScene):
    """A free-standing humanoid (ARMAR-4 URDFs) on a floor plane; deterministic for a given input."""

    def __init__(self, robot: RobotSpec, control_rate: float = 240.0, motor_force: float = 500.0,
                 fall_tilt_deg: float = FALL_TILT_DEG):
        super().__init__(control_rate, motor_force)
        self.robot = robot
        self.fall_tilt_deg = fall_tilt_deg
        self.floor = p.createMultiBody(0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=self.cid),
                                       physicsClientId=self.cid)
        self.body = load_urdf(self.cid, robot.urdf, fixed_base=False)
        info = [p.getJointInfo(self.body, j, physicsClientId=self.cid)
                for j in range(p.getNumJoints(self.body, physicsClientId=self.cid))]
        links = {i[12].decode(): j for j, i in enumerate(info)}
        joints = {i[1].decode(): j for j, i in enumerate(info)}
        if PELVIS_LINK not in links:
            raise ValueError(f"{robot.urdf}: no link {PELVIS_LINK!r} (pelvis)")
        self.pelvis = links[PELVIS_LINK]
        self.joint_ids = [joints[n] for n in robot.joints]
        self._start = p.getBasePositionAndOrientation(self.body, physicsClientId=self.cid)
        self._pelvis0 = np.zeros(3)

    def reset(self, q: np.ndarray) -> None:
        """Put the robot upright at the origin, at rest at joint positions `q` (D,)."""
        p.resetBasePositionAndOrientation(self.body, *self._start, physicsClientId=self.cid)
        p.resetBaseVelocity(self.body, (0, 0, 0), (0, 0, 0), physicsClientId=self.cid)
        for j, x in zip(self.joint_ids, np.asarray(q, dtype=float), strict=True):
            p.resetJointState(self.body, j, float(x), 0.0, physicsClientId=self.cid)
        self._hold(q, np.zeros(len(self.joint_ids)))
        self._pelvis0 = self.pelvis_pose()[0]

    def push(self, force: tuple[float, float, float], seconds: float) -> None:
        """Push the pelvis with a world-frame force (N) for `seconds`, joints holding their current targets."""
        for _ in range(int(round(seconds / self.control_dt))):
            pos, _ = self.pelvis_pose()
            p.applyExternalForce(self.body, self.pelvis, force, tuple(pos), p.WORLD_FRAME, physicsClientId=self.cid)
            p.stepSimulation(physicsClientId=self.cid)

    # ------------------------------------------------------------------ sensors
    def pelvis_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """World position (3,) and xyzw orientation (4,) of the pelvis."""
        s = p.getLinkState(self.body, self.pelvis, computeForwardKinematics=True, physicsClientId=self.cid)
        return np.asarray(s[4]), np.asarray(s[5])

    def pelvis_offset(self) -> np.ndarray:
        """Pelvis position relative to its position after reset (3,), m."""
        return self.pelvis_pose()[0] - self._pelvis0

    def tilt_deg(self) -> float:
        """Angle between the pelvis z axis and world z (deg)."""
        return z_tilt_deg(self.pelvis_pose()[1])

    def fallen(self) -> bool:
        """True if the pelvis tilts more than ``fall_tilt_deg``."""
        return self.tilt_deg() > self.fall_tilt_deg
