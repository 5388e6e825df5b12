"""The recorded ABB program used to calibrate the controller model ("curve 1" of
``../shared/reference/abb_irb6640_recorded.md``) and the figures RobotStudio executed it with.

Curve 1 in its own frame (mm): x = t, y = 30 sin(0.54 deg t^2 / 1000), z = (R^2 - y^2) H / R^2 (R = 50.8,
H = 25.4), t in [0, 1000], the tool z axis on the inward normal -(0, 2 H y / R^2, 1); 50 001 points uniform in
arc length, placed in the base frame by the reference's 4 x 4 pose. The tool: TCP (75, 0, 493.301) mm in tool0,
rotated Ry(30 deg). The TCP x axis is not given by the reference; it is taken from the forward kinematics of the
recorded start configuration and carried along the curve orthogonal to the normal (minimal rotation).
The program: 101 breakpoints every 1 % of arc length, the first and last moved 100 mm outward along their
segment (orientation extrapolated on the same rotation), MoveL z10 at the speed command.
Measurement (:func:`measure`): only the pass over the curve (samples whose nearest target point is strictly
inside it); speed over the middle 90 % of the arc length; time over the curve from entering to leaving it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from pathrl.industrial import arm
from pathrl.industrial.controller import Execution
from pathrl.industrial.metrics import project
from pathrl.industrial.program import Program
from pathrl.industrial.trajectories import Target

__all__ = ["RECORDED", "START_Q", "TOOL", "Measured", "curve1", "curve1_program", "curve1_target", "measure"]

#: Pose of the curve frame in the base frame (rows of the reference's 4 x 4 transform; mm).
POSE = np.array([[-0.008281240596627095, -0.9895715673738508, 0.14380380418973931, 1086.5085970910013],
                 [0.9999617720243631, -0.007791538934054126, 0.00396817476110772, -506.8233271810492],
                 [-0.0028063399787532726, 0.14383116827134246, 0.9895982616646132, 968.910804375142]])
#: Recorded joint configuration at the curve start (rad).
START_Q = np.array([-0.58589046, -0.03341733, 0.40482559, -2.79157683, -1.61501501, 0.95669868])
#: The recording's tool: TCP in tool0 (mm), rotated Ry(30 deg).
TOOL = arm.Tool(np.array([75.0, 0.0, 493.301]), Rotation.from_euler("y", 30.0, degrees=True).as_matrix())
R_CYL, H_CYL = 50.8, 25.4

#: What RobotStudio executed: speed command -> (max error mm, mean error mm, max orientation error deg, mean
#: speed mm/s, speed std % of mean, time over the curve s or None).
RECORDED: dict[float, tuple[float, float, float, float, float, float | None]] = {
    123.05: (0.483, 0.113, 0.19, 124.0, 0.23, 8.284),
    300.0: (1.61, 0.46, 0.35, 288.0, 9.1, None),
}
#: Recorded rest-to-95 % time (s) and where the max error sits (share of the arc length).
RECORDED_RAMP_S = (0.10, 0.12)
RECORDED_MAX_AT = (820.0 / 1027.735, 1.0)


def _raw(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Curve 1 in its frame, densely in t: positions (n, 3) and unit inward normals (n, 3)."""
    t = np.linspace(0.0, 1000.0, n)
    y = 30.0 * np.sin(np.radians(0.54) * t**2 / 1000.0)
    z = (R_CYL**2 - y**2) * H_CYL / R_CYL**2
    nrm = -np.stack([np.zeros_like(t), 2 * H_CYL * y / R_CYL**2, np.ones_like(t)], axis=1)
    return np.stack([t, y, z], axis=1), nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


