"""ABB IRB 6640-180/2.55 kinematics in numpy: forward kinematics, analytic inverse kinematics, Jacobian.

Where the numbers come from: ABB *Product specification IRB 6640* (the paper's ref. [21]), variant
180 kg / 2.55 m reach. Dimensions (mm): axis 2 sits 320 in front of and 780 above the base origin, the upper
arm is 1075 long, the forearm has a 200 offset and 1142.5 from axis 3 to the wrist centre, the flange is 200
beyond the wrist centre. These are the classic DH parameters (a1 = 320, d1 = 780, a2 = 1075, a3 = 200,
d4 = 1142.5, d6 = 200) written here as a product of exponentials in ABB's zero pose (upper arm vertical,
forearm horizontal pointing along base x): joint axes z, y, y, x, y, x and the link vectors in :data:`LINKS`.
Axis ranges and maximum speeds are the datasheet's (axes 1-6: +-170, -65..+85, -180..+70, +-300, +-120,
+-360 deg; 100, 90, 90, 170, 120, 190 deg/s). The datasheet gives no joint accelerations or jerks:
:data:`ACC_LIMITS` and :data:`JERK_LIMITS` are assumptions (about 3x / 30x the speed limits per second, the
order a heavy 6-axis arm reaches with its payload) and are labelled as such wherever they are used.

Conventions: positions in mm, angles in rad, rotations as (..., 3, 3) matrices whose columns are the tool
frame axes in the base frame. The tool frame at the flange follows ABB's tool0 (z out of the flange, along base
x in the zero pose); the TCP is :data:`TOOL_OFFSET` (a straight 300 mm tool, like a spray gun) along tool z.
The arm has a spherical wrist, so inverse kinematics is closed form (:func:`ik`): shoulder front/back,
elbow up/down and wrist flip give up to 8 solutions; the one nearest a reference configuration is returned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "ACC_LIMITS", "AXES", "DEFAULT_TOOL", "JERK_LIMITS", "LINKS", "POS_LIMITS", "R_FLANGE", "TOOL_OFFSET", "VEL_LIMITS",
    "Tool", "fk", "ik", "ik_all", "ik_path", "jacobian", "within_limits",
]

#: Joint axes in the zero pose (base frame).
AXES = np.array([[0, 0, 1], [0, 1, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0]], dtype=np.float64)
#: Link vectors (mm): base -> axis 2, axis 2 -> 3, axis 3 -> 4 (offset), axis 4 -> wrist centre, wrist -> flange.
LINKS = np.array([[320.0, 0, 780.0], [0, 0, 1075.0], [0, 0, 200.0], [1142.5, 0, 0], [200.0, 0, 0]])
#: Tool0 orientation relative to the last joint frame: tool z along joint-frame x (ABB flange convention).
R_FLANGE = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
#: TCP offset in the tool frame (mm): a straight 300 mm tool.
TOOL_OFFSET = np.array([0.0, 0.0, 300.0])

DEG = np.pi / 180.0


@dataclass(frozen=True, eq=False)
class Tool:
    """A tool on the flange: TCP `offset` (3,) mm in the tool0 frame and the TCP frame's rotation `rot` (3, 3)
    in tool0 (a program's rotations are TCP rotations; tool0 = TCP rot @ rot^T)."""

    offset: np.ndarray
    rot: np.ndarray


#: The project's straight 300 mm tool (TCP frame = tool0 frame).
DEFAULT_TOOL = Tool(TOOL_OFFSET, np.eye(3))
#: Datasheet axis ranges (rad), shape (6, 2).
POS_LIMITS = DEG * np.array([[-170, 170], [-65, 85], [-180, 70], [-300, 300], [-120, 120], [-360, 360]], dtype=float)
#: Datasheet maximum axis speeds (rad/s).
VEL_LIMITS = DEG * np.array([100.0, 90.0, 90.0, 170.0, 120.0, 190.0])
#: Assumed axis accelerations (rad/s^2); not in the datasheet.
ACC_LIMITS = 3.0 * VEL_LIMITS
#: Assumed axis jerks (rad/s^3); not in the datasheet.
JERK_LIMITS = 30.0 * VEL_LIMITS

_L2 = LINKS[1, 2]
_A3, _B3 = LINKS[3, 0], LINKS[2, 2]  # forearm: 1142.5 along x, 200 along z (in the axis-3 frame)
_L3 = float(np.hypot(_A3, _B3))
_PHI = float(np.arctan2(_B3, _A3))


def _rot(axis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Rotations about a fixed unit `axis` by angles q (N,) -> (N, 3, 3) (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    s, c = np.sin(q)[:, None, None], np.cos(q)[:, None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def _frames(q: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Joint origins (6 x (N, 3)) plus the flange (7th) and the accumulated rotations after each joint
    (6 x (N, 3, 3)) of configurations q (N, 6). The axis-6 origin is the wrist centre."""
    n = q.shape[0]
    steps = [LINKS[0], LINKS[1], LINKS[2], LINKS[3], np.zeros(3), LINKS[4]]  # origin j -> origin j+1
    rot = np.broadcast_to(np.eye(3), (n, 3, 3))
    pos = np.zeros((n, 3))
    origins, rots = [pos], []
    for j in range(6):
        rot = rot @ _rot(AXES[j], q[:, j])
        rots.append(rot)
        pos = pos + rot @ steps[j]
        origins.append(pos)
    return origins, rots


def fk(q: np.ndarray, tool: np.ndarray = TOOL_OFFSET) -> tuple[np.ndarray, np.ndarray]:
    """TCP positions (N, 3) mm and tool rotations (N, 3, 3) of joint configurations q (N, 6) rad."""
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    origins, rots = _frames(q)
    rot = rots[-1] @ R_FLANGE
    return origins[-1] + rot @ tool, rot


def jacobian(q: np.ndarray, tool: np.ndarray = TOOL_OFFSET) -> np.ndarray:
    """Geometric Jacobian (N, 6, 6) of the TCP: rows 0-2 linear velocity (mm/rad), rows 3-5 angular velocity."""
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    origins, rots = _frames(q)
    p = origins[-1] + (rots[-1] @ R_FLANGE) @ tool
    jac = np.zeros((q.shape[0], 6, 6))
    for j in range(6):
        pre = np.eye(3) if j == 0 else rots[j - 1]
        w = pre @ AXES[j]
        jac[:, :3, j] = np.cross(w, p - origins[j])
        jac[:, 3:, j] = w
    return jac


def _wrist_solutions(r03: np.ndarray, r06: np.ndarray) -> np.ndarray:
    """Both wrist solutions (2, N, 3) of R03^T R06 = Rx(q4) Ry(q5) Rx(q6)."""
    m = np.swapaxes(r03, -1, -2) @ r06
    q5 = np.arctan2(np.hypot(m[:, 1, 0], m[:, 2, 0]), m[:, 0, 0])
    q4 = np.arctan2(m[:, 1, 0], -m[:, 2, 0])
    q6 = np.arctan2(m[:, 0, 1], m[:, 0, 2])
    a = np.stack([q4, q5, q6], -1)
    b = np.stack([q4 + np.pi, -q5, q6 + np.pi], -1)
    return np.stack([a, b])


def ik_all(p: np.ndarray, rot: np.ndarray, tool: np.ndarray = TOOL_OFFSET) -> tuple[np.ndarray, np.ndarray]:
    """All 8 closed-form solutions (8, N, 6) of TCP poses p (N, 3) mm, rot (N, 3, 3), and a mask (8, N) of the
    reachable ones (NaN rows where the wrist centre is out of reach)."""
    p = np.atleast_2d(np.asarray(p, dtype=np.float64))
    rot = np.asarray(rot, dtype=np.float64).reshape(-1, 3, 3)
    r06 = rot @ R_FLANGE.T
    wc = p - rot @ tool - r06[:, :, 0] * LINKS[4, 0]
    sols, ok = [], []
    for back in (False, True):
        q1 = np.arctan2(wc[:, 1], wc[:, 0]) + (np.pi if back else 0.0)
        radial = np.hypot(wc[:, 0], wc[:, 1]) * (-1.0 if back else 1.0) - LINKS[0, 0]
        height = wc[:, 2] - LINKS[0, 2]
        cos_rel = (radial**2 + height**2 - _L2**2 - _L3**2) / (2 * _L2 * _L3)
        reach = np.abs(cos_rel) <= 1.0
        for up in (True, False):
            rel = -np.arccos(np.clip(cos_rel, -1, 1)) * (1.0 if up else -1.0)
            alpha = np.arctan2(height, radial) - np.arctan2(_L3 * np.sin(rel), _L2 + _L3 * np.cos(rel))
            q2 = np.pi / 2 - alpha
            q3 = _PHI - np.pi / 2 - rel
            r03 = _rot(AXES[0], q1) @ _rot(AXES[1], q2 + q3)
            for wrist in _wrist_solutions(r03, r06):
                q = np.column_stack([q1, q2, q3, wrist])
                sols.append(np.where(reach[:, None], _wrap(q), np.nan))
                ok.append(reach)
    return np.stack(sols), np.stack(ok)


def _wrap(q: np.ndarray) -> np.ndarray:
    return (q + np.pi) % (2 * np.pi) - np.pi


def ik(p: np.ndarray, rot: np.ndarray, q_ref: np.ndarray, tool: np.ndarray = TOOL_OFFSET) -> np.ndarray:
    """Joint configurations (N, 6) of TCP poses p (N, 3) mm, rot (N, 3, 3), each the closed-form solution nearest
    `q_ref` (6,) or (N, 6) (multi-turn axes 4 and 6 are shifted by 2 pi towards the reference). Raises ValueError
    if a pose is out of reach."""
    sols, ok = ik_all(p, rot, tool)
    ref = np.broadcast_to(np.asarray(q_ref, dtype=np.float64), sols.shape[1:])
    for j in (3, 5):  # axes with a range beyond +-pi: take the turn nearest the reference
        sols[..., j] += 2 * np.pi * np.round((ref[..., j] - sols[..., j]) / (2 * np.pi))
    dist = np.where(ok, np.nansum((sols - ref) ** 2, -1), np.inf)
    best = np.argmin(dist, 0)
    if not np.all(np.isfinite(dist[best, np.arange(len(best))])):
        raise ValueError("pose out of reach of the IRB 6640")
    return sols[best, np.arange(len(best))]


def ik_path(p: np.ndarray, rot: np.ndarray, q_seed: np.ndarray, tool: np.ndarray = TOOL_OFFSET) -> np.ndarray:
    """IK of a densely sampled path (N, 3), (N, 3, 3): the configuration branch of the solution nearest `q_seed`
    kept along the path, axes 4 and 6 unwrapped for continuity. Returns (N, 6)."""
    first = ik(p[:1], rot[:1], q_seed, tool)[0]
    sols, ok = ik_all(p, rot, tool)
    branch = int(np.argmin(np.where(ok[:, 0], np.nansum((_wrap(sols[:, 0] - first)) ** 2, -1), np.inf)))
    if not ok[branch].all():
        raise ValueError("path leaves the reach of the IRB 6640")
    q = np.unwrap(sols[branch], axis=0)
    return q + 2 * np.pi * np.round((first - q[0]) / (2 * np.pi))


def within_limits(q: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """(N,) bool: configurations q (N, 6) inside the datasheet axis ranges shrunk by `margin` rad."""
    return np.all((q >= POS_LIMITS[:, 0] + margin) & (q <= POS_LIMITS[:, 1] - margin), axis=-1)
