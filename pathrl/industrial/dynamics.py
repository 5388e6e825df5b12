"""Rigid-body dynamics of the IRB 6640-180/2.55 through PyBullet: mass matrix and bias torques along a path.

The kinematic tree is :mod:`pathrl.industrial.arm`'s (ABB zero pose, axes z, y, y, x, y, x, the datasheet link
vectors) written as a URDF at run time; pybullet (``calculateMassMatrix``, ``calculateInverseDynamics``, fixed
base, gravity -9.81 m/s^2 along base z) evaluates it. ABB publishes no link masses or inertias, so they are
**estimated** (:data:`LINK_MASSES`, :data:`LINK_COM`, :data:`LINK_BOX`): the datasheet's total arm mass is
1310-1405 kg depending on the variant; the moving links here add up to 900 kg (+ 35 kg of tool) and a ~430 kg
fixed base is left out (it does not move). Each link is a solid box (inertia m (b^2 + c^2) / 12 ...) of the
outer size its CAD-like silhouette suggests, centred at its centre of mass:

====  =====================================  ==========  =======================  ===================
link  what                                    mass (kg)   COM in joint frame (mm)  box (mm)
====  =====================================  ==========  =======================  ===================
1     rotating frame with motors 1-2          420         (160, 0, 450)            700 x 600 x 700
2     lower arm (1075 mm)                     130         (0, 0, 540)              250 x 300 x 1200
3     arm housing, motors 4-6, counterweight  200         (60, 0, 120)             500 x 400 x 450
4     forearm tube (1142.5 mm)                100         (520, 0, 0)              1100 x 250 x 250
5     wrist housing                           35          (90, 0, 0)               250 x 200 x 200
6     flange + the calibration tool (35 kg)   40          (205, 0, 0) + tool COM   see :data:`TOOL_*`
====  =====================================  ==========  =======================  ===================

The controller's own model (its feed-forward) is the same tree with every mass and inertia scaled by a seeded
factor 1 + ``model_error`` x U(-1, 1) and the centres of mass shifted by up to ``model_error`` x 50 mm (a
deliberately wrong model, :func:`perturbed`). Units: SI inside pybullet (kg, m); the functions take joint
angles in rad and return N m and kg m^2.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from pathrl.industrial import arm

__all__ = ["LINK_BOX", "LINK_COM", "LINK_MASSES", "ArmModel", "Dynamics", "cached", "nominal", "perturbed"]

#: Estimated link masses (kg), links 1-6 (the table in the module doc).
LINK_MASSES = (420.0, 130.0, 200.0, 100.0, 35.0, 5.0)
#: Estimated centres of mass (mm) in each joint's frame at the zero pose.
LINK_COM = ((160.0, 0.0, 450.0), (0.0, 0.0, 540.0), (60.0, 0.0, 120.0), (520.0, 0.0, 0.0), (90.0, 0.0, 0.0),
            (205.0, 0.0, 0.0))
#: Box sizes (mm) whose solid inertia stands for each link's.
LINK_BOX = ((700.0, 600.0, 700.0), (250.0, 300.0, 1200.0), (500.0, 400.0, 450.0), (1100.0, 250.0, 250.0),
            (250.0, 200.0, 200.0), (60.0, 200.0, 200.0))
#: The tool mounted on the flange for the calibration (kg, COM in the axis-6 frame at the zero pose, mm): a
#: spindle-like tool of 35 kg with its centre of mass half way to the TCP (the reference gives no load data).
TOOL_MASS = 35.0
TOOL_COM = (200.0 + 246.0, 0.0, -37.0)


@dataclass(frozen=True)
class ArmModel:
    """Masses (6,) kg, centres of mass (6, 3) mm and box sizes (6, 3) mm of links 1-6 (tool merged into 6)."""

    masses: tuple[float, ...]
    com: tuple[tuple[float, float, float], ...]
    box: tuple[tuple[float, float, float], ...]


def nominal() -> ArmModel:
    """The estimated arm (module doc) with the tool merged into link 6."""
    m6 = LINK_MASSES[5] + TOOL_MASS
    com6 = tuple((LINK_MASSES[5] * np.array(LINK_COM[5]) + TOOL_MASS * np.array(TOOL_COM)) / m6)
    return ArmModel(LINK_MASSES[:5] + (m6,), LINK_COM[:5] + (com6,), LINK_BOX)


def perturbed(model: ArmModel, error: float, seed: int) -> ArmModel:
    """`model` with masses scaled by 1 + error U(-1, 1) and COMs shifted by error x 50 mm U(-1, 1) (seeded)."""
    rng = np.random.default_rng(seed)
    scale = 1.0 + error * rng.uniform(-1.0, 1.0, 6)
    shift = error * 50.0 * rng.uniform(-1.0, 1.0, (6, 3))
    masses = tuple(float(m * s) for m, s in zip(model.masses, scale, strict=True))
    com = tuple(tuple(float(x) for x in np.add(c, d)) for c, d in zip(model.com, shift, strict=True))
    return ArmModel(masses, com, model.box)  # type: ignore[arg-type]


def _grid(x: float, per_unit: float) -> float:
    """x rounded to a multiple of 1 / per_unit (a power of two: exact in binary)."""
    return round(x * per_unit) / per_unit


def _urdf(model: ArmModel) -> str:
    """URDF text of the arm: joint origins are arm.LINKS (mm -> m), axes arm.AXES, boxes as inertias."""
    steps = [np.zeros(3), arm.LINKS[0], arm.LINKS[1], arm.LINKS[2], arm.LINKS[3], np.zeros(3)]
    parts = ['<?xml version="1.0"?>', '<robot name="irb6640">',
             '<link name="base"><inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" '
             'izz="0"/></inertial></link>']
    parent = "base"
    for j in range(6):
        # values on a binary grid (0.125 kg, 2^-10 m): pybullet's inverse dynamics rejects an inertia that its
        # own parallel-axis products make asymmetric by round-off
        m = _grid(model.masses[j], 8.0)
        bx, by, bz = (v / 1000.0 for v in model.box[j])
        ixx, iyy, izz = m * (by**2 + bz**2) / 12, m * (bx**2 + bz**2) / 12, m * (bx**2 + by**2) / 12
        cx, cy, cz = (_grid(v / 1000.0, 1024.0) for v in model.com[j])
        ox, oy, oz = (v / 1000.0 for v in steps[j])
        ax = " ".join(f"{v:g}" for v in arm.AXES[j])
        parts.append(f'<link name="l{j + 1}"><inertial><origin xyz="{cx} {cy} {cz}"/><mass value="{m}"/>'
                     f'<inertia ixx="{_grid(ixx, 1024.0)}" ixy="0" ixz="0" iyy="{_grid(iyy, 1024.0)}" iyz="0" '
                     f'izz="{_grid(izz, 1024.0)}"/></inertial></link>')
        parts.append(f'<joint name="j{j + 1}" type="revolute"><parent link="{parent}"/><child link="l{j + 1}"/>'
                     f'<origin xyz="{ox} {oy} {oz}"/><axis xyz="{ax}"/>'
                     '<limit lower="-10" upper="10" effort="1e6" velocity="100"/></joint>')
        parent = f"l{j + 1}"
    parts.append("</robot>")
    return "\n".join(parts)


class Dynamics:
    """PyBullet model of one :class:`ArmModel`: ``mass_matrix(q)`` (N, 6, 6) kg m^2 and ``bias(q, qd)`` (N, 6)
    N m (Coriolis, centrifugal and gravity torques; the inverse dynamics at zero acceleration)."""

    def __init__(self, model: ArmModel) -> None:
        import pybullet as pb

        self._pb = pb
        self.cid = pb.connect(pb.DIRECT)
        with tempfile.NamedTemporaryFile("w", suffix=".urdf", delete=False) as fh:
            fh.write(_urdf(model))
            path = fh.name
        try:
            self.body = pb.loadURDF(path, useFixedBase=True, physicsClientId=self.cid)
        finally:
            os.unlink(path)
        pb.setGravity(0, 0, -9.81, physicsClientId=self.cid)

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Joint-space inertia (N, 6, 6) kg m^2 at configurations q (N, 6) rad."""
        q = np.atleast_2d(q)
        return np.array([self._pb.calculateMassMatrix(self.body, list(map(float, qi)), physicsClientId=self.cid)
                         for qi in q])

    def bias(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Bias torques (N, 6) N m at configurations q (N, 6) rad and velocities qd (N, 6) rad/s."""
        q, qd = np.atleast_2d(q), np.atleast_2d(qd)
        zero = [0.0] * 6
        inv = self._pb.calculateInverseDynamics
        return np.array([inv(self.body, list(map(float, a)), list(map(float, b)), zero, physicsClientId=self.cid)
                         for a, b in zip(q, qd, strict=True)])


@lru_cache(maxsize=8)
def cached(model: ArmModel) -> Dynamics:
    """One :class:`Dynamics` per arm model and process (loading the URDF costs ~5 ms)."""
    return Dynamics(model)
