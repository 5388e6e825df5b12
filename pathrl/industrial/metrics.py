"""Error and speed metrics of an executed TCP path against the target curve, and the paper's specs.

Position error of an executed sample = its distance to the nearest point of the target curve (the target
polyline, projected onto its nearest segments, so the error is not quantised by the target's sampling).
Orientation error = angle between the executed tool z axis and the target's at that nearest point (the paper
measures the tool z axis; rotation about it is free). Speed = |p_j - p_{j-1}| / dt over the samples whose
nearest target point lies strictly inside the curve (the samples at rest on its ends are not part of the
traversal) and outside the first and last ``trim`` share (default 5 %) of the curve's length: the paper
reports speed deviations of a fraction of a percent on easy curves, which excludes starting from and braking
to rest; a longer ramp (high speed command) still reaches into the measured part.
Specs (paper Sec. II-C): max position error <= 0.5 mm, orientation <= 3 deg, speed standard deviation <= 5 %
of the mean.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = [
    "Errors", "POS_SPEC_MM", "SPEED_TRIM", "evaluate", "orientation_errors", "position_errors", "project",
    "speed_stats",
]

POS_SPEC_MM = 0.5
ORI_SPEC_DEG = 3.0
SPEED_STD_SPEC = 0.05
#: Share of the curve length at each end left out of the speed statistics.
SPEED_TRIM = 0.05


@dataclass(frozen=True)
class Errors:
    """Metrics of one execution (mm, deg, mm/s)."""

    max_pos_mm: float
    mean_pos_mm: float
    max_ori_deg: float
    mean_speed: float
    speed_std: float

    @property
    def speed_std_ratio(self) -> float:
        """Speed standard deviation over mean speed (inf if the mean is 0)."""
        return self.speed_std / self.mean_speed if self.mean_speed > 0 else float("inf")

    def meets_specs(self) -> bool:
        """True if position (mm), orientation (deg) and speed-spread errors are all within spec."""
        return (self.max_pos_mm <= POS_SPEC_MM and self.max_ori_deg <= ORI_SPEC_DEG
                and self.speed_std_ratio <= SPEED_STD_SPEC)

    def as_dict(self) -> dict[str, float]:
        """The errors as a dict, with ``speed_std_ratio``."""
        return {**asdict(self), "speed_std_ratio": self.speed_std_ratio}


def project(points: np.ndarray, curve: np.ndarray, tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Nearest points of the polyline `curve` (n, 3) to `points` (N, 3): distances (N,) and fractional curve
    indices (N,) in [0, n - 1]. Searches the segments next to the nearest vertex."""
    tree = cKDTree(curve) if tree is None else tree
    _, idx = tree.query(points)
    best_d = np.full(len(points), np.inf)
    best_u = np.zeros(len(points))
    for off in (-1, 0):  # the segment before and after the nearest vertex
        i0 = np.clip(idx + off, 0, len(curve) - 2)
        a, b = curve[i0], curve[i0 + 1]
        ab = b - a
        t = np.clip(np.einsum("ij,ij->i", points - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18), 0, 1)
        d = np.linalg.norm(points - (a + t[:, None] * ab), axis=1)
        better = d < best_d
        best_d = np.where(better, d, best_d)
        best_u = np.where(better, i0 + t, best_u)
    return best_d, best_u


def position_errors(p: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample position error (N,) mm of executed positions p (N, 3) and their fractional target index."""
    return project(p, target)


def orientation_errors(z_exec: np.ndarray, z_target: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Angle (N,) deg between executed tool z axes (N, 3) and the target's (n, 3) at fractional indices u."""
    i0 = np.clip(np.floor(u).astype(int), 0, len(z_target) - 2)
    f = (u - i0)[:, None]
    zt = (1 - f) * z_target[i0] + f * z_target[i0 + 1]
    zt /= np.linalg.norm(zt, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", z_exec, zt), -1.0, 1.0)))


def speed_stats(p: np.ndarray, dt: float, u: np.ndarray, n_target: int,
                trim: float = SPEED_TRIM) -> tuple[float, float]:
    """Mean and standard deviation (mm/s) of the TCP speed over the samples whose fractional target index u lies
    inside the target (n_target points, uniform in arc length) without its first and last `trim` share."""
    lo = max(trim * (n_target - 1), 1e-6)
    inside = (u > lo) & (u < n_target - 1 - lo)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / dt
    sel = speed[inside[1:] & inside[:-1]]
    if len(sel) < 2:
        return 0.0, 0.0
    return float(np.mean(sel)), float(np.std(sel))


def evaluate(p: np.ndarray, rot: np.ndarray, dt: float, target_p: np.ndarray, target_z: np.ndarray,
             trim: float = SPEED_TRIM) -> Errors:
    """All metrics of an execution (p (N, 3) mm, rot (N, 3, 3), sample time dt s) against a target curve
    (positions (n, 3) mm, tool z axes (n, 3))."""
    d, u = position_errors(p, target_p)
    ori = orientation_errors(rot[:, :, 2], target_z, u)
    mean_v, std_v = speed_stats(p, dt, u, len(target_p), trim)
    return Errors(float(d.max()), float(d.mean()), float(ori.max()), mean_v, std_v)
