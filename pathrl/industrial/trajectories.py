"""Target TCP trajectories of the motion-profile task and the 100-MoveL baseline profile.

Type 1 (paper Fig. 3): a multi-frequency sine on a parabolic surface. In the curve frame the path runs along
x over ``length`` mm, y(x) = sum_k A_k sin(2 pi f_k (x / length + 1/2) + phi_k) (f_k in periods per length),
and z lies on the bowl z = (x^2 + y^2) / (2 R). The tool z axis points into the surface (minus the normal),
the tool x axis is the curve frame's x projected orthogonal to it (a smooth, fixed-direction choice, so the
wrist does not spin with the sine). :func:`type1_random` draws the training family from a seed;
:data:`TYPE1_MEMBERS` are the evaluation members (easy / standard / medium / hard by peak curvature; the
paper's "standard" is slightly below medium).

Type 2 (paper Fig. 4): a blade-leading-edge-like curve: 1000 mm span, a 60 mm bow and an 80 mm sweep, the tool
normal to the edge and twisting by 30 deg along it. It is never in training.

Poses (:data:`POSES`) place the curve frame in the IRB 6640's base frame (mm); all members are reachable
within the axis ranges in all poses. A :class:`Target` is the curve resampled uniformly in arc length.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from pathrl.industrial.program import Program

__all__ = [
    "EVALUATION", "POSES", "SineParams", "TYPE1_MEMBERS", "Target", "baseline_program", "evaluation_targets",
    "resample", "type1", "type1_random", "type2", "waypoint_indices",
]

#: Curve-frame placements: (origin mm, rotation as xyz Euler angles deg).
POSES: dict[int, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    1: ((1800.0, 0.0, 700.0), (0.0, 0.0, 0.0)),
    2: ((1500.0, -300.0, 900.0), (0.0, 0.0, 60.0)),
    3: ((1700.0, 250.0, 1000.0), (0.0, 25.0, -20.0)),
    4: ((1600.0, -200.0, 1200.0), (20.0, 0.0, 30.0)),
}


@dataclass(frozen=True)
class SineParams:
    """Type-1 shape: amplitudes (mm), frequencies (periods per length), phases (rad), length mm, bowl radius mm."""

    amps: tuple[float, ...]
    freqs: tuple[float, ...]
    phases: tuple[float, ...]
    length: float = 800.0
    bowl_radius: float = 1500.0


#: Evaluation members of type 1 (by peak curvature: easy < standard < medium < hard).
TYPE1_MEMBERS: dict[str, SineParams] = {
    "easy": SineParams((45.0, 0.0, 0.0), (1.5, 2.0, 3.0), (0.0, 0.0, 0.0)),
    "standard": SineParams((45.0, 10.0, 0.0), (1.5, 4.0, 6.0), (0.0, 0.5, 0.0)),
    "medium": SineParams((45.0, 12.0, 4.0), (1.5, 4.0, 7.0), (0.0, 0.5, 1.0)),
    "hard": SineParams((50.0, 15.0, 6.0), (2.0, 5.0, 9.0), (0.0, 0.5, 1.0)),
}


@dataclass(frozen=True)
class Target:
    """A target curve: positions p (n, 3) mm, tool rotations rot (n, 3, 3); its name, pose, primitive and the
    speed command (mm/s) the evaluation runs it at."""

    name: str
    p: np.ndarray
    rot: np.ndarray
    pose: int = 1
    move: str = "L"
    speed: float = 250.0

    @property
    def z_axis(self) -> np.ndarray:
        """Tool z axes (n, 3) along the target (third column of ``rot``)."""
        return self.rot[:, :, 2]


def _frame(pose: int) -> tuple[np.ndarray, np.ndarray]:
    if pose not in POSES:
        raise ValueError(f"unknown pose {pose}; known: {sorted(POSES)}")
    origin, euler = POSES[pose]
    return np.asarray(origin), Rotation.from_euler("xyz", euler, degrees=True).as_matrix()


def _tool_rotations(z_tool: np.ndarray, ref_x: np.ndarray) -> np.ndarray:
    """Tool frames (n, 3, 3) with given z axes (n, 3) and x axes = `ref_x` (3,) made orthogonal to z."""
    z = z_tool / np.linalg.norm(z_tool, axis=1, keepdims=True)
    x = ref_x - np.einsum("ij,j->i", z, ref_x)[:, None] * z
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    return np.stack([x, np.cross(z, x), z], axis=2)


def resample(p: np.ndarray, rot: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Resample a densely given curve (N, 3), (N, 3, 3) to n points uniform in arc length."""
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    su = np.linspace(0.0, s[-1], n)
    pu = np.stack([np.interp(su, s, p[:, j]) for j in range(3)], axis=1)
    z = np.stack([np.interp(su, s, rot[:, j, 2]) for j in range(3)], axis=1)
    x = np.stack([np.interp(su, s, rot[:, j, 0]) for j in range(3)], axis=1)
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x -= np.einsum("ij,ij->i", x, z)[:, None] * z
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    return pu, np.stack([x, np.cross(z, x), z], axis=2)


