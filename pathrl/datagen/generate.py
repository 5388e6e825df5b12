"""``pathrl-dataset generate``: one entry point for every registered dataset generator.

The generators live in :mod:`pathrl.datagen.generators` (one module per kind behind one protocol and one
registry, :data:`pathrl.datagen.generators.GENERATORS`); how they work and why: docs/datasets.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pathrl.datagen.generators import get_generator
from pathrl.dataset.io import Dataset
from pathrl.robot.model import load_robot

__all__ = ["generate_dataset"]


def generate_dataset(
    robot_cfg: Mapping[str, Any],
    dataset_cfg: Mapping[str, Any],
    dest: str | None = None,
    workers: int = 1,
    overwrite: bool = False,
    progress: bool = True,
) -> Dataset:
    """Generate and save a dataset (train + test) as configured by a resolved robot and dataset config.

    Dispatches on ``dataset_cfg["kind"]`` to the registered generator. The destination is checked before any
    work; the result is written atomically (path kinds: :func:`pathrl.datagen.generators.paths.generate_paths`).
    """
    robot_cfg = dict(robot_cfg)
    load_robot(robot_cfg)  # a bad robot config fails first, whatever the kind
    generator = get_generator(str(dataset_cfg["kind"]))
    return generator(robot_cfg, dataset_cfg, dest, workers, overwrite, progress)
