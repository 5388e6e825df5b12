"""Batched forward kinematics in torch, straight from the robot's URDF (no extra dependency).

The URDF is parsed with :mod:`xml.etree`; every requested link is reached from the URDF root through a
chain of joints. Joints named in ``spec.joints`` move (revolute, continuous, prismatic); every other joint
(fixed, or a movable joint the spec does not control, e.g. fingers) is frozen at 0. Consecutive frozen
transforms are folded into one constant per moving joint at construction, so evaluating N configurations is
one small batched matrix product per moving joint on the way to the requested links.

Frames are URDF link frames expressed in the URDF root link frame (which is the pybullet world frame when
the URDF is loaded at the origin with ``useFixedBase=True``). A TCP is its link frame plus the spec's offset
rotated by the link orientation; its orientation is the link orientation (original_pathtracking.md 2.3).
Quaternions are ``(x, y, z, w)`` with ``w >= 0``.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from pathrl.robot.model import RobotConfigError, RobotSpec

__all__ = ["ForwardKinematics", "UrdfJoint", "matrix_to_quat", "parse_urdf_joints", "quat_angle_deg", "rpy_to_matrix"]

MOVABLE_TYPES = ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class UrdfJoint:
    """One URDF joint: constant origin transform (4x4, parent link -> joint frame) and unit axis."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray  # (4, 4)
    axis: np.ndarray  # (3,)


def _floats(text: str | None, default: Sequence[float]) -> np.ndarray:
    """Parse a URDF vector attribute; tolerant to commas (``armar6*.urdf`` has ``rpy="a, b c"``)."""
    if text is None:
        return np.asarray(default, dtype=np.float64)
    vals = [float(v) for v in text.replace(",", " ").split()]
    if len(vals) != len(default):
        raise RobotConfigError(f"URDF vector {text!r}: expected {len(default)} values")
    return np.asarray(vals, dtype=np.float64)


def rpy_to_matrix(rpy: Sequence[float]) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(yaw) @ Ry(pitch) @ Rx(roll)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def parse_urdf_joints(path: str | Path) -> tuple[str, dict[str, UrdfJoint]]:
    """Return the root link name and all joints of a URDF keyed by child link."""
    root = ET.parse(str(path)).getroot()
    links = [el.get("name") for el in root.findall("link")]
    by_child: dict[str, UrdfJoint] = {}
    for el in root.findall("joint"):
        origin = np.eye(4)
        o = el.find("origin")
        if o is not None:
            origin[:3, :3] = rpy_to_matrix(_floats(o.get("rpy"), (0.0, 0.0, 0.0)))
            origin[:3, 3] = _floats(o.get("xyz"), (0.0, 0.0, 0.0))
        a = el.find("axis")
        axis = _floats(a.get("xyz") if a is not None else None, (1.0, 0.0, 0.0))
        jtype = el.get("type")
        if jtype in MOVABLE_TYPES:
            norm = np.linalg.norm(axis)
            if norm == 0:
                raise RobotConfigError(f"URDF joint {el.get('name')!r} has a zero axis")
            axis = axis / norm
        child = el.find("child").get("link")
        by_child[child] = UrdfJoint(
            name=el.get("name"),
            type=jtype,
            parent=el.find("parent").get("link"),
            child=child,
            origin=origin,
            axis=axis,
        )
    roots = [name for name in links if name not in by_child]
    if len(roots) != 1:
        raise RobotConfigError(f"URDF {path}: expected one root link, found {roots}")
    return roots[0], by_child


@dataclass(frozen=True)
class _Plan:
    """Compiled evaluation order for a set of target links."""

    q_index: list[int]  # per moving node: column of q
    parent: list[int]  # per moving node: index of the parent node, -1 = root
    kind: list[int]  # 0 revolute, 1 prismatic
    a0: Tensor  # (J, 3, 3) C_R         } local rotation = a0 + sin(q) a1 + (1 - cos(q)) a2
    a1: Tensor  # (J, 3, 3) C_R K       } (Rodrigues, premultiplied by the constant origin rotation)
    a2: Tensor  # (J, 3, 3) C_R K^2     }
    cp: Tensor  # (J, 3) constant translation
    cr_axis: Tensor  # (J, 3) C_R @ axis (prismatic direction)
    target_node: list[int]  # per target: node it hangs off (-1 = root)
    target_R: Tensor  # (T, 3, 3) constant node frame -> target rotation
    target_p: Tensor  # (T, 3) constant node frame -> target translation


