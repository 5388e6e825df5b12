"""The episode protocol shared by training, evaluation and the TOPP-RA baseline.

``paper``: a random segment per episode (as the paper's authors evaluated): start at normalized arc
length U(0, 0.8), end at U(start + 0.2, 1), the end moved forward to the next knot.
``full``: whole paths. Evaluation plans cycle over the test paths with a fixed seed, so every method
sees exactly the same segments.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from pathrl.paths.pathset import PathSet

__all__ = ["PROTOCOLS", "Segments", "evaluation_plan", "full_segments", "sample_segments"]

PROTOCOLS = ("paper", "full")


@dataclass(frozen=True)
class Segments:
    """A batch of episode segments. All (N,) tensors; arc lengths in rad."""

    path: Tensor
    start_s: Tensor
    end_s: Tensor
    end_knot: Tensor

    def __len__(self) -> int:
        return int(self.path.shape[0])

    def subset(self, ids: Tensor) -> Segments:
        """The segments `ids` (K,) of this batch."""
        return Segments(self.path[ids], self.start_s[ids], self.end_s[ids], self.end_knot[ids])

    def to(self, device: torch.device | str) -> Segments:
        """The same segments on `device`."""
        return Segments(self.path.to(device), self.start_s.to(device), self.end_s.to(device), self.end_knot.to(device))


def sample_segments(
    paths: PathSet,
    idx: Tensor,
    generator: torch.Generator,
    start_range: tuple[float, float] = (0.0, 0.8),
    min_fraction: float = 0.2,
) -> Segments:
    """Random segments of paths `idx` (N,) following the paper's protocol."""
    n = idx.shape[0]
    dev, dt = paths.device, paths.length.dtype
    u = torch.rand(n, generator=generator, device=dev, dtype=dt)
    u_start = start_range[0] + u * (start_range[1] - start_range[0])
    lo = torch.clamp(u_start + min_fraction, max=1.0)
    u_end = lo + torch.rand(n, generator=generator, device=dev, dtype=dt) * (1.0 - lo)
    length = paths.length[idx]
    start_s = u_start * length
    end_knot = paths.first_knot_at_or_after(idx, u_end * length)
    end_s = paths.knot_s[idx, end_knot]
    return Segments(idx, start_s, end_s, end_knot)


def full_segments(paths: PathSet, idx: Tensor) -> Segments:
    """Whole paths `idx` (N,): from s = 0 to the end knot."""
    end_knot = paths.num_knots[idx] - 1
    return Segments(idx, torch.zeros_like(paths.length[idx]), paths.length[idx].clone(), end_knot)


def evaluation_plan(paths: PathSet, episodes: int, protocol: str = "paper", seed: int = 0) -> Segments:
    """Deterministic episode plan: episode i uses path i mod P; `paper` segments drawn with `seed`."""
    if protocol not in PROTOCOLS:
        raise ValueError(f"segments must be one of {PROTOCOLS}, got {protocol!r}")
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    idx = torch.arange(episodes, device=paths.device) % paths.num_paths
    if protocol == "full":
        return full_segments(paths, idx)
    gen = torch.Generator(device=paths.device)
    gen.manual_seed(seed)
    return sample_segments(paths, idx, gen)
