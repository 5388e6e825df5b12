"""Static centre of mass of a standing robot relative to its feet, batched (torch forward kinematics).

Masses and inertial origins come from the URDF (through PyBullet, DIRECT mode, once); link frames from
:class:`pathrl.robot.kinematics.ForwardKinematics`. The offset is expressed in the frame of the first foot link,
turned into world axes with that foot's orientation at the zero posture (flat on the floor): x forward, y left,
z up, relative to the midpoint of the foot links' origins (the ankles).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import Tensor

from pathrl.robot.kinematics import ForwardKinematics

__all__ = ["StaticCom"]


def _urdf_masses(robot: Any, feet: list[str]) -> tuple[list[str], np.ndarray, np.ndarray, str, np.ndarray]:
    """(link names, masses (L,), inertial origins in the link frames (L, 3), base link name, world rotation
    (3, 3) of the first foot at the zero posture with the base at the URDF's own pose)."""
    import pybullet as p

    from pathrl.sim.scene import load_urdf

    cid = p.connect(p.DIRECT)
    try:
        body = load_urdf(cid, robot.urdf, fixed_base=True)
        base = p.getBodyInfo(body, physicsClientId=cid)[0].decode()
        names, mass, origin = [base], [p.getDynamicsInfo(body, -1, physicsClientId=cid)[0]], []
        origin.append(p.getDynamicsInfo(body, -1, physicsClientId=cid)[3])
        foot_rot = None
        for j in range(p.getNumJoints(body, physicsClientId=cid)):
            info = p.getJointInfo(body, j, physicsClientId=cid)
            dyn = p.getDynamicsInfo(body, j, physicsClientId=cid)
            names.append(info[12].decode())
            mass.append(dyn[0])
            origin.append(dyn[3])
            if info[12].decode() == feet[0]:
                rot = p.getLinkState(body, j, computeForwardKinematics=True, physicsClientId=cid)[5]
                foot_rot = np.asarray(p.getMatrixFromQuaternion(rot)).reshape(3, 3)
        if foot_rot is None:
            raise ValueError(f"{robot.urdf}: no foot link {feet[0]!r}")
        return names, np.asarray(mass), np.asarray(origin), base, foot_rot
    finally:
        p.disconnect(physicsClientId=cid)


class StaticCom:
    """Centre of mass relative to the feet for joint positions q (N, D) of `robot` (``robot.joints`` order)."""

    def __init__(self, robot: Any, feet: list[str]):
        names, mass, origin, base, foot_rot = _urdf_masses(robot, feet)
        self.fk = ForwardKinematics(robot)
        keep = [i for i, n in enumerate(names) if n != base and mass[i] > 0.0]
        self.links = [names[i] for i in keep]
        self.mass = torch.as_tensor(mass[keep])
        self.origin = torch.as_tensor(origin[keep])
        self.base_mass, self.base_origin = float(mass[0]), torch.as_tensor(origin[0])
        self.feet = list(feet)
        self.foot_rot = torch.as_tensor(foot_rot)
        self.total = float(self.mass.sum()) + self.base_mass

    def offset(self, q: Tensor) -> Tensor:
        """COM minus the ankles' midpoint (N, 3) in m: forward, left, up (world axes with the feet flat)."""
        pos, rot = self.fk.link_transforms(q.to(torch.float64), self.links + self.feet)
        k = len(self.links)
        com = (self.mass[:, None] * (pos[:, :k] + (rot[:, :k] @ self.origin[:, :, None])[..., 0])).sum(1)
        com = (com + self.base_mass * self.base_origin) / self.total
        foot = pos[:, k:].mean(dim=1)
        local = (rot[:, k].transpose(1, 2) @ (com - foot)[:, :, None])[..., 0]  # in the first foot's frame
        return local @ self.foot_rot.T

    def points(self, q: Tensor) -> Tensor:
        """Centre of mass of every massive link (N, L + 1, 3) relative to the ankles' midpoint, in the axes of
        :meth:`offset` (the base last); their mass-weighted mean is :meth:`offset`."""
        pos, rot = self.fk.link_transforms(q.to(torch.float64), self.links + self.feet)
        k = len(self.links)
        pts = pos[:, :k] + (rot[:, :k] @ self.origin[:, :, None])[..., 0]
        pts = torch.cat([pts, self.base_origin.expand(len(pts), 1, 3)], dim=1)
        local = (pts - pos[:, k:].mean(dim=1, keepdim=True)) @ rot[:, k]  # row-wise R_foot^T (p - ankles)
        return local @ self.foot_rot.T

    def point_masses(self) -> Tensor:
        """Masses (L + 1,) in kg in the order of :meth:`points`."""
        return torch.cat([self.mass, torch.tensor([self.base_mass], dtype=self.mass.dtype)])

    def zmp(self, q: Tensor, v: Tensor, a: Tensor, ankle_height: float, h: float = 1e-3,
            g: float = 9.81) -> tuple[Tensor, Tensor]:
        """Zero-moment point of the commanded motion with the feet flat and fixed on the floor.

        The links are point masses at their centres of mass; their accelerations are the central second difference
        of :meth:`points` along q(t) = q + v t + a t^2 / 2 at t = +-h (exact up to O(h^2)), so joint velocities
        (N, D) rad/s and accelerations (N, D) rad/s^2 both count. The floor lies `ankle_height` m below the ankles.

        Returns:
            ``(zmp, com_acc)``: the ZMP (N, 2) in m (forward, left; relative to the ankles, on the floor) and the
            acceleration of the centre of mass (N, 3) in m/s^2.
        """
        q, v, a = (x.to(torch.float64) for x in (q, v, a))
        mid = q + (0.5 * h * h) * a
        p0, pp, pm = self.points(q), self.points(mid + h * v), self.points(mid - h * v)
        acc = (pp - 2.0 * p0 + pm) / (h * h)  # (N, P, 3)
        m = self.point_masses()[None, :, None]
        z = p0[..., 2:3] + ankle_height  # height above the floor
        weight = m * (g + acc[..., 2:3])  # (N, P, 1): each point's share of the vertical force
        moment = (weight * p0[..., :2] - m * z * acc[..., :2]).sum(dim=1)
        return moment / weight.sum(dim=1), (m * acc).sum(dim=1) / self.total
