"""Local features, actions and rewards of the learned waypoint adjustment (paper Sec. IV-B, eqs. 7-18).

Everything is per waypoint and vectorised over the m waypoints. The executed path is matched to the target by
nearest points: for every target point j, p_exe(j) is the nearest point of the executed polyline and the error
vector is e(j) = p_trk(j) - p_exe(j) (its norm is the distance of the target point to the executed path).

Local region of waypoint i: target indices [psi_{i-1}, psi_{i+1}] ([psi_1, psi_2] for the first,
[psi_{m-1}, psi_m] for the last), resampled to 50 points. The feature vector (313 values):

* eq. 7: the 50 local error vectors divided by |e^i| (e^i = e(psi_i), eq. 10), 150 values;
* eq. 8: the 50 local target points in their principal axes (PCA, centred, signs fixed: axis 1 from start to
  end, axis 2 towards the middle point, axis 3 = axis 1 x axis 2), divided by the chord length, 150 values;
* eq. 9: the waypoint's joint configuration q^i (rad), 6 values;
* eq. 10: e^i (mm), 3 values;
* eq. 11: F_jac = |J(q^i)^-1 [e^i, 0]| in rad per m of error (the paper's heuristic scale), 1 value;
* eq. 12: the waypoint's position in its region, 1 value; eq. 13: first / last flags, 2 values.

Features are clipped to [-10, 10] (the normalised error trajectory explodes where |e^i| is tiny). Action
(eq. 14): a^i in [-1, 1]^3 moves the waypoint by |e^i| (a_1 eta_1 + a_2 eta_2 + a_3 eta_3), eta_1 along e^i,
eta_2 towards the previous waypoint (away from the next for the first), eta_3 = eta_1 x eta_2 (normalised).
Rewards (eqs. 15-18) compare the local maximum position / orientation error with the previous iteration,
relative to iteration 0; the paper prints the difference as (new - old), we reward the improvement
(old - new), which is what the text describes. Failure (local max > 5 mm) -100, success (< 0.25 mm) +10.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pathrl.industrial import arm
from pathrl.industrial.metrics import project

__all__ = [
    "FAIL_MM", "Matched", "N_FEATURES", "SLICES", "SUCCESS_MM", "action_steps", "f_jac", "features", "local",
    "local_max", "match", "pca_shape", "regions", "rewards",
]

LOCAL_POINTS = 50
N_FEATURES = 313
FAIL_MM = 5.0
SUCCESS_MM = 0.25
FEATURE_CLIP = 10.0
#: Feature slices by name (for ablations: the paper's -P_target, -q/F_jac, -e).
SLICES = {"p_error": slice(0, 150), "p_target": slice(150, 300), "q": slice(300, 306), "e": slice(306, 309),
          "f_jac": slice(309, 310), "f_position": slice(310, 311), "f_flag": slice(311, 313)}


@dataclass(frozen=True)
class Matched:
    """The execution matched to the target: error vectors e (n, 3) mm and orientation errors (n,) deg."""

    err: np.ndarray
    ori_deg: np.ndarray


def match(target_p: np.ndarray, target_z: np.ndarray, exec_p: np.ndarray, exec_z: np.ndarray) -> Matched:
    """Nearest executed point (and its tool z axis) for every target point."""
    _, u = project(target_p, exec_p)
    i0 = np.clip(np.floor(u).astype(int), 0, len(exec_p) - 2)
    f = (u - i0)[:, None]
    p = (1 - f) * exec_p[i0] + f * exec_p[i0 + 1]
    z = (1 - f) * exec_z[i0] + f * exec_z[i0 + 1]
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    ori = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", z, target_z), -1.0, 1.0)))
    return Matched(target_p - p, ori)


def regions(psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local region bounds (m,), (m,) (target indices) of waypoints at target indices psi (m,)."""
    psi = psi.astype(float)
    lo = np.r_[psi[0], psi[:-2], psi[-2]]
    hi = np.r_[psi[1], psi[2:], psi[-1]]
    return lo, hi


def local(values: np.ndarray, lo: np.ndarray, hi: np.ndarray, k: int = LOCAL_POINTS) -> np.ndarray:
    """`values` (n, d) linearly interpolated at k points spread over each region: (m, k, d)."""
    u = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, k)
    i0 = np.clip(np.floor(u).astype(int), 0, len(values) - 2)
    f = (u - i0)[..., None]
    return (1 - f) * values[i0] + f * values[i0 + 1]


