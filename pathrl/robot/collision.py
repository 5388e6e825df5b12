"""PyBullet collision checker for configurations (dataset generation: reject colliding poses).

A configuration collides if two robot links penetrate (self-collision) or a robot link penetrates the floor
plane ``z = spec.floor_z + floor_margin`` (URDF root frame; the robot is loaded at the origin with a fixed
base, so the iiwa base and the ARMAR feet / platform stand on ``z = 0``). "Penetrate" means a pybullet
contact distance < 0 (exact for primitives; meshes are used as pybullet's convex hulls).

Link pairs that are never checked (decided once at construction, see :attr:`CollisionChecker.excluded_pairs`):

1. links in the same rigid group (links joined by joints that are not in ``spec.joints``: fixed joints, and
   movable joints the spec does not control, which stay at 0);
2. adjacent rigid groups (parent and child of one controlled joint);
3. pairs already in contact in the default pose ``q0`` (= 0 clipped to the position limits, the pose the
   URDF is loaded in, robot standing on the floor). This is MoveIt's "default" rule; it contains every pair
   that is in contact at all configurations ("always" rule), because ``q0`` is one of them. For the shipped
   robots these are overlapping convex hulls around a joint two links apart: ARMAR-6 ``arm_t67``/``arm_t8``
   and ARMAR-4 ``arm_elb2``/``arm_wri2`` (in contact in 100 % of random configurations), ARMAR-4
   ``torso_pitch``/``arm_sho2_r0`` (80 %, only the r0 side) and, with controlled legs, ``leg_hip1``/
   ``leg_hip3`` and ``leg_knee``/``leg_ank2`` (100 %), ``leg_hip1``/``torso_yaw`` (50 %).

Floor checks skip links rigidly attached to the base (they cannot move relative to the floor) and the rigid
groups that touch the floor in the default pose (the ARMAR-4 feet when the legs are controlled).
"""

from __future__ import annotations

import numpy as np
import pybullet as p

from pathrl.robot.model import RobotSpec

__all__ = ["CollisionChecker"]

BASE = -1  # pybullet link index of the base


