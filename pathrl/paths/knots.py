"""Knot sampling strategies (config group ``conf/knots``) applied to a dataset's paths at load time."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from pathrl.paths.spline import dedupe_knots, resample_by_curvature, resample_by_distance

__all__ = ["KnotStrategy"]

STRATEGIES = ("curvature", "distance", "file")


@dataclass(frozen=True)
class KnotStrategy:
    """How knots are placed along each path and how many the policy sees.

    strategy: ``curvature`` (equal integrated curvature `spacing` between knots, after a distance
        resampling at `base_spacing` rad), ``distance`` (equal arc length `spacing` rad) or ``file``
        (keep the dataset's knots, e.g. for paths imported in the authors' format).
    n_state: number of knots in the observation (the knot at/behind the robot + n_state - 1 ahead).
    """

    strategy: str = "curvature"
    spacing: float = 0.3
    base_spacing: float = 0.1
    n_state: int = 9

    def __post_init__(self) -> None:
        if self.strategy not in STRATEGIES:
            raise ValueError(f"knots.strategy must be one of {STRATEGIES}, got {self.strategy!r}")
        if self.spacing <= 0 or self.base_spacing <= 0:
            raise ValueError("knots.spacing and knots.base_spacing must be > 0")
        if self.n_state < 2:
            raise ValueError(f"knots.n_state must be >= 2, got {self.n_state}")

    @classmethod
    def from_cfg(cls, cfg: Mapping[str, Any]) -> KnotStrategy:
        """The strategy of a ``knots`` config (other keys ignored)."""
        keys = {"strategy", "spacing", "base_spacing", "n_state"}
        return cls(**{k: v for k, v in cfg.items() if k in keys})

    def apply(self, knots: np.ndarray) -> np.ndarray:
        """Resample one path's knots (K, M) -> (K', M)."""
        if self.strategy == "file":
            return dedupe_knots(knots)
        if self.strategy == "distance":
            return resample_by_distance(knots, self.spacing)
        return resample_by_curvature(knots, self.spacing, self.base_spacing)
