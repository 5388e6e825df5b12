"""TrueAdapt reference trajectories on disk: time-parameterised iiwa7 plate motions sampled every ``sample_dt``.

Stored in the project's dataset format (:mod:`pathrl.dataset.io`): the "knots" of a path are its positions at
t = 0, dt, 2 dt, ... (a trajectory, not a geometric path; ``meta["kind"] == "trueadapt"`` and
``meta["sample_dt"]`` say so). :func:`load_trajectories` reads them back as a :class:`TrajectoryBank`;
:func:`trajectory_stats` summarises a split. They are made by :mod:`pathrl.datagen.trueadapt`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from scipy.interpolate import CubicSpline

from pathrl.dataset.io import DatasetError, load_dataset
from pathrl.robot.model import RobotSpec

__all__ = ["KIND", "TrajectoryBank", "bank_from_arrays", "format_trajectory_stats", "load_trajectories",
           "reference_derivatives", "trajectory_stats"]

#: ``meta["kind"]`` of a TrueAdapt trajectory set.
KIND = "trueadapt"


def reference_derivatives(q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations (T, D) at the samples of the clamped cubic spline through q (T, D).

    A cubic spline has piecewise-linear acceleration, so replaying these accelerations with the env's linear
    interpolation (from v = 0) reproduces the spline exactly, up to the first step where the env starts at
    a = 0 instead of the spline's first acceleration.
    """
    t = np.arange(len(q)) * dt
    spline = CubicSpline(t, q, axis=0, bc_type="clamped")
    return spline(t, 1), spline(t, 2)



def trajectory_stats(trajs: Sequence[np.ndarray], spec: RobotSpec, dt: float) -> dict[str, Any]:
    """Per split: count, duration (s) min/mean/max, plate travel (m) mean, mean and max |v| / v_max and |a| / a_max
    of the replayed reference (:func:`reference_derivatives`), mean |jerk| / j_max."""
    if not trajs:
        return {"count": 0}
    from pathrl.robot.kinematics import ForwardKinematics

    fk = ForwardKinematics(spec)
    dur = np.array([(len(q) - 1) * dt for q in trajs])
    travel, vn, an, jn = [], [], [], []
    for q in trajs:
        v, a = reference_derivatives(q, dt)
        tcp = fk.tcp_positions_np(q)[:, 0]
        travel.append(float(np.linalg.norm(np.diff(tcp, axis=0), axis=1).sum()))
        vn.append(np.abs(v) / spec.vel_limits)
        an.append(np.abs(a) / spec.acc_limits)
        jn.append(np.abs(np.diff(a, axis=0)) / dt / spec.jerk_limits)
    v_all, a_all, j_all = (np.concatenate(x) for x in (vn, an, jn))
    def mm(x: np.ndarray) -> dict[str, float]:
        return {"mean": float(x.mean()), "max": float(x.max())}

    return {"count": len(trajs), "duration_s": {"min": float(dur.min()), **mm(dur)},
            "travel_m_mean": float(np.mean(travel)), "vel_norm": mm(v_all), "acc_norm": mm(a_all),
            "jerk_norm_mean": float(j_all.mean())}


def format_trajectory_stats(stats: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """Lines for ``pathrl-dataset info``."""
    lines = ["trajectories (duration s min/mean/max, plate travel m, |v|/v_max and |a|/a_max mean/max, |j|/j_max mean)"]
    for split, st in stats.items():
        if not st.get("count"):
            lines.append(f"  {split:5s} 0 trajectories")
            continue
        d, v, a = st["duration_s"], st["vel_norm"], st["acc_norm"]
        lines.append(f"  {split:5s} {st['count']} trajectories, "
                     f"duration {d['min']:.2f}/{d['mean']:.2f}/{d['max']:.2f}, "
                     f"travel {st['travel_m_mean']:.2f}, v {v['mean']:.3f}/{v['max']:.3f}, "
                     f"a {a['mean']:.3f}/{a['max']:.3f}, j {st['jerk_norm_mean']:.4f}")
    return lines


# ----------------------------------------------------------------------------------------------------
# loading


@dataclass(frozen=True)
class TrajectoryBank:
    """Reference trajectories of one split as padded float64 tensors (P trajectories, T_max samples, D joints).

    pos, acc: (P, T_max, D) samples and replay accelerations (:func:`reference_derivatives`), padded with the
    final (rest) sample; steps: (P,) long, the number of decision steps (samples - 1); dt: sample period (s).
    """

    pos: torch.Tensor
    acc: torch.Tensor
    steps: torch.Tensor
    dt: float

    @property
    def num(self) -> int:
        """Number of trajectories."""
        return int(self.pos.shape[0])

    def to(self, device: str | torch.device) -> TrajectoryBank:
        """The bank on `device`."""
        return TrajectoryBank(self.pos.to(device), self.acc.to(device), self.steps.to(device), self.dt)


def bank_from_arrays(trajs: Sequence[np.ndarray], dt: float) -> TrajectoryBank:
    """A :class:`TrajectoryBank` from trajectories (T_i, D) sampled every `dt`."""
    t_max = max(len(q) for q in trajs)
    d = trajs[0].shape[1]
    pos = np.empty((len(trajs), t_max, d))
    acc = np.zeros((len(trajs), t_max, d))
    for i, q in enumerate(trajs):
        pos[i, : len(q)], pos[i, len(q):] = q, q[-1]
        acc[i, : len(q)] = reference_derivatives(q, dt)[1]
    steps = torch.as_tensor([len(q) - 1 for q in trajs], dtype=torch.long)
    return TrajectoryBank(torch.as_tensor(pos), torch.as_tensor(acc), steps, dt)


def load_trajectories(path: str, split: str, robot: RobotSpec, dt: float) -> TrajectoryBank:
    """A split of a TrueAdapt dataset as a bank; DatasetError if it is no such set, or sampled at another dt."""
    ds = load_dataset(path, robot=robot)
    if ds.meta.get("kind") != KIND:
        raise DatasetError(f"{path}: kind {ds.meta.get('kind')!r} is not a {KIND} trajectory set; generate one with "
                           f"pathrl-dataset generate robot={robot.name} dataset=trueadapt_on_plate")
    if abs(float(ds.meta.get("sample_dt", -1.0)) - dt) > 1e-12:
        raise DatasetError(f"{path}: trajectories sampled every {ds.meta.get('sample_dt')} s, the env steps {dt} s")
    if split not in ds.splits or not len(ds.splits[split]):
        raise DatasetError(f"{path}: split {split!r} missing or empty")
    return bank_from_arrays(list(ds.splits[split].knots), dt)
