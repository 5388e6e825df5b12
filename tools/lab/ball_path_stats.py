"""How alike are two sets of plate-horizontal iiwa7 paths? (the statistics used to set ``dataset=ball_balancing_sweep``)

Per dataset (its ``test`` split, or ``--split``), over the whole paths sampled every 0.05 rad:

* mean arc length (rad) and mean turn between consecutive knot steps (deg);
* share of the joint motion (sum of |dq| per joint over all joints) for q1, q2, q4, q6, and the mean extent
  (max - min over a path) of those joints;
* mean and spread of the start configuration and the mean over whole paths (q1, q2, q4, q6);
* TCP path length per joint-space rad, mean TCP height and mean distance from the base axis (m).

TOPP-RA durations come from ``pathrl-toppra robot=iiwa7 dataset.path=DIR segments=full`` beside it.
The authors' released set, for the comparison: ``pathrl-dataset import --format kiemel-json --robot iiwa7
<pathTracking>/tracking/dataset/industrial/ball_balancing DEST`` from a checkout of their code (not committed).

Usage:
    .venv/bin/python tools/lab/ball_path_stats.py data/iiwa7/ball_balancing_sweep datasets/iiwa7/ball_balancing [...]
"""

from __future__ import annotations

import argparse

import numpy as np

from pathrl.dataset.io import load_dataset
from pathrl.paths.spline import dedupe_knots, sample_uniform
from pathrl.robot.external import load_robot_by_name
from pathrl.robot.kinematics import ForwardKinematics

JOINTS = (0, 1, 3, 5)  # q1, q2, q4, q6: the joints that move on a plate-horizontal path


def path_stats(knots_list: list[np.ndarray], fk: ForwardKinematics, step: float = 0.05) -> dict[str, np.ndarray]:
    """The statistics above for paths `knots_list` [(K_i, 7)] (rad); `step` is the sampling distance (rad)."""
    share, extent, start, mean, length, turn, lever, height, radius = ([] for _ in range(9))
    for k in knots_list:
        k = dedupe_knots(k)
        q, total = sample_uniform(k, step)
        dq = np.abs(np.diff(q, axis=0)).sum(0)
        share.append(dq / dq.sum())
        extent.append(q.max(0) - q.min(0))
        start.append(q[0])
        mean.append(q.mean(0))
        length.append(total)
        d = np.diff(k, axis=0)
        u = d / np.linalg.norm(d, axis=1, keepdims=True)
        turn.append(np.degrees(np.arccos(np.clip((u[1:] * u[:-1]).sum(1), -1.0, 1.0))).mean())
        x = fk.tcp_positions_np(q).reshape(len(q), -1)[:, :3]
        lever.append(np.linalg.norm(np.diff(x, axis=0), axis=1).sum() / total)
        height.append(x[:, 2].mean())
        radius.append(np.linalg.norm(x[:, :2], axis=1).mean())
    j = list(JOINTS)
    return {
        "length_rad": np.mean(length),
        "turn_deg": np.mean(turn),
        "motion_share": np.mean(share, 0)[j],
        "extent_rad": np.mean(extent, 0)[j],
        "start_mean": np.mean(start, 0)[j],
        "start_std": np.std(start, 0)[j],
        "path_mean": np.mean(mean, 0)[j],
        "tcp_m_per_rad": np.mean(lever),
        "tcp_height_m": np.mean(height),
        "tcp_radius_m": np.mean(radius),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", nargs="+")
    ap.add_argument("--split", default="test")
    args = ap.parse_args()
    fk = ForwardKinematics(load_robot_by_name("iiwa7"))
    np.set_printoptions(precision=3, suppress=True)
    print("joint columns: q1, q2, q4, q6")
    for path in args.datasets:
        knots = list(load_dataset(path).splits[args.split].knots)
        print(f"{path} ({args.split}, {len(knots)} paths)")
        for key, value in path_stats(knots, fk).items():
            print(f"  {key:14s} {value:.3f}" if np.ndim(value) == 0 else f"  {key:14s} {value}")


if __name__ == "__main__":
    main()
