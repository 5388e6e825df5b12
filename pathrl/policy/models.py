"""Policy and value models for RSL-RL: the stock `MLPModel` with its hidden layers computed in bfloat16.

On a CPU with native bfloat16 (AVX-512 BF16 or AMX) the hidden matrix products of a PPO update run about twice as
fast in bfloat16; on one without (AVX2 only) torch emulates them and a PPO update is about 13x *slower* than in
float32 (measured: 27.5 s against 2.0 s per iteration, iiwa7 random): :func:`bfloat16_warning` measures it.
Only the inputs of the hidden layers are rounded (8-bit mantissa); the weights, their
gradients, the optimizer state, the output layer, the action distribution and every loss stay float32.
The model is the same function in rollouts, updates and evaluation, so PPO's probability ratio starts at
exactly 1 and nothing is biased by the rounding.

Measured (docs/lab/training_speed.md, iiwa7 random, 2 seeds each): 1.7x the samples/s of float32 and the paper's
quality in 5-7 instead of 13-21 min, but after 600 iterations 3.97-3.98 s against float32's 3.73-3.83 s at
the same deviation: late in training, with the action noise annealed, float32 learns more per sample.
``hidden_dtype="float32"`` is exactly the stock model. Keeping the first layer in float32 (the observation
unrounded) gave back most of the time (1.72 s per iteration against 1.16 s) and was dropped.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import torch
from rsl_rl.models import MLPModel
from rsl_rl.modules import MLP
from torch import nn

__all__ = ["BFLOAT16_EMULATED", "HIDDEN_DTYPES", "MixedMLP", "MixedPrecisionMLPModel", "bfloat16_roles",
           "bfloat16_slowdown", "bfloat16_warning"]


HIDDEN_DTYPES = {"bfloat16": torch.bfloat16, "float32": torch.float32}


class MixedMLP(MLP):
    """An rsl-rl `MLP` built from given layers (same state-dict keys) whose layers before the last run in `dtype`.

    forward: (N, in) float32 -> (N, out) float32.
    """

    def __init__(self, *layers: nn.Module, dtype: torch.dtype = torch.bfloat16) -> None:
        nn.Sequential.__init__(self, *layers)  # the layers exist already: skip MLP's constructor
        self.dtype = dtype

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, in) float32 -> (N, out) float32; hidden layers in ``dtype``."""
        *hidden, last = self
        with torch.autocast(x.device.type, dtype=self.dtype, enabled=self.dtype != torch.float32):
            for layer in hidden:
                x = layer(x)
        return last(x.float())


class MixedPrecisionMLPModel(MLPModel):
    """`rsl_rl.models.MLPModel` whose hidden layers compute in `hidden_dtype` ("bfloat16" or "float32").

    Its state dict is that of an `MLPModel` with the same sizes, so checkpoints load either way.
    """

    def __init__(self, *args, hidden_dtype: str = "bfloat16", **kwargs) -> None:
        super().__init__(*args, **kwargs)
        if hidden_dtype not in HIDDEN_DTYPES:
            raise ValueError(f"hidden_dtype: expected one of {list(HIDDEN_DTYPES)}, got {hidden_dtype!r}")
        self.mlp = MixedMLP(*self.mlp, dtype=HIDDEN_DTYPES[hidden_dtype])


#: A :func:`bfloat16_slowdown` above this: the CPU emulates bfloat16 (native: ~0.5; emulated: 10 or more).
BFLOAT16_EMULATED = 1.5


def bfloat16_slowdown(rows: int = 4096, reps: int = 3) -> float:
    """Wall time of a (rows, 256) -> 128 linear layer under bfloat16 autocast over the same in float32 on this CPU
    (best of `reps` after a warm-up): about 0.5 with native bfloat16, 10 or more where torch emulates it."""
    layer, x = nn.Linear(256, 128), torch.randn(rows, 256)

    def best(dtype: torch.dtype) -> float:
        times = []
        with torch.no_grad(), torch.autocast("cpu", dtype=dtype, enabled=dtype != torch.float32):
            for _ in range(reps + 1):
                t0 = time.perf_counter()
                layer(x)
                times.append(time.perf_counter() - t0)
        return min(times[1:])

    return best(torch.bfloat16) / max(best(torch.float32), 1e-9)


def bfloat16_roles(agent: Mapping[str, Any]) -> list[str]:
    """The models of an agent config (``actor``, ``critic``, ``student``, ``teacher``) whose hidden layers compute in
    bfloat16 (:class:`MixedPrecisionMLPModel` with ``hidden_dtype: bfloat16``)."""
    return [r for r in ("actor", "critic", "student", "teacher")
            if isinstance(agent.get(r), Mapping) and agent[r].get("hidden_dtype", "bfloat16") == "bfloat16"
            and str(agent[r].get("class_name", "")).endswith("MixedPrecisionMLPModel")]


def bfloat16_warning(agent: Mapping[str, Any], slowdown: float | None = None, limit: float = BFLOAT16_EMULATED
                     ) -> str | None:
    """One line for a run whose actor or critic (``agent.<role>.hidden_dtype``) asks for bfloat16 on a CPU where it is
    more than `limit` times slower than float32 (`slowdown`: measured by :func:`bfloat16_slowdown` when None)."""
    roles = bfloat16_roles(agent)
    if not roles:
        return None
    ratio = bfloat16_slowdown() if slowdown is None else slowdown
    if ratio <= limit:
        return None
    overrides = " ".join(f"agent.{r}.hidden_dtype=float32" for r in roles)
    return (f"bfloat16 hidden layers are {ratio:.0f}x slower than float32 on this CPU (no native bfloat16): "
            f"add {overrides} for a much faster run")
