"""``pathrl-dataset generate``: one entry point for every registered dataset generator.

The generators live in :mod:`pathrl.dataset.generators` (one module per kind behind one protocol and one
registry, :data:`pathrl.dataset.generators.GENERATORS`); how they work and why: docs/datasets.md. The names
below are re-exported from their new homes for code that imports them from here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pathrl.dataset.generators import GENERATORS, get_generator
from pathrl.dataset.generators.ball_balancing import ball_constraint_violation, ball_paths, check_ball_robot
from pathrl.dataset.generators.context import GenerationError, GeneratorContext, process_context
from pathrl.dataset.generators.defaults import APPROACHES, DEFAULT_PARAMS, KINDS, resolve_params
from pathrl.dataset.generators.ik import sample_starts, solve_ik
from pathrl.dataset.generators.jobs import SPLIT_IDS
from pathrl.dataset.generators.paths import generate_chunk
from pathrl.dataset.generators.rollout import path_valid, rollout_paths
from pathrl.dataset.io import Dataset
from pathrl.robot.model import load_robot

__all__ = [
    "APPROACHES",
    "DEFAULT_PARAMS",
    "GENERATORS",
    "KINDS",
    "SPLIT_IDS",
    "GenerationError",
    "GeneratorContext",
    "ball_constraint_violation",
    "ball_paths",
    "check_ball_robot",
    "generate_chunk",
    "generate_dataset",
    "path_valid",
    "process_context",
    "resolve_params",
    "rollout_paths",
    "sample_starts",
    "solve_ik",
]


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
    work; the result is written atomically (path kinds: :func:`pathrl.dataset.generators.paths.generate_paths`).
    """
    robot_cfg = dict(robot_cfg)
    load_robot(robot_cfg)  # a bad robot config fails first, whatever the kind
    generator = get_generator(str(dataset_cfg["kind"]))
    return generator(robot_cfg, dataset_cfg, dest, workers, overwrite, progress)