@lru_cache(maxsize=1)
def curve1(n: int = 50001) -> tuple[np.ndarray, np.ndarray]:
    """Curve 1 in the base frame, n points uniform in arc length: positions (n, 3) mm, TCP rotations (n, 3, 3)."""
    p, nrm = _raw(400001)
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    su = np.linspace(0.0, s[-1], n)
    p = np.stack([np.interp(su, s, p[:, j]) for j in range(3)], axis=1)
    nrm = np.stack([np.interp(su, s, nrm[:, j]) for j in range(3)], axis=1)
    rot_b, off = POSE[:, :3], POSE[:, 3]
    p, z = p @ rot_b.T + off, nrm @ rot_b.T
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    _, r0 = arm.fk(START_Q[None], TOOL.offset)
    x = (r0[0] @ TOOL.rot)[:, 0]
    xs = np.empty_like(z)
    for i in range(n):  # carry x along, orthogonal to z (minimal rotation)
        x = x - (x @ z[i]) * z[i]
        x /= np.linalg.norm(x)
        xs[i] = x
    return p, np.stack([xs, np.cross(z, xs), z], axis=2)


def curve1_target(speed: float = 123.05) -> Target:
    """Curve 1 as a :class:`Target` (dense, 50 001 points)."""
    p, rot = curve1()
    return Target("Curve 1 (recorded)", p, rot, 0, "L", speed)


def curve1_program(zone: float = 10.0) -> Program:
    """The recorded program: 101 breakpoints, ends moved 100 mm outward, MoveL with `zone`, the recording's tool
    and start configuration."""
    p, rot = curve1()
    idx = np.arange(0, len(p), 500)
    pos, rots = p[idx].copy(), rot[idx].copy()
    for end, nxt in ((0, 1), (-1, -2)):
        seg = pos[end] - pos[nxt]
        length = np.linalg.norm(seg)
        step = Rotation.from_matrix(rots[nxt]).inv() * Rotation.from_matrix(rots[end])
        pos[end] = pos[end] + 100.0 * seg / length
        rots[end] = (Rotation.from_matrix(rots[end]) * Rotation.from_rotvec(step.as_rotvec() * 100.0 / length)
                     ).as_matrix()
    return Program(pos, rots, "L", zone, START_Q.copy(), TOOL)


@dataclass(frozen=True)
class Measured:
    """Figures of one execution of curve 1, as the reference reports them (mm, deg, mm/s, %, s); where the max
    error sits (share of the arc length) and the rest-to-95 % time of the start (s)."""

    max_err: float
    mean_err: float
    max_ori: float
    mean_speed: float
    speed_std_pct: float
    time_over: float
    max_at: float
    ramp95_s: float


@lru_cache(maxsize=1)
def _tree() -> cKDTree:
    return cKDTree(curve1()[0])


def measure(ex: Execution, v: float) -> Measured:
    """The reference's figures of an execution of :func:`curve1_program` at command `v` mm/s (module doc)."""
    p_t, rot_t = curve1()
    n = len(p_t)
    d, u = project(ex.p, p_t, _tree())
    inside = (u > 1e-6) & (u < n - 1 - 1e-6)
    i0 = np.clip(np.floor(u).astype(int), 0, n - 2)
    f = (u - i0)[:, None]
    zt = (1 - f) * rot_t[i0, :, 2] + f * rot_t[i0 + 1, :, 2]
    zt /= np.linalg.norm(zt, axis=1, keepdims=True)
    ori = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", ex.rot[:, :, 2], zt), -1.0, 1.0)))
    dt = ex.t[1] - ex.t[0]
    speed = np.r_[0.0, np.linalg.norm(np.diff(ex.p, axis=0), axis=1) / dt]
    mid = (u > 0.05 * (n - 1)) & (u < 0.95 * (n - 1))
    times = ex.t[inside]
    moving = np.nonzero(speed > 0.01 * v)[0]
    t0 = ex.t[moving[0]] if len(moving) else 0.0
    fast = np.nonzero(speed >= 0.95 * v)[0]
    ramp = float(ex.t[fast[0]] - t0) if len(fast) else float("inf")
    j = int(np.argmax(np.where(inside, d, -1.0)))
    return Measured(float(d[inside].max()), float(d[inside].mean()), float(ori[inside].max()),
                    float(speed[mid].mean()), float(100 * speed[mid].std() / speed[mid].mean()),
                    float(times[-1] - times[0]), float(u[j] / (n - 1)), ramp)
