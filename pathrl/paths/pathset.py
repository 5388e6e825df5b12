"""Many reference paths as padded torch tensors, for batched lookup inside the environment.

Each path is tabulated at uniform arc length (``table_step`` rad); positions in between are
linearly interpolated (error ~ kappa * h^2 / 8, i.e. ~1e-5 rad for h = 0.01 and kappa ~ 1). Knots and
their arc lengths are kept for the knot window of the observation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import torch
from torch import Tensor

from pathrl.paths.spline import dedupe_knots, tabulate

__all__ = ["PathSet", "build_pathset", "table_position"]


@dataclass(frozen=True)
class PathSet:
    """P paths with M joints each, padded to the longest.

    Attributes:
        names: (P,) path names (dataset file names).
        knots: (P, Kmax, M) knot positions; padded with the end knot.
        knot_s: (P, Kmax) arc length of each knot (rad); padded with the path length.
        num_knots: (P,) number of real knots.
        length: (P,) path length L (rad).
        table: (P, S, M) positions at s = j * table_step; padded with the end knot.
        table_step: arc-length spacing of `table` (rad).
    """

    names: tuple[str, ...]
    knots: Tensor
    knot_s: Tensor
    num_knots: Tensor
    length: Tensor
    table: Tensor
    table_step: float

    @property
    def num_paths(self) -> int:
        """Number of paths P."""
        return len(self.names)

    @property
    def dof(self) -> int:
        """Number of path joints M."""
        return int(self.knots.shape[-1])

    @property
    def device(self) -> torch.device:
        """Device of the tensors."""
        return self.knots.device

    def max_knot_gap(self) -> float:
        """Largest arc length between consecutive knots over all paths (the normalizer D)."""
        gaps = torch.diff(self.knot_s, dim=1)
        return float(gaps.max())

    def to(self, device: str | torch.device) -> PathSet:
        """The path set on `device`."""
        return replace(
            self,
            knots=self.knots.to(device),
            knot_s=self.knot_s.to(device),
            num_knots=self.num_knots.to(device),
            length=self.length.to(device),
            table=self.table.to(device),
        )

    def position_at(self, idx: Tensor, s: Tensor) -> Tensor:
        """Reference positions of paths `idx` (N,) at arc lengths `s` (N, ...), clamped to [0, L]. -> (N, ..., M)."""
        return table_position(self.table, self.length, self.table_step, idx, s)

    def knot_index_at(self, idx: Tensor, s: Tensor) -> Tensor:
        """Index of the last knot with arc length <= s, for paths `idx` (N,) at `s` (N,). -> (N,) long."""
        ks = self.knot_s[idx]
        i = torch.searchsorted(ks, s.to(ks.dtype).unsqueeze(1).contiguous(), right=True).squeeze(1) - 1
        return torch.clamp(i, min=0)

    def first_knot_at_or_after(self, idx: Tensor, s: Tensor) -> Tensor:
        """Index of the first knot with arc length >= s (the end snapped forward to a knot). -> (N,) long."""
        ks = self.knot_s[idx]
        i = torch.searchsorted(ks, s.to(ks.dtype).unsqueeze(1).contiguous(), right=False).squeeze(1)
        return torch.minimum(i, self.num_knots[idx] - 1)

    def window(self, idx: Tensor, s: Tensor, end_knot: Tensor, n: int) -> tuple[Tensor, Tensor]:
        """Knot window of the observation: the knot at/behind `s` and the n-1 following knots.

        Indices beyond `end_knot` repeat the end knot (paper: repeated end knot near the end).
        Returns (knots (N, n, M), knot_s (N, n)).
        """
        i0 = torch.minimum(self.knot_index_at(idx, s), end_knot)
        offs = torch.arange(n, device=s.device)
        ii = torch.minimum(i0.unsqueeze(1) + offs, end_knot.unsqueeze(1))  # (N, n)
        knots = self.knots[idx.unsqueeze(1), ii]
        ks = self.knot_s[idx.unsqueeze(1), ii]
        return knots, ks

    def subset(self, indices: Sequence[int]) -> PathSet:
        """The paths at `indices`, in that order (a new PathSet)."""
        ii = torch.as_tensor(list(indices), dtype=torch.long, device=self.device)
        return replace(
            self,
            names=tuple(self.names[i] for i in indices),
            knots=self.knots[ii],
            knot_s=self.knot_s[ii],
            num_knots=self.num_knots[ii],
            length=self.length[ii],
            table=self.table[ii],
        )


def table_position(table: Tensor, length: Tensor, table_step: float, idx: Tensor, s: Tensor) -> Tensor:
    """:meth:`PathSet.position_at` as a pure function of the path table (P, S, M) and lengths (P,)."""
    shape = s.shape
    s2 = s.reshape(shape[0], -1).to(table.dtype)
    x = (s2 / table_step).clamp(min=0.0)
    last = (length.index_select(0, idx) / table_step).to(table.dtype).unsqueeze(1)
    x = torch.minimum(x, last)
    n_s = table.shape[1]
    i0 = x.floor().long().clamp(max=n_s - 2)
    w = (x - i0).unsqueeze(-1)
    m = table.shape[-1]
    flat = table.reshape(-1, m)
    base = ((idx * n_s).unsqueeze(1) + i0).reshape(-1)  # rows of the flattened table
    p0 = flat.index_select(0, base).view(*i0.shape, m)
    p1 = flat.index_select(0, base + 1).view(*i0.shape, m)
    return (p0 + w * (p1 - p0)).reshape(*shape, m)


def build_pathset(
    knots_list: Sequence[np.ndarray],
    names: Sequence[str],
    table_step: float = 0.01,
    dtype: torch.dtype = torch.float64,
) -> PathSet:
    """Tabulate paths given by their knots (each (K_i, M)) into a :class:`PathSet`."""
    if len(knots_list) != len(names) or not knots_list:
        raise ValueError("need one name per path and at least one path")
    knots_list = [dedupe_knots(k) for k in knots_list]
    m = knots_list[0].shape[1]
    if any(k.shape[1] != m for k in knots_list):
        raise ValueError("all paths must have the same number of joints")
    tables, ks, lengths = [], [], []
    for k in knots_list:
        table, s_k, length = tabulate(k, table_step)
        tables.append(table)
        ks.append(s_k)
        lengths.append(length)
    p = len(knots_list)
    kmax = max(k.shape[0] for k in knots_list)
    smax = max(t.shape[0] for t in tables) + 1
    knots = np.empty((p, kmax, m))
    knot_s = np.empty((p, kmax))
    table = np.empty((p, smax, m))
    for i, (k, s_k, t, length) in enumerate(zip(knots_list, ks, tables, lengths, strict=True)):
        knots[i, : len(k)], knots[i, len(k) :] = k, k[-1]
        knot_s[i, : len(k)], knot_s[i, len(k) :] = s_k, length
        # t[:-1] sits at s = j * h, t[-1] at s = L (less than h after the previous sample). Store at
        # index j = len(t) - 1 the point that linear interpolation needs to hit t[-1] exactly at s = L.
        j = t.shape[0] - 1
        rest = length - (j - 1) * table_step
        table[i, :j] = t[:-1]
        if rest > 1e-9:
            table[i, j:] = t[-2] + (t[-1] - t[-2]) * (table_step / rest)
        else:
            table[i, j - 1 :] = t[-1]
    return PathSet(
        names=tuple(str(n) for n in names),
        knots=torch.as_tensor(knots, dtype=dtype),
        knot_s=torch.as_tensor(knot_s, dtype=dtype),
        num_knots=torch.as_tensor([len(k) for k in knots_list], dtype=torch.long),
        length=torch.as_tensor(lengths, dtype=dtype),
        table=torch.as_tensor(table, dtype=dtype),
        table_step=float(table_step),
    )
