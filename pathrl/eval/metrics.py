"""Per-episode tracking metrics as in the paper: the executed path vs the reference at equal arc length.

The executed path is the polyline through all control-rate setpoints of an episode (path joints). It
is resampled every `sample_step` rad of its own arc length (first sample dropped, as the authors did);
sample k at arc length s_k is compared with the reference at start_s + s_k (the end knot beyond the
segment end). Joint deviation: unweighted Euclidean norm (rad). Cartesian: TCP position distance (cm)
and orientation angle (deg) via forward kinematics; mean and max over samples and TCPs, final = the
last sample averaged over TCPs.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from pathrl.paths.pathset import PathSet
from pathrl.robot.kinematics import ForwardKinematics, quat_angle_deg

__all__ = ["METRIC_KEYS", "episode_deviation", "episode_deviations", "resample_polyline"]


METRIC_KEYS = (
    "joint_dev_mean_rad", "joint_dev_max_rad", "joint_dev_final_rad",
    "cart_pos_dev_mean_cm", "cart_pos_dev_max_cm", "cart_pos_dev_final_cm",
    "cart_rot_dev_mean_deg", "cart_rot_dev_max_deg", "cart_rot_dev_final_deg",
)


def resample_polyline(points: Tensor, step: float) -> tuple[Tensor, Tensor]:
    """Points (T, M) of a polyline resampled at arc lengths step, 2 step, ..., plus its end.

    Returns (samples (K, M), their arc lengths (K,)). A path that never moves gives its end point at 0.
    """
    seg = (points[1:] - points[:-1]).norm(dim=1)
    cum = torch.cat([points.new_zeros(1), seg.cumsum(0)])
    total = float(cum[-1])
    if total < step:
        return points[-1:], cum[-1:]
    s = torch.arange(1, int(total / step) + 1, dtype=points.dtype, device=points.device) * step
    if total - float(s[-1]) > 1e-9:
        s = torch.cat([s, cum[-1:]])
    i = torch.searchsorted(cum, s, right=True).clamp(1, len(cum) - 1)
    c0, c1 = cum[i - 1], cum[i]
    w = ((s - c0) / (c1 - c0).clamp(min=1e-15)).unsqueeze(1)
    return points[i - 1] + w * (points[i] - points[i - 1]), s


def episode_deviation(
    setpoints: Tensor,
    path_index: Tensor,
    paths: PathSet,
    path: int,
    start_s: float,
    end_s: float,
    fk: ForwardKinematics,
    sample_step: float = 0.01,
) -> dict[str, float]:
    """Deviation metrics of one episode. `setpoints`: (T, D) commanded positions incl. the start."""
    return episode_deviations([setpoints], path_index, paths, [path], [start_s], [end_s], fk, sample_step)[0]


def episode_deviations(
    setpoints: Sequence[Tensor],
    path_index: Tensor,
    paths: PathSet,
    path: Sequence[int],
    start_s: Sequence[float],
    end_s: Sequence[float],
    fk: ForwardKinematics,
    sample_step: float = 0.01,
) -> list[dict[str, float]]:
    """:func:`episode_deviation` of many episodes (setpoints (T_i, D) each), with one batched FK pass."""
    joint, full_exec, full_ref = [], [], []
    for q, p, s0, s1 in zip(setpoints, path, start_s, end_s, strict=True):
        q_all = q.to(torch.float64)
        q_exec, s = resample_polyline(q_all[:, path_index], sample_step)
        s_ref = torch.clamp(s0 + s, max=s1)
        idx = torch.full((len(s),), p, dtype=torch.long, device=paths.device)
        q_ref = paths.position_at(idx, s_ref.to(paths.device)).to(q_exec)
        joint.append((q_exec - q_ref).norm(dim=1))
        # Full-robot configurations for FK: non-path joints (e.g. legs) as executed at the last setpoint.
        full_exec.append(_embed(q_exec, q_all, path_index))
        full_ref.append(_embed(q_ref, q_all, path_index))
    out = []
    for j, (p_e, r_e), (p_r, r_r) in zip(joint, fk.tcp_poses_of(full_exec), fk.tcp_poses_of(full_ref), strict=True):
        pos = (p_e - p_r).norm(dim=2) * 100.0  # (K, T) cm
        rot = quat_angle_deg(r_e, r_r)  # (K, T)
        out.append({
            "joint_dev_mean_rad": float(j.mean()),
            "joint_dev_max_rad": float(j.max()),
            "joint_dev_final_rad": float(j[-1]),
            "cart_pos_dev_mean_cm": float(pos.mean()),
            "cart_pos_dev_max_cm": float(pos.max()),
            "cart_pos_dev_final_cm": float(pos[-1].mean()),
            "cart_rot_dev_mean_deg": float(rot.mean()),
            "cart_rot_dev_max_deg": float(rot.max()),
            "cart_rot_dev_final_deg": float(rot[-1].mean()),
        })
    return out


def _embed(q_path: Tensor, q_all: Tensor, path_index: Tensor) -> Tensor:
    """(K, M) path-joint samples -> (K, D) configurations; other joints from the last setpoint."""
    full = q_all[-1].expand(q_path.shape[0], -1).clone()
    full[:, path_index] = q_path
    return full