class CollisionChecker:
    """Self- and floor-collision checks for a :class:`RobotSpec` in its own pybullet DIRECT client."""

    def __init__(self, spec: RobotSpec, floor_margin: float = 0.0):
        self.spec = spec
        self.floor_margin = float(floor_margin)
        self._cid: int | None = p.connect(p.DIRECT)
        if self._cid < 0:
            self._cid = None
            raise RuntimeError("pybullet: could not open a DIRECT client")
        try:
            self._setup()
        except Exception:
            self.close()
            raise

    # ------------------------------------------------------------------------------------------------ setup
    def _setup(self) -> None:
        cid, spec = self._cid, self.spec
        flags = p.URDF_USE_SELF_COLLISION | p.URDF_USE_SELF_COLLISION_INCLUDE_PARENT
        self._body = body = p.loadURDF(str(spec.urdf), useFixedBase=True, flags=flags, physicsClientId=cid)
        n = p.getNumJoints(body, physicsClientId=cid)
        info = [p.getJointInfo(body, j, physicsClientId=cid) for j in range(n)]
        joint_index = {inf[1].decode(): j for j, inf in enumerate(info)}
        missing = [name for name in spec.joints if name not in joint_index]
        if missing:
            raise ValueError(f"{spec.name}: joints not in {spec.urdf.name}: {missing}")
        self._joint_ids = [joint_index[name] for name in spec.joints]
        self.link_names = {j: inf[12].decode() for j, inf in enumerate(info)}
        self.link_names[BASE] = p.getBodyInfo(body, physicsClientId=cid)[0].decode()
        parent = {j: inf[16] for j, inf in enumerate(info)}
        controlled = set(self._joint_ids)
        group = {BASE: BASE}  # link -> rigid group id (= link index of the group's root link)
        for j in range(n):  # pybullet orders links parent-before-child
            group[j] = j if j in controlled else group[parent[j]]
        adjacent = {frozenset((group[j], group[parent[j]])) for j in controlled}
        links = [BASE, *range(n)]
        excluded: set[tuple[int, int]] = set()
        for i, a in enumerate(links):
            for b in links[i + 1 :]:
                if group[a] == group[b] or frozenset((group[a], group[b])) in adjacent:
                    excluded.add((a, b))

        plane_shape = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
        self._floor = p.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=plane_shape,
            basePosition=[0.0, 0.0, spec.floor_z + self.floor_margin],
            physicsClientId=cid,
        )
        floor_exempt = {link for link in links if group[link] == BASE}

        # Default-pose rule: pairs (and floor-touching rigid groups) in contact at q0 are excluded.
        self.q_default = np.clip(np.zeros(spec.dof), spec.pos_limits[:, 0], spec.pos_limits[:, 1])
        self._set(self.q_default)
        p.performCollisionDetection(physicsClientId=cid)
        default_pairs: set[tuple[int, int]] = set()
        for c in p.getContactPoints(bodyA=body, physicsClientId=cid):
            if c[8] >= 0:
                continue
            if c[2] == body:
                pair = (min(c[3], c[4]), max(c[3], c[4]))
                if pair not in excluded:
                    default_pairs.add(pair)
            elif c[2] == self._floor and c[3] not in floor_exempt:
                floor_exempt |= {link for link in links if group[link] == group[c[3]]}
        excluded |= default_pairs

        for a, b in excluded:
            p.setCollisionFilterPair(body, body, a, b, 0, physicsClientId=cid)
        for link in floor_exempt:
            p.setCollisionFilterPair(body, self._floor, link, BASE, 0, physicsClientId=cid)
        self._excluded = excluded
        self._floor_exempt = floor_exempt
        self.excluded_pairs = sorted((self.link_names[a], self.link_names[b]) for a, b in excluded)
        self.default_contact_pairs = sorted(
            (self.link_names[a], self.link_names[b]) for a, b in default_pairs
        )
        self.floor_exempt_links = sorted(self.link_names[link] for link in floor_exempt)

    # ------------------------------------------------------------------------------------------------ query
    def _set(self, q: np.ndarray) -> None:
        # one call for all joints (7x faster than a resetJointState loop; same link transforms and contacts,
        # checked in tests/test_collision.py)
        p.resetJointStatesMultiDof(
            self._body, self._joint_ids, [[float(v)] for v in q], physicsClientId=self._cid
        )

    def _contacts(self, q: np.ndarray) -> list[tuple[str, str, float]]:
        """Penetrating contacts at q: (link A, link B or 'floor', distance < 0)."""
        if self._cid is None:
            raise RuntimeError("CollisionChecker is closed")
        self._set(q)
        p.performCollisionDetection(physicsClientId=self._cid)
        out = []
        for c in p.getContactPoints(bodyA=self._body, physicsClientId=self._cid):
            if c[8] >= 0:
                continue
            if c[2] == self._body:
                if (min(c[3], c[4]), max(c[3], c[4])) not in self._excluded:
                    out.append((self.link_names[c[3]], self.link_names[c[4]], c[8]))
            elif c[2] == self._floor and c[3] not in self._floor_exempt:
                out.append((self.link_names[c[3]], "floor", c[8]))
        return out

    def colliding_pairs(self, q: np.ndarray) -> list[tuple[str, str, float]]:
        """Diagnostics for one configuration (D,): the penetrating pairs with their (negative) distance."""
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (self.spec.dof,):
            raise ValueError(f"q: expected shape ({self.spec.dof},), got {q.shape}")
        return self._contacts(q)

    def in_collision(self, q: np.ndarray) -> np.ndarray:
        """q (K, D) (or (D,)) -> (K,) bool: self-collision or floor collision."""
        q = np.asarray(q, dtype=np.float64)
        single = q.ndim == 1
        q = np.atleast_2d(q)
        if q.shape[1] != self.spec.dof:
            raise ValueError(f"q: expected shape (K, {self.spec.dof}), got {q.shape}")
        out = np.array([bool(self._contacts(row)) for row in q], dtype=bool)
        return out[0] if single else out

    # ---------------------------------------------------------------------------------------------- cleanup
    def close(self) -> None:
        """Disconnect the pybullet client (idempotent)."""
        if self._cid is not None and self._cid >= 0:
            try:
                p.disconnect(physicsClientId=self._cid)
            except p.error:
                pass
        self._cid = None

    def __enter__(self) -> CollisionChecker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # best effort; prefer close() / the context manager
        try:
            self.close()
        except Exception:
            pass
