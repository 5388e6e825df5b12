"""A synthetic path set for smoke runs and soak tests: smooth sine curves well inside the position limits."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pathrl.dataset.io import save_dataset
from pathrl.robot.external import load_robot_by_name
from pathrl.robot.model import RobotSpec

__all__ = ["smooth_paths", "write_synthetic"]


def smooth_paths(robot: RobotSpec, n: int, seed: int, knots: int = 40) -> list[tuple[str, np.ndarray]]:
    """`n` named paths of `knots` knots (K, M path joints): per joint a sine of random frequency (0.3-1 periods)
    and phase around the middle of the joint's range, spanning 30 % of it."""
    rng = np.random.default_rng(seed)
    lim = robot.pos_limits[robot.path_index]
    mid, half = lim.mean(1), 0.3 * (lim[:, 1] - lim[:, 0]) / 2
    t = np.linspace(0, 1, knots)[:, None]
    return [(f"path_{seed}_{i}", mid + half * np.sin(2 * np.pi * rng.uniform(0.3, 1.0, (1, len(mid))) * t
                                              + rng.uniform(0, 6.28, (1, len(mid))))) for i in range(n)]


def write_synthetic(dest: Path, robot_name: str = "iiwa7", num_train: int = 6, num_test: int = 3) -> Path:
    """A dataset directory of :func:`smooth_paths` (train seed 0, test seed 1) at `dest`."""
    robot = load_robot_by_name(robot_name)
    meta = {"robot": robot_name, "kind": "synthetic", "path_joints": list(robot.path_joints), "seed": 0,
            "generator": {"kind": "synthetic"}, "source": "pathrl.dataset.synthetic"}
    save_dataset(dest, {"train": smooth_paths(robot, num_train, 0), "test": smooth_paths(robot, num_test, 1)}, meta)
    return Path(dest)
