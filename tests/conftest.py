"""Shared fixtures: one torch thread (the suite's workloads are small), a tiny synthetic iiwa7 dataset."""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest  # noqa: E402
import torch  # noqa: E402

from pathrl.dataset.synthetic import write_synthetic  # noqa: E402

torch.set_num_threads(1)


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    return write_synthetic(tmp_path_factory.mktemp("data") / "iiwa7_tiny")
