"""Shared fixtures: one torch thread (the suite's workloads are small), a tiny synthetic iiwa7 dataset, a tiny
TrueAdapt trajectory set."""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest  # noqa: E402
import torch  # noqa: E402

from pathrl.dataset.synthetic import write_synthetic  # noqa: E402

torch.set_num_threads(1)


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    return write_synthetic(tmp_path_factory.mktemp("data") / "iiwa7_tiny")


@pytest.fixture(scope="session")
def tiny_trueadapt(tmp_path_factory):
    """A generated TrueAdapt on-plate set of one drawn trajectory per split (4 stored each, mirrored)."""
    from omegaconf import OmegaConf

    from pathrl.config.paths import CONF_DIR
    from pathrl.datagen.generate import generate_dataset

    robot = OmegaConf.to_container(OmegaConf.load(CONF_DIR / "robot" / "iiwa7.yaml"), resolve=True)
    ds = OmegaConf.load(CONF_DIR / "dataset" / "trueadapt_on_plate.yaml")
    ds.num_train, ds.num_test = 1, 1
    dest = tmp_path_factory.mktemp("ta") / "tiny"
    return generate_dataset(robot, OmegaConf.to_container(ds, resolve=False), dest=str(dest), workers=1,
                            progress=False)
