"""ARMAR-4 standing free on the floor, batched in torch (:class:`AnalyticStanding`): the fast twin of
:class:`pathrl.sim.vec.PyBulletStanding` for training, with the same sensor (:func:`standing_observation`).

Frames: W the world (z up, the floor at z = 0); B the URDF root link (``base``), where forward kinematics puts the
links. All quantities float64, SI units (m, s, rad, kg), batch first.

* Joints are where they are commanded (stiff position-controlled motors); joints not in ``robot.joints`` stay at 0.
* Stance: the body hangs off a foot that stays where it was put down, T_WB(q) = T_WF T_BF(q)^-1. Legs moved alike
  keep both feet flat. Legs that disagree (one knee bent alone) cannot: the body hangs off the foot whose stance
  puts the centre of mass lower once the other foot's lowest sole corner is lifted onto the floor (:func:`stance`;
  the other foot rocks onto that corner: one knee bent by a turns the body back by a, as PyBullet's motors let it),
  blended over ``STANCE_SOFTNESS`` (m) of that height so that the pose stays continuous. At reset the robot is put
  down as PyBullet's scene puts it down: in the URDF pose (B = W), then turned about the lowest point of its soles
  until they lie flat (ARMAR-4's soles are 0.39 deg off its foot frames: at rest the pelvis leans back 0.39 deg and
  7 mm; PyBullet 0.37 deg).
* Support polygon: the convex hull of the sole corners (each foot's resting facet of its collision mesh,
  :func:`pathrl.robot.bodies.resting_sole`) within ``CONTACT_TOL`` of the floor in the stance.
* Zero-moment point: the robot's rigid bodies (links that move together merged,
  :func:`pathrl.robot.bodies.rigid_bodies`) are point masses at their centres of mass (URDF masses); their
  accelerations are second differences of their positions in the stance over the model's instants, every
  `stride`-th control setpoint (``model_rate``, 40 Hz): ``zmp = sum m (p_xy (g + z'') - z p_xy'') / sum m (g + z'')``.
* Tipping: while the ZMP is inside the polygon the robot stands. When it leaves, the body turns as one rigid body
  about the polygon edge it crossed (angle theta >= 0 and rate omega per env; the edge is kept until it lands):

      I_e theta'' = M g (d cos theta + h sin theta) - sum m (z x_n'' - x_n z'')

  with d, h the centre of mass outward from and above the edge in the stance, x_n a body's outward distance, I_e
  the bodies' point masses and URDF inertia tensors about the edge (the tensors summed at the decision step's end);
  the sum is the joints' own motion (at theta = 0 the right side is the ZMP's distance outside the edge times
  sum m (g + z''): a tip starts exactly when the ZMP leaves). It is integrated at the control rate; theta back at 0
  puts the robot down again (an inelastic landing: at rest), and so does a sole corner the legs put down on the
  floor ``CATCH_DIST`` beyond the edge (checked once per decision step); at 90 deg the body lies on the floor.
* Sensor: the pelvis (URDF link ``root``) offset from its position at reset (the URDF pose, before the robot is
  put down: PyBullet's scene reads it there too), its orientation and tilt; fallen: tilt > 30 deg.

Neglected: the motors' compliance and force limits (but for the choice of stance foot), foot slip and turning
about the floor normal, bounces, the Coriolis terms of the joint motion during a tip.
Measured against PyBullet: tests/test_standing_model.py and tools/lab/standing_gap.py (docs/lab/armar4_balance.md).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor

from pathrl.robot.bodies import collision_vertices, resting_sole, rigid_bodies
from pathrl.robot.kinematics import ForwardKinematics, matrix_to_quat
from pathrl.robot.model import RobotSpec
from pathrl.sim.feedback import GRAVITY, FeedbackStep

__all__ = ["BASE_POS_SCALE", "BASE_TILT_SCALE", "CATCH_DIST", "CONTACT_TOL", "FALL_TILT_RAD", "FEET", "PELVIS_LINK",
           "STANCE_SOFTNESS", "AnalyticStanding", "edge_line", "hull_edges", "polygon_margin", "rotation_about",
           "stance", "standing_observation", "standing_values"]

#: Observation scales of the free-standing robot (the authors' normalization) and the fall threshold.
BASE_POS_SCALE = 0.2 / math.sqrt(3.0)  # m
BASE_TILT_SCALE = 0.125  # rad
FALL_TILT_RAD = math.radians(30.0)
PELVIS_LINK = "root"  # URDF link of the pelvis sensor
FEET = ("leg_ank2_r0", "leg_ank2_r1")  # URDF links whose soles touch the floor (heel and toe links stand higher)
STANCE_SOFTNESS = 5e-4  # m of centre-of-mass height over which the stance passes from one foot to the other
CONTACT_TOL = 2e-3  # m: a sole corner this close to the floor (or below it) in the stance supports the robot
CATCH_DIST = 1e-2  # m: a supporting sole corner this far beyond the edge a robot tips about puts it down


def standing_values(reading: Tensor, ok: Tensor) -> dict[str, Tensor]:
    """Task values (N,) of pelvis readings (N, 8) (offset m, xyzw quaternion, tilt rad) and upright flags (N,):
    base_tilt (rad), base_offset (m), base_orientation (arccos|w| 2/pi, 0..1), upright (1/0)."""
    orient = torch.arccos(reading[:, 6].abs().clamp(max=1.0)) * 2.0 / math.pi
    return {"base_tilt": reading[:, 7], "base_offset": reading[:, :3].norm(dim=1), "base_orientation": orient,
            "upright": ok.to(torch.float64)}


def standing_observation(reading: Tensor) -> Tensor:
    """The pelvis part of the state (N, 8) in [-1, 1]: offset / BASE_POS_SCALE, quaternion (xyzw), tilt mapped from
    [0, BASE_TILT_SCALE] to [-1, 1]."""
    tilt = 2.0 * reading[:, 7:8] / BASE_TILT_SCALE - 1.0
    return torch.cat([reading[:, :3] / BASE_POS_SCALE, reading[:, 3:7], tilt], dim=1).clamp(-1.0, 1.0)


def hull_edges(points: Tensor, mask: Tensor | None = None, tol: float = 1e-12) -> tuple[Tensor, Tensor, Tensor]:
    """Edges of the convex hulls of point sets (N, S, 2) (only the points where `mask` (N, S) is set), as all ordered
    pairs (i, j): ``valid`` (N, S, S) for the counter-clockwise hull edges i -> j (every point on their left,
    collinear ones included), outward unit normals (N, S, S, 2) and line offsets (N, S, S) (a point x is
    ``normal . x - offset`` outside the edge's line)."""
    if mask is not None:  # a point left out becomes a copy of one kept: it adds no edge of its own
        kept = points.gather(1, mask.to(torch.int8).argmax(dim=1)[:, None, None].expand(-1, 1, 2))
        points = torch.where(mask[..., None], points, kept)
    x, y = points[..., 0], points[..., 1]
    c = x[:, :, None] * y[:, None, :] - y[:, :, None] * x[:, None, :]  # (N, a, b): p_a x p_b
    cross = c[:, None, :, :] + c[:, :, :, None] + c.transpose(1, 2)[:, :, None, :]  # (N, i, j, k): e_ij x (p_k - p_i)
    e = points[:, None, :, :] - points[:, :, None, :]  # (N, i, j, 2): p_j - p_i
    length = e.norm(dim=-1)
    valid = (length > 1e-9) & (cross >= -tol).all(dim=-1)
    if mask is not None:
        valid = valid & mask[:, :, None] & mask[:, None, :]
    normal = torch.stack([e[..., 1], -e[..., 0]], dim=-1) / length.clamp(min=1e-9)[..., None]
    offset = (normal * points[:, :, None, :]).sum(-1)
    return valid, normal, offset


def polygon_margin(points: Tensor, x: Tensor, mask: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """How far points `x` (N, K, 2) lie outside the convex hulls of `points` (N, S, 2) (those `mask` (N, S) sets):
    the largest signed distance to a hull edge's line (N, K) (> 0 outside, minus the distance to the nearest edge
    inside), with that edge's outward normal (N, K, 2), offset (N, K) and corners i S + j (N, K) (:func:`edge_line`)."""
    valid, normal, offset = hull_edges(points, mask)  # (N, S, S), (N, S, S, 2), (N, S, S)
    normal, offset = normal.flatten(1, 2), offset.flatten(1)  # (N, E, 2), (N, E)
    dist = (x @ normal.transpose(1, 2) - offset[:, None]).masked_fill(~valid.flatten(1)[:, None], -math.inf)
    best = dist.argmax(dim=2)  # (N, K)
    return (dist.gather(2, best[..., None])[..., 0], normal.gather(1, best.flatten(1)[..., None].expand(-1, -1, 2)),
            offset.gather(1, best), best)


def edge_line(points: Tensor, edge: Tensor) -> tuple[Tensor, Tensor]:
    """The line through corners i -> j (``edge`` = i S + j, (N,)) of point sets (N, S, 2): outward unit normal (its
    right side; (N, 2)) and offset (N,), as :func:`hull_edges` gives them."""
    s = points.shape[1]
    pi = points.gather(1, (edge // s)[:, None, None].expand(-1, 1, 2))[:, 0]
    e = points.gather(1, (edge % s)[:, None, None].expand(-1, 1, 2))[:, 0] - pi
    normal = torch.stack([e[:, 1], -e[:, 0]], dim=1) / e.norm(dim=1, keepdim=True).clamp(min=1e-9)
    return normal, (normal * pi).sum(dim=1)


def rotation_about(axis: Tensor, angle: Tensor) -> Tensor:
    """Rotation matrices (N, 3, 3) by `angle` (N,) rad about unit axes (N, 3) (Rodrigues)."""
    k = torch.zeros(len(axis), 3, 3, dtype=axis.dtype, device=axis.device)
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    k = k - k.transpose(1, 2)
    s, c1 = torch.sin(angle)[:, None, None], (1.0 - torch.cos(angle))[:, None, None]
    return torch.eye(3, dtype=axis.dtype, device=axis.device) + s * k + c1 * (k @ k)


def _quat_matrix(q: Tensor) -> Tensor:
    """Rotation matrices (M, 3, 3) of quaternions (M, 4) xyzw (normalized here)."""
    x, y, z, w = (q / q.norm(dim=-1, keepdim=True)).unbind(-1)
    return torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
                        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], dim=-1).reshape(-1, 3, 3)


def _align(a: Tensor, b: Tensor) -> Tensor:
    """The smallest rotations (N, 3, 3) taking unit vectors a (N, 3) to b (N, 3) (not opposite)."""
    v, c = torch.linalg.cross(a, b), (a * b).sum(-1)
    k = torch.zeros(len(a), 3, 3, dtype=a.dtype, device=a.device)
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    k = k - k.transpose(1, 2)
    return torch.eye(3, dtype=a.dtype, device=a.device) + k + (k @ k) / (1.0 + c)[:, None, None]


def _blend(rot: Tensor, w: Tensor) -> Tensor:
    """Weighted mean (M, 3, 3) of rotations rot (M, F, 3, 3) with weights w (M, F) (normalized quaternion sum)."""
    q = matrix_to_quat(rot)
    q = q * torch.where((q * q[:, :1]).sum(-1, keepdim=True) < 0.0, -1.0, 1.0)  # one hemisphere
    return _quat_matrix((w[..., None] * q).sum(dim=1))


def stance(com: Tensor, feet_p: Tensor, feet_r: Tensor, sole: Tensor, rot_wf: Tensor, pos_wf: Tensor,
           softness: float = STANCE_SOFTNESS) -> tuple[Tensor, Tensor]:
    """The pose (R_WB (M, 3, 3), p_WB (M, 3)) of M standing postures in B: centre of mass `com` (M, 3), feet at
    `feet_p` (M, F, 3), `feet_r` (M, F, 3, 3), sole corners `sole` (M, S, 3), each foot f put down at (`rot_wf`
    (M, F, 3, 3), `pos_wf` (M, F, 3)) in W. Hung off foot f, the body's centre of mass would stand at z_f, and the
    other feet's lowest sole corner at -lift_f below the floor; the body takes the stances of lowest z_f + lift_f,
    softmax-weighted over `softness` (m). Feet that agree give one pose."""
    r = rot_wf @ feet_r.transpose(-1, -2)  # (M, F, 3, 3): R_WB hung off foot f
    p = pos_wf - (r @ feet_p[..., None])[..., 0]  # (M, F, 3)
    up = r[..., 2, :]  # (M, F, 3): world z in B
    height = (up * com[:, None]).sum(-1) + p[..., 2]  # (M, F)
    lift = (-(torch.einsum("msj,mfj->mfs", sole, up) + p[..., 2:3]).amin(dim=-1)).clamp(min=0.0)
    w = torch.softmax(-(height + lift) / softness, dim=1)
    return _blend(r, w), (w[..., None] * p).sum(dim=1)


class _Body(NamedTuple):
    """Link quantities of M postures in B: centres of mass (M, L, 3), link rotations (M, L, 3, 3), pelvis position
    (M, 3) and rotation (M, 3, 3), feet positions (M, F, 3) and rotations (M, F, 3, 3), sole corners (M, S, 3), sole
    normals of the feet (M, F, 3)."""

    com: Tensor
    rot: Tensor
    pelvis_p: Tensor
    pelvis_r: Tensor
    feet_p: Tensor
    feet_r: Tensor
    sole: Tensor
    sole_n: Tensor


class _Flat(NamedTuple):
    """Link quantities of M postures in W, standing (:func:`stance`): centres of mass (M, L, 3), R_WB (M, 3, 3),
    pelvis position (M, 3) and rotation (M, 3, 3), sole corners (M, S, 2) (x, y) and which of them touch the floor
    (M, S)."""

    com: Tensor
    r_wb: Tensor
    pelvis_p: Tensor
    pelvis_r: Tensor
    sole: Tensor
    contact: Tensor


class AnalyticStanding:
    """Free-standing ARMAR-4 (module docstring), batched over `num_envs` envs on `device`; the feedback protocol of
    :class:`pathrl.sim.feedback.Feedback` with :class:`pathrl.sim.vec.PyBulletStanding`'s observation (8: pelvis offset
    / (0.2/sqrt 3 m), quaternion xyzw, tilt from [0, 0.125 rad] to [-1, 1]), values and fall flag (tilt > 30 deg).

    ``reading`` (N, 8): offset (m), quaternion, tilt (rad), as PyBullet's pool reports it; ``theta``, ``omega`` (N,):
    the tip about the edge ``edge_n`` (N, 2) (outward normal), ``edge_c`` (N,) (line ``edge_n . x = edge_c``);
    ``margin`` (N,): the ZMP's distance outside the support polygon at the last model instant (m, < 0 inside);
    ``sole`` (N, S, 2), ``contact`` (N, S): the sole corners in W and those that carry the robot.
    """

    name = "standing"
    num_obs = 8
    value_names = ("base_tilt", "base_offset", "base_orientation", "upright")
    ok_value = "upright"

    def __init__(self, robot: RobotSpec, num_envs: int, control_rate: float = 240.0, seed: int = 0,
                 device: str | torch.device = "cpu", model_rate: float = 40.0, feet: tuple[str, ...] = FEET,
                 fk: ForwardKinematics | None = None):
        self.device = torch.device(device)
        self.n = num_envs
        self.stride = max(1, int(round(control_rate / model_rate)))  # control setpoints per model instant
        self.h, self.dtc = self.stride / control_rate, 1.0 / control_rate  # s
        self.generator = torch.Generator(device=self.device)  # the model draws nothing yet; a randomized one would
        self.generator.manual_seed(seed)
        self.fk = fk if fk is not None else ForwardKinematics(robot, device=self.device)  # the env's (make_env)
        f64 = dict(dtype=torch.float64, device=self.device)
        inert = rigid_bodies(robot)  # the links that move together merged (ARMAR-4: 47 links, 31 bodies)
        self.links = list(inert)
        self.mass = torch.tensor([inert[k].mass for k in self.links], **f64)  # (L,) kg
        self.total = float(self.mass.sum())
        self.com_local = torch.tensor([inert[k].com.tolist() for k in self.links], **f64)  # (L, 3) m, link frames
        self.inertia_local = torch.tensor([inert[k].inertia.tolist() for k in self.links], **f64)  # (L, 3, 3)
        self.feet = list(feet)
        self.targets = [*self.links, PELVIS_LINK, *self.feet]
        self._soles(robot)
        self.theta = torch.zeros(num_envs, **f64)
        self.omega = torch.zeros(num_envs, **f64)
        self.edge_n = torch.zeros(num_envs, 2, **f64)
        self.edge_n[:, 0] = 1.0
        self.edge_c = torch.zeros(num_envs, **f64)
        self.edge = torch.zeros(num_envs, dtype=torch.long, device=self.device)  # its sole corners i S + j
        self.margin = torch.zeros(num_envs, **f64)
        nf = len(self.feet)
        self.rot_wf = torch.eye(3, **f64).expand(num_envs, nf, 3, 3).clone()  # where the feet were put down in W
        self.pos_wf = torch.zeros(num_envs, nf, 3, **f64)
        self.pelvis0 = torch.zeros(num_envs, 3, **f64)
        self.hist = torch.zeros(num_envs, 2, len(self.links), 3, **f64)  # body COMs (stance) at the last 2 instants
        self.sole = torch.zeros(num_envs, len(self.sole_foot), 2, **f64)  # sole corners (stance, x y) now
        self.contact = torch.ones(num_envs, len(self.sole_foot), dtype=torch.bool, device=self.device)
        self.reading = torch.zeros(num_envs, 8, **f64)
        self.reading[:, 6] = 1.0
        self.ok = torch.ones(num_envs, dtype=torch.bool, device=self.device)

    def _soles(self, robot: RobotSpec) -> None:
        """Each foot's resting facet at the zero posture, kept in its link frame: ``sole_local`` (S, 3), the foot of
        each point ``sole_foot`` (S,), the facets' outward normals ``sole_normal`` (F, 3)."""
        q0 = torch.zeros(1, robot.dof, dtype=torch.float64, device=self.device)
        pos, rot = self.fk.link_transforms(q0, self.feet)
        pts, feet, normals = [], [], []
        for k, foot in enumerate(self.feet):
            r, p = rot[0, k].cpu().numpy(), pos[0, k].cpu().numpy()
            poly, normal = resting_sole(collision_vertices(robot.urdf, foot) @ r.T + p)
            pts += ((poly - p) @ r).tolist()
            feet += [k] * len(poly)
            normals.append((r.T @ normal).tolist())
        self.sole_local = torch.tensor(pts, dtype=torch.float64, device=self.device)
        self.sole_foot = torch.tensor(feet, dtype=torch.long, device=self.device)
        self.sole_normal = torch.tensor(normals, dtype=torch.float64, device=self.device)

    def _body(self, q: Tensor) -> _Body:
        """Link quantities of postures q (M, D) in B."""
        pos, rot = self.fk.link_transforms(q, self.targets)
        nl = len(self.links)
        com = pos[:, :nl] + (rot[:, :nl] @ self.com_local[:, :, None])[..., 0]
        fp, fr = pos[:, nl + 1:], rot[:, nl + 1:]
        sole = fp[:, self.sole_foot] + (fr[:, self.sole_foot] @ self.sole_local[:, :, None])[..., 0]
        normals = (fr @ self.sole_normal[:, :, None])[..., 0]
        return _Body(com, rot[:, :nl], pos[:, nl], rot[:, nl], fp, fr, sole, normals)

    def _flat(self, b: _Body, rot_wf: Tensor, pos_wf: Tensor) -> _Flat:
        """`b` (M postures) standing in W, its feet put down at (`rot_wf` (M, F, 3, 3), `pos_wf` (M, F, 3))."""
        com = (self.mass[:, None] * b.com).sum(dim=1) / self.total
        r, p = stance(com, b.feet_p, b.feet_r, b.sole, rot_wf, pos_wf)
        sole = b.sole @ r.transpose(1, 2) + p[:, None]
        return _Flat(b.com @ r.transpose(1, 2) + p[:, None], r, (r @ b.pelvis_p[:, :, None])[..., 0] + p,
                     r @ b.pelvis_r, sole[..., :2], sole[..., 2] <= CONTACT_TOL)

    def reset(self, env_ids: Tensor, q: Tensor) -> None:
        """See :meth:`Feedback.reset`: robots of `env_ids` put down on their soles at rest at postures q (k, D)."""
        if len(env_ids) == 0:
            return
        q = q.to(device=self.device, dtype=torch.float64)
        b = self._body(q)
        down = torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64, device=self.device).expand(len(q), 3)
        normal = b.sole_n.mean(dim=1)
        level = _align(normal / normal.norm(dim=1, keepdim=True), down)  # (k, 3, 3): turns the soles flat
        pivot = b.sole[torch.arange(len(q), device=self.device), b.sole[..., 2].argmin(dim=1)]  # (k, 3)
        low = ((b.sole - pivot[:, None]) @ level.transpose(1, 2))[..., 2].amin(dim=1) + pivot[:, 2]
        pos_wb = pivot - (level @ pivot[:, :, None])[..., 0]
        pos_wb[:, 2] -= low  # the lowest sole point on the floor
        self.rot_wf[env_ids] = level[:, None] @ b.feet_r
        self.pos_wf[env_ids] = (level[:, None] @ b.feet_p[..., None])[..., 0] + pos_wb[:, None]
        flat = self._flat(b, self.rot_wf[env_ids], self.pos_wf[env_ids])
        self.pelvis0[env_ids] = b.pelvis_p  # the URDF pose, as PyBullet's scene reads it at reset
        self.hist[env_ids] = flat.com[:, None].expand(-1, 2, -1, -1)
        self.sole[env_ids], self.contact[env_ids] = flat.sole, flat.contact
        self.theta[env_ids], self.omega[env_ids], self.margin[env_ids] = 0.0, 0.0, -1.0
        tilt = torch.arccos(b.pelvis_r[:, 2, 2].clamp(-1.0, 1.0))  # read as PyBullet's scene reads it at reset:
        self.reading[env_ids] = torch.cat([torch.zeros_like(b.pelvis_p), matrix_to_quat(b.pelvis_r), tilt[:, None]],
                                          dim=1)  # the URDF pose, before the robot is put down
        self.ok[env_ids] = True

    def step(self, q: Tensor, qd: Tensor, active: Tensor | None = None) -> FeedbackStep:
        """See :meth:`Feedback.step`: every env (active or not) follows its setpoints q (N, C, D) (rad); `qd` is not
        needed (velocities come from the positions)."""
        qs = q[:, self.stride - 1 :: self.stride].to(device=self.device, dtype=torch.float64)  # (N, K, D)
        n, k = qs.shape[:2]
        body = self._body(qs.reshape(n * k, -1))
        flat = self._flat(body, self.rot_wf.repeat_interleave(k, 0), self.pos_wf.repeat_interleave(k, 0))
        com = torch.cat([self.hist, flat.com.reshape(n, k, *flat.com.shape[1:])], dim=1)  # (N, K + 2, L, 3)
        acc = (com[:, 2:] - 2.0 * com[:, 1:-1] + com[:, :-2]) / self.h**2  # at the instants com[:, 1:-1]
        rot_w = flat.r_wb.reshape(n, k, 1, 3, 3)[:, -1] @ body.rot.reshape(n, k, *body.rot.shape[1:])[:, -1]
        spin = (rot_w @ self.inertia_local @ rot_w.transpose(-1, -2)).sum(dim=1)  # (N, 3, 3) at the step's end
        self.sole = flat.sole.reshape(n, k, -1, 2)[:, -1].clone()  # the polygon of the step's end serves all instants
        self.contact = flat.contact.reshape(n, k, -1)[:, -1].clone()
        self._follow_edge()
        margin, normal, offset, edge = polygon_margin(self.sole, self.zmp(com[:, 1:-1], acc), self.contact)
        for i in range(k):
            self._advance(com[:, i + 1], acc[:, i], spin, margin[:, i], normal[:, i], offset[:, i], edge[:, i])
        self.hist = com[:, -2:].clone()
        was_up = self.ok.clone()
        self.reading = self._read(flat.pelvis_p.reshape(n, k, 3)[:, -1], flat.pelvis_r.reshape(n, k, 3, 3)[:, -1])
        self.ok = self.ok & (self.reading[:, 7] <= FALL_TILT_RAD)
        return FeedbackStep(obs=self.observe(), values=self.values(), failed=was_up & ~self.ok)

    def zmp(self, p: Tensor, a: Tensor) -> Tensor:
        """Zero-moment points (..., 2) on the floor (m, W) of point masses at p (..., L, 3) accelerating at a."""
        w = self.mass * (GRAVITY + a[..., 2])  # (..., L): each point's share of the vertical force
        moment = (w[..., None] * p[..., :2]).sum(-2) - (self.mass[:, None] * p[..., 2:3] * a[..., :2]).sum(-2)
        return moment / w.sum(-1).clamp(min=1e-6 * self.total * GRAVITY)[..., None]

    def _follow_edge(self) -> None:
        """A tipping robot's edge moves with its two sole corners (the stance moves with the legs); a supporting
        corner the legs put down ``CATCH_DIST`` beyond it puts the robot down."""
        tipping = (self.theta > 0.0) | (self.omega > 0.0)
        normal, offset = edge_line(self.sole, self.edge)
        self.edge_n = torch.where(tipping[:, None], normal, self.edge_n)
        self.edge_c = torch.where(tipping, offset, self.edge_c)
        beyond = ((self.sole @ self.edge_n[:, :, None])[..., 0] - self.edge_c[:, None]).masked_fill(~self.contact, -1.0)
        caught = tipping & (beyond.amax(dim=1) > CATCH_DIST)
        self.theta, self.omega = self.theta.masked_fill(caught, 0.0), self.omega.masked_fill(caught, 0.0)

    def _advance(self, p: Tensor, a: Tensor, spin: Tensor, margin: Tensor, normal: Tensor, offset: Tensor,
                 edge: Tensor) -> None:
        """One model instant: body COMs p (N, L, 3) (standing pose) accelerating at a (N, L, 3), the bodies' own
        inertia tensors summed in W (N, 3, 3), the ZMP's margin (N,) to the support polygon's edge it is nearest to
        leaving (outward normal (N, 2), offset (N,), corners (N,)). A robot standing still takes that edge; a tipping
        one keeps its own. theta and omega advance `stride` control periods (semi-implicit Euler); theta stays in
        [0, 90 deg]."""
        still = (self.theta <= 0.0) & (self.omega <= 0.0)
        self.edge_n = torch.where(still[:, None], normal, self.edge_n)
        self.edge_c = torch.where(still, offset, self.edge_c)
        self.edge = torch.where(still, edge, self.edge)
        self.margin = margin
        m, n = self.mass, self.edge_n
        x = (p[..., :2] * n[:, None]).sum(-1) - self.edge_c[:, None]  # (N, L) outward of the edge
        z = p[..., 2]
        joints = (m * (z * (a[..., :2] * n[:, None]).sum(-1) - x * a[..., 2])).sum(1)  # N m
        axis = torch.stack([-n[:, 1], n[:, 0], torch.zeros_like(n[:, 0])], dim=1)  # z x n: tips towards n
        inertia = (m * (x * x + z * z)).sum(1) + ((axis[:, None, :] @ spin)[:, 0] * axis).sum(1)  # kg m^2, edge
        d, h = (m * x).sum(1) / self.total, (m * z).sum(1) / self.total
        th, om = self.theta, self.omega
        for _ in range(self.stride):
            alpha = (self.total * GRAVITY * (d * torch.cos(th) + h * torch.sin(th)) - joints) / inertia
            om = om + alpha * self.dtc
            th = th + om * self.dtc
            stop = (th <= 0.0) | (th >= math.pi / 2)
            th, om = th.clamp(0.0, math.pi / 2), torch.where(stop, torch.zeros_like(om), om)
        self.theta, self.omega = th, om

    def _read(self, pelvis_p: Tensor, pelvis_r: Tensor, env_ids: Tensor | None = None) -> Tensor:
        """Pelvis readings (M, 8) of pelvis poses in the stance (M, 3), (M, 3, 3) turned by the envs' tip (all, or
        `env_ids`)."""
        sel = slice(None) if env_ids is None else env_ids
        n, c, th = self.edge_n[sel], self.edge_c[sel], self.theta[sel]
        zero = torch.zeros_like(c)
        axis = torch.stack([-n[:, 1], n[:, 0], zero], dim=1)
        on_edge = torch.stack([c * n[:, 0], c * n[:, 1], zero], dim=1)
        turn = rotation_about(axis, th)
        pos = on_edge + (turn @ (pelvis_p - on_edge)[:, :, None])[..., 0]
        rot = turn @ pelvis_r
        tilt = torch.arccos(rot[:, 2, 2].clamp(-1.0, 1.0))
        return torch.cat([pos - self.pelvis0[sel], matrix_to_quat(rot), tilt[:, None]], dim=1)

    def push(self, env_ids: Tensor, rate: float | Tensor, direction: tuple[float, float] | Tensor) -> None:
        """Start envs `env_ids` tipping at `rate` (rad/s) about the edge of their support polygon whose outward normal
        is nearest `direction` (x, y) (an impulsive push of the standing robot; a test and study device)."""
        d = torch.as_tensor(direction, dtype=torch.float64, device=self.device).expand(len(env_ids), 2)
        valid, normal, offset = hull_edges(self.sole[env_ids], self.contact[env_ids])
        score = (normal * d[:, None, None, :]).sum(-1).masked_fill(~valid, -math.inf).flatten(1)
        best = score.argmax(dim=1)
        rows = torch.arange(len(env_ids), device=self.device)
        self.edge_n[env_ids] = normal.flatten(1, 2)[rows, best]
        self.edge_c[env_ids] = offset.flatten(1)[rows, best]
        self.edge[env_ids] = best
        self.omega[env_ids] = torch.as_tensor(rate, dtype=torch.float64, device=self.device)

    def values(self) -> dict[str, Tensor]:
        """See :func:`standing_values`."""
        return standing_values(self.reading, self.ok)

    def observe(self) -> Tensor:
        """See :meth:`Feedback.observe`: :func:`standing_observation` of the pelvis reading (N, 8)."""
        return standing_observation(self.reading)

    def privileged(self) -> Tensor:
        """What an asymmetric critic may see and the policy does not (N, 3): tip angle (rad), tip rate (rad/s) and
        the ZMP's margin to the support polygon (m, < 0 inside)."""
        return torch.stack([self.theta, self.omega, self.margin], dim=1)

    def close(self) -> None:
        """Nothing to release (torch model)."""
