"""Shared fixtures: one torch thread (the suite's workloads are small), a tiny synthetic iiwa7 dataset."""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402

from pathrl.dataset.io import save_dataset
from pathrl.robot.model import load_robot_by_name  # noqa: E402

torch.set_num_threads(1)


def smooth_paths(robot, n, seed):
    rng = np.random.default_rng(seed)
    lim = robot.pos_limits[robot.path_index]
    mid, half = lim.mean(1), 0.3 * (lim[:, 1] - lim[:, 0]) / 2
    t = np.linspace(0, 1, 40)[:, None]
    return [(f"path_{seed}_{i}", mid + half * np.sin(2 * np.pi * rng.uniform(0.3, 1.0, (1, len(mid))) * t
                                              + rng.uniform(0, 6.28, (1, len(mid))))) for i in range(n)]


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    robot = load_robot_by_name("iiwa7")
    dest = tmp_path_factory.mktemp("data") / "iiwa7_tiny"
    meta = {"robot": "iiwa7", "kind": "synthetic", "path_joints": list(robot.path_joints), "seed": 0,
            "generator": {"kind": "synthetic"}, "source": "test"}
    save_dataset(dest, {"train": smooth_paths(robot, 6, 0), "test": smooth_paths(robot, 3, 1)}, meta)
    return dest