def _place(p: np.ndarray, rot: np.ndarray, pose: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    origin, frame = _frame(pose)
    return resample(p @ frame.T + origin, frame @ rot, n)


def type1(params: SineParams, pose: int = 1, n: int = 2000, dense: int = 8000) -> tuple[np.ndarray, np.ndarray]:
    """A type-1 curve in the base frame: positions (n, 3) mm and tool rotations (n, 3, 3)."""
    x = np.linspace(-params.length / 2, params.length / 2, dense)
    arg = 2 * np.pi * (x / params.length + 0.5)
    y = sum(a * np.sin(f * arg + ph) for a, f, ph in zip(params.amps, params.freqs, params.phases, strict=True))
    r = params.bowl_radius
    p = np.stack([x, y, (x**2 + y**2) / (2 * r)], axis=1)
    normal = np.stack([-x / r, -y / r, np.ones_like(x)], axis=1)
    return _place(p, _tool_rotations(-normal, np.array([1.0, 0.0, 0.0])), pose, n)


def type1_random(seed: int, pose: int = 1) -> SineParams:
    """A random member of the type-1 training family (three sine components, seeded)."""
    rng = np.random.default_rng(seed)
    freqs = (rng.uniform(1.0, 2.0), rng.uniform(3.0, 5.0), rng.uniform(6.0, 9.0))
    amps = (rng.uniform(25.0, 55.0), rng.uniform(0.0, 15.0), rng.uniform(0.0, 6.0))
    return SineParams(amps, freqs, tuple(rng.uniform(0.0, 2 * np.pi, 3)))


def type2(pose: int = 1, n: int = 2000, dense: int = 8000) -> tuple[np.ndarray, np.ndarray]:
    """The blade-leading-edge-like curve in the base frame: positions (n, 3) mm and tool rotations (n, 3, 3)."""
    u = np.linspace(0.0, 1.0, dense)
    p = np.stack([1000.0 * (u - 0.5), 60.0 * np.sin(np.pi * u) + 15.0 * np.sin(2 * np.pi * u), 80.0 * u**2], 1)
    tangent = np.gradient(p, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    twist = np.radians(30.0) * (u - 0.5)
    down = np.stack([np.zeros_like(u), np.sin(twist), -np.cos(twist)], axis=1)
    z = down - np.einsum("ij,ij->i", down, tangent)[:, None] * tangent
    return _place(p, _tool_rotations(z, np.array([1.0, 0.0, 0.0])), pose, n)


#: The paper's Table II rows: (row name, curve, pose, primitive, speed command of the simulation mm/s).
EVALUATION: tuple[tuple[str, str, int, str, float], ...] = (
    ("Type 1 Hard", "hard", 1, "L", 250.0),
    ("Type 1 Easy", "easy", 1, "L", 250.0),
    ("Type 1 Medium", "medium", 1, "L", 250.0),
    ("Type 1 (pose 1)", "standard", 1, "L", 250.0),
    ("Type 1 (pose 2)", "standard", 2, "L", 400.0),
    ("Type 1 (pose 3)", "standard", 3, "L", 400.0),
    ("Type 2 (pose 1)", "type2", 1, "L", 1100.0),
    ("Type 2 (pose 4)", "type2", 4, "L", 1100.0),
    ("Type 2 (MoveJ)", "type2", 1, "J", 1100.0),
)


def evaluation_targets() -> list[Target]:
    """The evaluation trajectories, in the order of the paper's Table II."""
    out = []
    for name, curve, pose, move, speed in EVALUATION:
        p, rot = type2(pose) if curve == "type2" else type1(TYPE1_MEMBERS[curve], pose)
        out.append(Target(name, p, rot, pose, move, speed))
    return out


def waypoint_indices(n_target: int, m: int = 100) -> np.ndarray:
    """Indices (m,) of m waypoints spread uniformly along a target of n_target arc-length-uniform points."""
    if m < 2 or m > n_target:
        raise ValueError(f"need 2 <= m <= {n_target} waypoints, got {m}")
    return np.round(np.linspace(0, n_target - 1, m)).astype(int)


def baseline_program(target: Target, m: int = 100, zone: float = 10.0) -> Program:
    """The paper's baseline profile: m waypoints sampled uniformly along the target, joined by the target's
    primitive (MoveL unless the target says MoveJ) with blend zone `zone` mm."""
    idx = waypoint_indices(len(target.p), m)
    return Program(target.p[idx].copy(), target.rot[idx].copy(), target.move, zone)
