"""``random`` generator: paths from random limit-respecting motions (docs/datasets.md)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from pathrl.datagen.generators.context import GeneratorContext
from pathrl.datagen.generators.defaults import smoothing_range
from pathrl.datagen.generators.rollout import stored_rollout_paths
from pathrl.robot.model import RobotSpec

__all__ = ["KIND", "check_robot", "draw_smoothing", "stored_paths"]

KIND = "random"


def draw_smoothing(lo: float, hi: float, n: int, tgen: torch.Generator) -> torch.Tensor:
    """(n, 1) AR(1) coefficients rho in [lo, hi] with 1 - rho log-uniform: the actions' correlation time
    dt / (1 - rho) is log-uniform, so every time scale between dt / (1 - lo) and dt / (1 - hi) is equally common."""
    u = torch.rand(n, 1, generator=tgen, dtype=torch.float64)
    return 1.0 - (1.0 - lo) * ((1.0 - hi) / (1.0 - lo)) ** u


class _RandomPolicy:
    """Uniform random actions, optionally AR(1)-smoothed (one coefficient per candidate, :func:`draw_smoothing` when
    ``action_smoothing`` is a range); a checkpoint every ``checkpoint_steps`` steps."""

    def __init__(self, ctx: GeneratorContext, p: Mapping[str, Any], n: int, tgen: torch.Generator):
        lo, hi = smoothing_range(p["action_smoothing"])
        self.rho: torch.Tensor | None = None  # (n, 1); None: independent actions
        if hi > lo:
            self.rho = draw_smoothing(lo, hi, n, tgen)
        elif hi > 0:  # a fixed rho draws nothing: the stream of a fixed-rho dataset is unchanged
            self.rho = torch.full((n, 1), lo, dtype=torch.float64)
        self.ck_steps = int(p["checkpoint_steps"])
        self.tgen = tgen
        self.prev = torch.zeros(n, ctx.spec.dof, dtype=torch.float64)

    def reset(self, q0: torch.Tensor) -> torch.Tensor:
        return torch.zeros(len(q0), dtype=torch.bool)

    def action(self, rows, p, v, a, a_min, a_max) -> torch.Tensor:
        u = torch.rand(a_min.shape, generator=self.tgen, dtype=torch.float64) * 2.0 - 1.0
        if self.rho is not None:
            rho = self.rho[rows]
            u = (rho * self.prev[rows] + torch.sqrt(1.0 - rho**2) * u).clamp(-1.0, 1.0)
            self.prev[rows] = u
        return u

    def after_step(self, rows, p, steps) -> tuple[torch.Tensor, torch.Tensor]:
        """-> (checkpoint mask, reject mask) for `rows`."""
        return steps[rows] % self.ck_steps == 0, torch.zeros(len(rows), dtype=torch.bool)

    def finished(self, rows: torch.Tensor) -> None:
        pass

    def on_rewind(self, rows, p) -> torch.Tensor:
        self.prev[rows] = 0.0
        return torch.zeros(len(rows), dtype=torch.bool)


def check_robot(spec: RobotSpec) -> None:
    """Any robot whose joints are all path joints (checked by :func:`generate_paths`)."""


def stored_paths(
    ctx: GeneratorContext,
    params: Mapping[str, Any],
    n: int,
    rng: np.random.Generator,
    tgen: torch.Generator,
    stats: dict[str, int],
) -> list[np.ndarray]:
    """`n` stored paths of one chunk (:func:`pathrl.datagen.generators.rollout.stored_rollout_paths`)."""
    return stored_rollout_paths(ctx, lambda b: _RandomPolicy(ctx, params, b, tgen), params, n, rng, stats)

