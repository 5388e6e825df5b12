"""Dataset generators behind one protocol and one registry.

Every kind of dataset is made by a :class:`DatasetGenerator` (robot config, dataset config -> saved
:class:`pathrl.dataset.io.Dataset`), registered in :data:`GENERATORS` as ``"module:function"`` and imported on
first use. The path kinds (``random``, ``target_point``, ``ball_balancing``) share the chunked, seeded pipeline of
:mod:`pathrl.dataset.generators.paths`; each of their modules is a :class:`PathKind`. How they work and why:
docs/datasets.md.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol

from pathrl.dataset.io import DatasetError

if TYPE_CHECKING:
    import numpy as np
    import torch

    from pathrl.dataset.generators.context import GeneratorContext
    from pathrl.dataset.io import Dataset
    from pathrl.robot.model import RobotSpec

#: kind -> "module:function", a DatasetGenerator (``dataset.kind`` of conf/dataset/*.yaml).
GENERATORS: dict[str, str] = {
    "random": "pathrl.dataset.generators.random:generate",
    "target_point": "pathrl.dataset.generators.target_point:generate",
    "ball_balancing": "pathrl.dataset.generators.ball_balancing:generate",
    "trueadapt": "pathrl.dataset.trueadapt:generate_trueadapt",
}


class DatasetGenerator(Protocol):
    """Generate and save a dataset (train + test) as configured; the destination is checked before any work."""

    def __call__(
        self,
        robot_cfg: Mapping[str, Any],
        dataset_cfg: Mapping[str, Any],
        dest: str | None = None,
        workers: int = 1,
        overwrite: bool = False,
        progress: bool = True,
    ) -> Dataset: ...


class PathKind(Protocol):
    """A path kind's module, as :func:`pathrl.dataset.generators.paths.generate_paths` uses it."""

    KIND: str

    def check_robot(self, spec: RobotSpec) -> None:
        """DatasetError if the kind is not defined for this robot."""

    def stored_paths(
        self,
        ctx: GeneratorContext,
        params: Mapping[str, Any],
        n: int,
        rng: np.random.Generator,
        tgen: torch.Generator,
        stats: dict[str, int],
    ) -> list[np.ndarray]:
        """`n` stored knot arrays (K, D) of one chunk, drawn from the chunk's generators; counts into `stats`."""


def _entry(kind: str) -> tuple[str, str]:
    if kind not in GENERATORS:
        raise DatasetError(f"dataset.kind: unknown generator {kind!r}; choose one of {list(GENERATORS)}")
    module, name = GENERATORS[kind].split(":")
    return module, name


def get_generator(kind: str) -> DatasetGenerator:
    """The registered generator of `kind`; DatasetError (one line) for an unknown kind."""
    module, name = _entry(kind)
    return getattr(importlib.import_module(module), name)


def path_kind(kind: str) -> PathKind:
    """The module of a registered path kind (its generator's module)."""
    return importlib.import_module(_entry(kind)[0])  # type: ignore[return-value]
