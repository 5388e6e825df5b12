"""Motion programs (MoveL / MoveJ waypoints with a blend zone) and the geometric path a controller makes of them.

A :class:`Program` is m waypoints (TCP positions in mm, tool rotations) reached one after the other by the same
primitive, MoveL (TCP position linear, orientation slerped) or MoveJ (joints linear), with one zone radius
(``z10`` = 10 mm) at every interior waypoint; the first and last are fine points.

Blending (:func:`sample_path`). At interior waypoint i the zone radius is r_i = min(zone, L_{i-1}/2, L_i/2)
(L the segment lengths; a controller shrinks the zone on short segments the same way). The path leaves the
straight segment r_i before the waypoint and rejoins the next one r_i after it, along the quadratic Bezier
(a parabola) with control points (P_i - r_i u_{i-1}, P_i, P_i + r_i u_i): tangent to both segments at the
joins, it passes at distance r_i sin(theta/2) / 2 from the waypoint (theta the turning angle), which bounds
the corner cut. The orientation inside a zone is the slerp of the unblended polyline at the matching
polyline arc position, so orientation is continuous. MoveJ blends the same way in joint space, the zone
being the fraction r_i / L of the segment's Cartesian length.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from pathrl.industrial import arm

__all__ = ["DEFAULT_SEED", "PathSamples", "Program", "blend_polyline", "sample_path", "zone_radii"]


@dataclass(frozen=True)
class Program:
    """m waypoints: positions (m, 3) mm, rotations (m, 3, 3); `move` "L" or "J"; `zone` mm; for MoveJ (and as
    the IK seed of MoveL) `q_seed` (6,) rad picks the arm configuration; `tool` is the TCP on the flange (None:
    :data:`pathrl.industrial.arm.DEFAULT_TOOL`; the calibrated controller model honours it)."""

    positions: np.ndarray
    rotations: np.ndarray
    move: str = "L"
    zone: float = 10.0
    q_seed: np.ndarray | None = None
    tool: arm.Tool | None = None

    def __post_init__(self) -> None:
        m = len(self.positions)
        if m < 2 or self.positions.shape != (m, 3) or self.rotations.shape != (m, 3, 3):
            raise ValueError(f"a program needs >= 2 waypoints (m, 3) and (m, 3, 3); got {self.positions.shape}")
        if self.move not in ("L", "J"):
            raise ValueError(f"move must be 'L' or 'J', got {self.move!r}")
        if not self.zone >= 0.0:
            raise ValueError(f"zone must be >= 0 mm, got {self.zone}")

    def with_positions(self, positions: np.ndarray) -> Program:
        """The same program with moved waypoints (rotations kept, as in the paper's waypoint adjustment)."""
        return Program(np.asarray(positions, dtype=np.float64), self.rotations, self.move, self.zone, self.q_seed,
                       self.tool)


@dataclass(frozen=True)
class PathSamples:
    """A densely sampled commanded path: joint configurations q (K, 6), TCP positions p (K, 3) mm and the TCP
    arc length s (K,) mm."""

    q: np.ndarray
    p: np.ndarray
    s: np.ndarray


def zone_radii(points: np.ndarray, zone: float) -> np.ndarray:
    """Effective zone radius (m,) at each waypoint of a polyline `points` (m, 3): 0 at the ends, else
    min(zone, half of each adjacent segment)."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    r = np.zeros(len(points))
    r[1:-1] = np.minimum(zone, 0.5 * np.minimum(seg[:-1], seg[1:]))
    return r


def blend_polyline(points: np.ndarray, radii: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample the polyline `points` (m, d) with quadratic-Bezier corners of `radii` (m,) at about `step` spacing.

    Returns the samples (K, d) and each sample's position along the unblended polyline (K,), in the polyline's
    own length units (used to slerp orientations and to map MoveJ zones)."""
    seg = np.diff(points, axis=0)
    length = np.linalg.norm(seg, axis=1)
    if np.any(length <= 0.0):
        raise ValueError("two consecutive waypoints coincide")
    unit = seg / length[:, None]
    cum = np.r_[0.0, np.cumsum(length)]
    pieces, params = [], []
    for k in range(len(seg)):
        a, b = radii[k], length[k] - radii[k + 1]  # straight part of segment k, in its own arc length
        n = max(int(np.ceil((b - a) / step)), 1)
        u = np.linspace(a, b, n + 1)[:-1] if k < len(seg) - 1 else np.linspace(a, b, n + 1)
        pieces.append(points[k] + u[:, None] * unit[k])
        params.append(cum[k] + u)
        r = radii[k + 1]
        if k < len(seg) - 1 and r > 0.0:
            n = max(int(np.ceil(2.0 * r / step)), 2)
            t = np.linspace(0.0, 1.0, n + 1)[:-1, None]
            c0, c1, c2 = points[k + 1] - r * unit[k], points[k + 1], points[k + 1] + r * unit[k + 1]
            pieces.append((1 - t) ** 2 * c0 + 2 * (1 - t) * t * c1 + t**2 * c2)
            params.append(cum[k + 1] - r + 2.0 * r * t[:, 0])
    return np.concatenate(pieces), np.concatenate(params)


def _arc_length(p: np.ndarray) -> np.ndarray:
    return np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]