class ForwardKinematics:
    """Batched forward kinematics for a :class:`RobotSpec` (q in ``spec.joints`` order)."""

    def __init__(
        self, spec: RobotSpec, dtype: torch.dtype = torch.float64, device: str | torch.device = "cpu"
    ):
        self.spec = spec
        self.dtype = dtype
        self.device = torch.device(device)
        self.root, self._joints = parse_urdf_joints(spec.urdf)
        movable = {j.name: j for j in self._joints.values() if j.type in MOVABLE_TYPES}
        missing = [name for name in spec.joints if name not in movable]
        if missing:
            raise RobotConfigError(f"{spec.name}: joints not movable in {spec.urdf.name}: {missing}")
        self._q_index = {name: i for i, name in enumerate(spec.joints)}
        self._plans: dict[tuple[str, ...], _Plan] = {}
        tcp_links = [t.link for t in spec.tcps]
        self._tcp_offset = torch.tensor([t.offset for t in spec.tcps], dtype=dtype, device=self.device)
        self._tcp_links = tuple(tcp_links)

    # ----------------------------------------------------------------------------------------------- compile
    def _chain(self, link: str) -> list[UrdfJoint]:
        chain: list[UrdfJoint] = []
        cur = link
        while cur != self.root:
            if cur not in self._joints:
                raise RobotConfigError(f"{self.spec.name}: link {link!r} not in {self.spec.urdf.name}")
            joint = self._joints[cur]
            chain.append(joint)
            cur = joint.parent
        return chain[::-1]

    def _plan(self, links: tuple[str, ...]) -> _Plan:
        plan = self._plans.get(links)
        if plan is not None:
            return plan
        nodes: dict[str, int] = {}  # moving joint name -> node index
        q_index, parent, kind, a0, a1, a2, cp, cr_axis = [], [], [], [], [], [], [], []
        target_node, target_T = [], []
        for link in links:
            node, const = -1, np.eye(4)  # current frame = node's child frame @ const
            for joint in self._chain(link):
                if joint.name in self._q_index:
                    if joint.name not in nodes:
                        c = const @ joint.origin
                        cr, ax = c[:3, :3], joint.axis
                        k = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
                        nodes[joint.name] = len(q_index)
                        q_index.append(self._q_index[joint.name])
                        parent.append(node)
                        kind.append(1 if joint.type == "prismatic" else 0)
                        a0.append(cr)
                        a1.append(cr @ k)
                        a2.append(cr @ k @ k)
                        cp.append(c[:3, 3])
                        cr_axis.append(cr @ ax)
                    node, const = nodes[joint.name], np.eye(4)
                else:  # fixed, or a movable joint the spec does not control: frozen at q = 0
                    const = const @ joint.origin
            target_node.append(node)
            target_T.append(const)

        def t(x: list, shape: tuple[int, ...]) -> Tensor:
            arr = np.asarray(x, dtype=np.float64).reshape(shape)
            return torch.as_tensor(arr, dtype=self.dtype, device=self.device)

        nj, nt = len(q_index), len(links)
        target_T = np.asarray(target_T).reshape(nt, 4, 4)
        plan = _Plan(
            q_index=q_index,
            parent=parent,
            kind=kind,
            a0=t(a0, (nj, 3, 3)),
            a1=t(a1, (nj, 3, 3)),
            a2=t(a2, (nj, 3, 3)),
            cp=t(cp, (nj, 3)),
            cr_axis=t(cr_axis, (nj, 3)),
            target_node=target_node,
            target_R=t(target_T[:, :3, :3], (nt, 3, 3)),
            target_p=t(target_T[:, :3, 3], (nt, 3)),
        )
        self._plans[links] = plan
        return plan

    # -------------------------------------------------------------------------------------------- evaluate
    def _as_q(self, q: Tensor | np.ndarray) -> Tensor:
        q = torch.as_tensor(q, dtype=self.dtype, device=self.device)
        if q.ndim != 2 or q.shape[1] != self.spec.dof:
            raise ValueError(f"q: expected shape (N, {self.spec.dof}), got {tuple(q.shape)}")
        return q

    def link_transforms(self, q: Tensor | np.ndarray, links: Sequence[str]) -> tuple[Tensor, Tensor]:
        """Link frames in the root frame: positions (N, L, 3) and rotation matrices (N, L, 3, 3)."""
        q = self._as_q(q)
        plan = self._plan(tuple(links))
        n = q.shape[0]
        rots: list[Tensor] = []
        poss: list[Tensor] = []
        for j, qi in enumerate(plan.q_index):
            qj = q[:, qi]
            if plan.kind[j] == 0:
                s = torch.sin(qj)[:, None, None]
                c1 = (1.0 - torch.cos(qj))[:, None, None]
                local_r = plan.a0[j] + s * plan.a1[j] + c1 * plan.a2[j]
                local_p = plan.cp[j].expand(n, 3)
            else:
                local_r = plan.a0[j].expand(n, 3, 3)
                local_p = plan.cp[j] + qj[:, None] * plan.cr_axis[j]
            par = plan.parent[j]
            if par < 0:
                rots.append(local_r)
                poss.append(local_p)
            else:
                rp = rots[par]
                rots.append(rp @ local_r)
                poss.append(poss[par] + (rp @ local_p[:, :, None])[:, :, 0])
        out_r, out_p = [], []
        for k, node in enumerate(plan.target_node):
            if node < 0:
                out_r.append(plan.target_R[k].expand(n, 3, 3))
                out_p.append(plan.target_p[k].expand(n, 3))
            else:
                rp = rots[node]
                out_r.append(rp @ plan.target_R[k])
                out_p.append(poss[node] + rp @ plan.target_p[k])
        return torch.stack(out_p, dim=1), torch.stack(out_r, dim=1)

    def link_poses(self, q: Tensor | np.ndarray, links: Sequence[str]) -> tuple[Tensor, Tensor]:
        """Link frames: positions (N, L, 3) in metres and quaternions (N, L, 4) xyzw."""
        pos, rot = self.link_transforms(q, links)
        return pos, matrix_to_quat(rot)

    def tcp_transforms(self, q: Tensor | np.ndarray) -> tuple[Tensor, Tensor]:
        """TCP positions (N, T, 3) and rotation matrices (N, T, 3, 3) (= link orientation)."""
        pos, rot = self.link_transforms(q, self._tcp_links)
        return pos + (rot @ self._tcp_offset[:, :, None])[..., 0], rot

    def tcp_poses(self, q: Tensor | np.ndarray) -> tuple[Tensor, Tensor]:
        """TCP positions (N, T, 3) in metres and orientations (N, T, 4) as xyzw quaternions."""
        pos, rot = self.tcp_transforms(q)
        return pos, matrix_to_quat(rot)

    def tcp_poses_of(self, qs: Sequence[Tensor], chunk: int = 32768) -> list[tuple[Tensor, Tensor]]:
        """:meth:`tcp_poses` of several configuration batches (N_i, D) at once: one FK pass per `chunk`
        configurations instead of one per batch (an evaluation has a thousand short episodes)."""
        sizes = [len(q) for q in qs]
        if not sizes:
            return []
        q = torch.cat([self._as_q(x) for x in qs])
        parts = [self.tcp_poses(q[i:i + chunk]) for i in range(0, max(len(q), 1), chunk)]
        pos = torch.cat([p for p, _ in parts])
        quat = torch.cat([r for _, r in parts])
        return list(zip(pos.split(sizes), quat.split(sizes), strict=True))

    def tcp_positions(self, q: Tensor | np.ndarray) -> Tensor:
        """TCP positions (N, T, 3) only."""
        return self.tcp_transforms(q)[0]

    def tcp_positions_np(self, q: np.ndarray) -> np.ndarray:
        """NumPy convenience: q (N, D) or (D,) -> TCP positions (N, T, 3) or (T, 3), float64."""
        q = np.asarray(q, dtype=np.float64)
        single = q.ndim == 1
        with torch.no_grad():
            pos = self.tcp_positions(q[None] if single else q).detach().cpu().numpy().astype(np.float64)
        return pos[0] if single else pos


