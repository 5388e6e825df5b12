"""Shared PyBullet plumbing of the physics scenes: a DIRECT client stepping at the control rate, and joint
position motors (target position and velocity) that follow setpoints."""

from __future__ import annotations

import re
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Self

import numpy as np
import pybullet as p

from pathrl.robot.bodies import resolve_mesh

__all__ = ["FixedBaseScene", "MotorScene", "collision_only_urdf", "load_urdf", "load_urdf_text", "z_tilt_deg"]


def z_tilt_deg(orientation_xyzw) -> float:
    """Angle between a frame's z axis and world z (deg)."""
    z = np.asarray(p.getMatrixFromQuaternion(orientation_xyzw)).reshape(3, 3)[:, 2]
    return float(np.degrees(np.arccos(np.clip(z[2], -1.0, 1.0))))


def collision_only_urdf(urdf: Path) -> str:
    """The URDF's text without ``<visual>`` elements and with absolute mesh paths (for a copy elsewhere).

    A DIRECT client never draws, but PyBullet still parses every visual mesh: ARMAR-4's 89 MB of OBJ files
    cost 285 MB per client. ``package://NAME/...`` resolves against the URDF's directory and its ancestors
    (as PyBullet does), relative paths against the URDF's directory.
    """
    root = ET.parse(urdf).getroot()
    for link in root.iter("link"):
        for visual in link.findall("visual"):
            link.remove(visual)

    def resolve(match: re.Match) -> str:
        try:
            return f'filename="{resolve_mesh(urdf, match.group(1))}"'
        except FileNotFoundError:
            return match.group(0)  # PyBullet reports a missing mesh

    return re.sub(r'filename="([^"/][^"]*)"', resolve, ET.tostring(root, encoding="unicode"))


def load_urdf(cid: int, urdf: Path, fixed_base: bool) -> int:
    """Load ``urdf`` into client ``cid`` without its visual meshes (:func:`collision_only_urdf`)."""
    urdf = Path(urdf).resolve()
    return load_urdf_text(cid, collision_only_urdf(urdf), urdf.name, fixed_base)


def load_urdf_text(cid: int, text: str, name: str, fixed_base: bool) -> int:
    """Load URDF ``text`` (mesh paths absolute) into client ``cid`` through a temporary file ``name``."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / name
        path.write_text(text)
        return p.loadURDF(str(path), useFixedBase=fixed_base, physicsClientId=cid)


class MotorScene:
    """Base of the scenes: subclasses load their bodies and set ``body`` and ``joint_ids``."""

    body: int
    joint_ids: list[int]

    def __init__(self, control_rate: float = 240.0, motor_force: float = 500.0):
        self.control_dt = 1.0 / control_rate
        self.motor_force = motor_force
        self.cid = p.connect(p.DIRECT)
        if self.cid < 0:
            raise RuntimeError("pybullet: could not open a DIRECT client")
        p.setGravity(0, 0, -9.81, physicsClientId=self.cid)
        p.setTimeStep(self.control_dt, physicsClientId=self.cid)

    def follow(self, q: np.ndarray, qd: np.ndarray) -> None:
        """Track setpoints (K, D) positions and velocities, one physics step per control period."""
        q, qd = np.asarray(q, dtype=float).tolist(), np.asarray(qd, dtype=float).tolist()  # (K, D), once per call
        for qk, vk in zip(q, qd, strict=True):
            self._command(qk, vk)
            p.stepSimulation(physicsClientId=self.cid)

    def _hold(self, q: np.ndarray, qd: np.ndarray) -> None:
        self._command(np.asarray(q, dtype=float).tolist(), np.asarray(qd, dtype=float).tolist())

    def _command(self, q: list[float], qd: list[float]) -> None:
        """Position-control targets q and qd (D,) as Python floats (converted by the caller: this runs per setpoint)."""
        p.setJointMotorControlArray(self.body, self.joint_ids, p.POSITION_CONTROL, targetPositions=q,
                                    targetVelocities=qd, forces=[self.motor_force] * len(self.joint_ids),
                                    physicsClientId=self.cid)

    def joint_positions(self) -> np.ndarray:
        """Measured joint positions (D,)."""
        return np.array([s[0] for s in p.getJointStates(self.body, self.joint_ids, physicsClientId=self.cid)])

    def close(self) -> None:
        """Disconnect from the physics server (idempotent)."""
        if self.cid is not None and self.cid >= 0:
            p.disconnect(physicsClientId=self.cid)
            self.cid = -1

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class FixedBaseScene(MotorScene):
    """A robot with a fixed base following setpoints (no task objects): the simulation cost of tracking alone."""

    def __init__(self, robot, control_rate: float = 240.0, motor_force: float = 500.0):
        super().__init__(control_rate, motor_force)
        self.body = load_urdf(self.cid, robot.urdf, fixed_base=True)
        joints = {p.getJointInfo(self.body, j, physicsClientId=self.cid)[1].decode(): j
                  for j in range(p.getNumJoints(self.body, physicsClientId=self.cid))}
        self.joint_ids = [joints[n] for n in robot.joints]

    def reset(self, q: np.ndarray) -> None:
        """Place the joints at `q` at rest and hold them there."""
        for j, x in zip(self.joint_ids, np.asarray(q, dtype=float), strict=True):
            p.resetJointState(self.body, j, float(x), 0.0, physicsClientId=self.cid)
        self._hold(q, np.zeros(len(self.joint_ids)))