def _uniform(q: np.ndarray, p: np.ndarray, step: float) -> PathSamples:
    """Resample joints (K, 6) and TCP positions (K, 3) uniformly in TCP arc length at ~`step` mm (the blend
    pieces meet at nearly coincident samples; a uniform grid keeps the path derivatives well conditioned)."""
    s = _arc_length(p)
    keep = np.r_[True, np.diff(s) > 1e-6]
    q, p, s = q[keep], p[keep], s[keep]
    su = np.linspace(0.0, s[-1], max(int(np.ceil(s[-1] / step)), 2) + 1)
    qu = np.stack([np.interp(su, s, q[:, j]) for j in range(q.shape[1])], axis=1)
    pu = np.stack([np.interp(su, s, p[:, j]) for j in range(3)], axis=1)
    return PathSamples(qu, pu, su)


def sample_path(program: Program, step: float = 0.5) -> PathSamples:
    """The commanded, blended path of `program` as joint configurations every ~`step` mm of TCP arc length."""
    seed = arm.ik(program.positions[:1], program.rotations[:1], _seed(program))[0]
    if program.move == "L":
        radii = zone_radii(program.positions, program.zone)
        p, u = blend_polyline(program.positions, radii, step)
        cum = _arc_length(program.positions)
        rot = Slerp(cum, Rotation.from_matrix(program.rotations))(np.clip(u, 0.0, cum[-1])).as_matrix()
        q = arm.ik_path(p, rot, seed)
        return _uniform(q, p, step)
    qw = _ik_waypoints(program, seed)
    cart = np.linalg.norm(np.diff(program.positions, axis=0), axis=1)
    radii = zone_radii(program.positions, program.zone)
    joint_len = np.linalg.norm(np.diff(qw, axis=0), axis=1)
    frac = np.zeros(len(qw))
    frac[1:-1] = radii[1:-1] / np.maximum(np.minimum(cart[:-1], cart[1:]), 1e-9)
    jr = frac * np.r_[0.0, np.minimum(joint_len[:-1], joint_len[1:]), 0.0]
    jstep = step * np.sum(joint_len) / max(np.sum(cart), 1e-9)
    q, _ = blend_polyline(qw, jr, max(jstep, 1e-6))
    p, _ = arm.fk(q)
    return _uniform(q, p, step)


def _seed(program: Program) -> np.ndarray:
    return DEFAULT_SEED if program.q_seed is None else np.asarray(program.q_seed, dtype=np.float64)


def _ik_waypoints(program: Program, seed: np.ndarray) -> np.ndarray:
    """Joint waypoints of a MoveJ program: IK of each waypoint on the seed's branch, unwrapped in sequence."""
    return arm.ik_path(program.positions, program.rotations, seed)


#: Default IK seed: elbow up, shoulder front, wrist not flipped (tool pointing down in front of the robot).
DEFAULT_SEED = np.array([0.0, 0.3, 0.0, 0.0, 1.0, 0.0])