def matrix_to_quat(rot: Tensor) -> Tensor:
    """Rotation matrices (..., 3, 3) -> unit quaternions (..., 4) xyzw with w >= 0 (Shepperd's method)."""
    m = rot
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    diag = torch.stack(
        [1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1
    )
    cand = torch.stack(
        [
            torch.stack([m21 - m12, m02 - m20, m10 - m01, diag[..., 0]], -1),
            torch.stack([diag[..., 1], m01 + m10, m02 + m20, m21 - m12], -1),
            torch.stack([m01 + m10, diag[..., 2], m12 + m21, m02 - m20], -1),
            torch.stack([m02 + m20, m12 + m21, diag[..., 3], m10 - m01], -1),
        ],
        -2,
    )  # (..., 4 candidates, 4)
    best = diag.argmax(-1)
    q = torch.gather(cand, -2, best[..., None, None].expand(*best.shape, 1, 4))[..., 0, :]
    q = q / torch.linalg.vector_norm(q, dim=-1, keepdim=True)
    return torch.where(q[..., 3:4] < 0, -q, q)


def quat_angle_deg(q1: Tensor, q2: Tensor) -> Tensor:
    """Rotation angle between quaternions (..., 4) in degrees: 2 * arccos(min(|<q1, q2>|, 1)).

    Evaluated as the mathematically identical ``4 * atan2(|q1 - s q2|, |q1 + s q2|)`` with
    ``s = sign(<q1, q2>)``, which stays accurate for tiny angles (arccos near 1 loses ~8 digits). Inputs are
    normalized; the quaternion sign (q vs. -q) does not matter.
    """
    q1 = q1 / torch.linalg.vector_norm(q1, dim=-1, keepdim=True)
    q2 = q2 / torch.linalg.vector_norm(q2, dim=-1, keepdim=True)
    dot = (q1 * q2).sum(-1, keepdim=True)
    q2 = torch.where(dot < 0, -q2, q2)
    diff = torch.linalg.vector_norm(q1 - q2, dim=-1)
    summ = torch.linalg.vector_norm(q1 + q2, dim=-1)
    return torch.rad2deg(4.0 * torch.atan2(diff, summ))