def pca_shape(points: np.ndarray) -> np.ndarray:
    """Local target shapes (m, k, 3) in their principal axes, divided by the chord length (eq. 8)."""
    centred = points - points.mean(axis=1, keepdims=True)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    a1, a2 = vt[:, 0], vt[:, 1]
    chord = points[:, -1] - points[:, 0]
    a1 = a1 * np.where(np.einsum("ij,ij->i", a1, chord) < 0, -1.0, 1.0)[:, None]
    mid = points[:, points.shape[1] // 2] - 0.5 * (points[:, 0] + points[:, -1])
    a2 = a2 * np.where(np.einsum("ij,ij->i", a2, mid) < 0, -1.0, 1.0)[:, None]
    axes = np.stack([a1, a2, np.cross(a1, a2)], axis=1)  # (m, 3, 3), rows are axes
    scale = np.maximum(np.linalg.norm(chord, axis=1), 1e-9)[:, None, None]
    return np.einsum("mkj,maj->mka", centred, axes) / scale


def f_jac(q: np.ndarray, e: np.ndarray) -> np.ndarray:
    """|J(q)^-1 [e, 0]| (m,) in rad per m of error (eq. 11), by least squares (robust near singularities)."""
    jac = arm.jacobian(q)
    rhs = np.concatenate([e, np.zeros_like(e)], axis=1)[..., None]
    x = np.linalg.pinv(jac, rcond=1e-6) @ rhs
    return np.linalg.norm(x[..., 0], axis=1) * 1000.0


def features(target_p: np.ndarray, psi: np.ndarray, matched: Matched, q_wp: np.ndarray) -> np.ndarray:
    """The (m, 313) feature matrix (module doc) of waypoints at target indices psi with joint configurations
    q_wp (m, 6)."""
    m = len(psi)
    lo, hi = regions(psi)
    e = matched.err[psi]
    e_norm = np.maximum(np.linalg.norm(e, axis=1), 1e-6)
    p_err = local(matched.err, lo, hi) / e_norm[:, None, None]
    p_tgt = pca_shape(local(target_p, lo, hi))
    pos = (psi - lo) / np.maximum(hi - lo, 1e-9)
    flags = np.zeros((m, 2))
    flags[0, 0] = flags[-1, 1] = 1.0
    out = np.concatenate([p_err.reshape(m, -1), p_tgt.reshape(m, -1), q_wp, e, f_jac(q_wp, e)[:, None],
                          pos[:, None], flags], axis=1)
    return np.clip(out, -FEATURE_CLIP, FEATURE_CLIP)


def local_max(matched: Matched, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Maximum position error (m,) mm and orientation error (m,) deg in each waypoint's region."""
    lo, hi = regions(psi)
    pos = local(np.linalg.norm(matched.err, axis=1)[:, None], lo, hi)[..., 0].max(axis=1)
    ori = local(matched.ori_deg[:, None], lo, hi)[..., 0].max(axis=1)
    return pos, ori


def action_steps(actions: np.ndarray, positions: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Waypoint moves (m, 3) mm of actions (m, 3) in the error / previous-waypoint / cross frame (eq. 14)."""
    norm = np.linalg.norm(e, axis=1, keepdims=True)
    eta1 = e / np.maximum(norm, 1e-9)
    prev = np.r_[2 * positions[:1] - positions[1:2], positions[:-1]]  # the first: away from the next
    eta2 = prev - positions
    eta2 /= np.maximum(np.linalg.norm(eta2, axis=1, keepdims=True), 1e-9)
    eta3 = np.cross(eta1, eta2)
    eta3 /= np.maximum(np.linalg.norm(eta3, axis=1, keepdims=True), 1e-9)
    return (actions[:, :1] * eta1 + actions[:, 1:2] * eta2 + actions[:, 2:3] * eta3) * norm


def rewards(pos: np.ndarray, ori: np.ndarray, prev_pos: np.ndarray, prev_ori: np.ndarray, pos0: np.ndarray,
            ori0: np.ndarray, w_ori: float = 1.0, w_success: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Per-waypoint rewards (m,) and local termination flags (m,) (eqs. 15-18): position improvement, `w_ori` x
    orientation improvement, -100 on failure, `w_success` x 10 on success (the paper: w_ori = 0.5 and
    w_success = 0.8^k at iteration k)."""
    r_p = np.clip((prev_pos - pos) / np.maximum(pos0, 1e-6), -10, 10)
    r_b = np.clip((prev_ori - ori) / np.maximum(ori0, 1e-6), -10, 10)
    fail, success = pos > FAIL_MM, pos < SUCCESS_MM
    return r_p + w_ori * r_b - 100.0 * fail + 10.0 * w_success * success, fail | success
