"""Per-episode tracking metrics as in the paper: the executed path vs the reference at equal arc length.

The executed path is the polyline through all control-rate setpoints of an episode (path joints). It
is resampled every `sample_step` rad of its own arc length (first sample dropped, as the authors did);
sample k at arc length s_k is compared with the reference at start_s + s_k (the end knot beyond the
segment end). Joint deviation: unweighted Euclidean norm (rad). Cartesian: TCP position distance (cm)
and orientation angle (deg) via forward kinematics; mean and max over samples and TCPs, final = the
last sample averaged over TCPs. Per joint (:func:`per_joint_errors`, pooled over all samples of all
episodes): the mean signed error (commanded minus reference), its RMS and the joint's share of the squared
joint deviation, which show constant offsets that the norms above hide.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from pathrl.paths.pathset import PathSet
from pathrl.robot.kinematics import ForwardKinematics, quat_angle_deg

__all__ = ["METRIC_KEYS", "episode_deviation", "episode_deviations", "matched_samples", "offset_joints",
           "per_joint_errors", "resample_polyline", "sample_deviations"]


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
    matched = matched_samples(setpoints, path_index, paths, path, start_s, end_s, sample_step)
    return sample_deviations(setpoints, matched, path_index, fk)


def matched_samples(
    setpoints: Sequence[Tensor],
    path_index: Tensor,
    paths: PathSet,
    path: Sequence[int],
    start_s: Sequence[float],
    end_s: Sequence[float],
    sample_step: float = 0.01,
) -> list[tuple[Tensor, Tensor]]:
    """Per episode (executed, reference) path-joint samples at equal arc length, (K_i, M) each, float64, rad."""
    out = []
    for q, p, s0, s1 in zip(setpoints, path, start_s, end_s, strict=True):
        q_exec, s = resample_polyline(q.to(torch.float64)[:, path_index], sample_step)
        s_ref = torch.clamp(s0 + s, max=s1)
        idx = torch.full((len(s),), p, dtype=torch.long, device=paths.device)
        out.append((q_exec, paths.position_at(idx, s_ref.to(paths.device)).to(q_exec)))
    return out


def sample_deviations(
    setpoints: Sequence[Tensor],
    matched: Sequence[tuple[Tensor, Tensor]],
    path_index: Tensor,
    fk: ForwardKinematics,
) -> list[dict[str, float]]:
    """Deviation metrics (:data:`METRIC_KEYS`) per episode from its :func:`matched_samples`; `setpoints` (T_i, D)
    give the non-path joints (as at the last setpoint) for the batched FK pass."""
    joint, full_exec, full_ref = [], [], []
    for q, (q_exec, q_ref) in zip(setpoints, matched, strict=True):
        q_all = q.to(torch.float64)
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


def per_joint_errors(errors: Tensor, joint_names: Sequence[str]) -> dict[str, dict[str, float]]:
    """Per path joint, over all samples of `errors` (N, M) = executed minus reference (rad): ``offset_rad`` (mean
    signed error), ``rms_rad`` (root mean square error) and ``share`` (the joint's part of the summed squared joint
    deviation; the shares sum to 1, all 0 when there is no error)."""
    if errors.ndim != 2 or errors.shape[1] != len(joint_names):
        raise ValueError(f"errors {tuple(errors.shape)}: expected (N, {len(joint_names)}), one column per joint")
    e = errors.to(torch.float64)
    sq = (e * e).sum(0)  # (M,)
    total = float(sq.sum())
    offset, rms = e.mean(0).tolist(), (sq / max(len(e), 1)).sqrt().tolist()
    share = (sq / total).tolist() if total > 0 else [0.0] * len(joint_names)
    return {n: {"offset_rad": o, "rms_rad": r, "share": f}
            for n, o, r, f in zip(joint_names, offset, rms, share, strict=True)}


def offset_joints(per_joint: dict[str, dict[str, float]], threshold: float = 0.02) -> list[str]:
    """Names of the joints of :func:`per_joint_errors` with |offset| > `threshold` (rad), largest first."""
    big = [n for n, v in per_joint.items() if abs(v["offset_rad"]) > threshold]
    return sorted(big, key=lambda n: -abs(per_joint[n]["offset_rad"]))


def _embed(q_path: Tensor, q_all: Tensor, path_index: Tensor) -> Tensor:
    """(K, M) path-joint samples -> (K, D) configurations; other joints from the last setpoint."""
    full = q_all[-1].expand(q_path.shape[0], -1).clone()
    full[:, path_index] = q_path
    return full
