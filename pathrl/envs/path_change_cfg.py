"""Settings of path changes during training (config group ``path_change``; :mod:`pathrl.envs.path_changes`). No
torch here: the config schema imports it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["PathChangeCfg"]


@dataclass
class PathChangeCfg:
    """Config group ``path_change`` (``conf/path_change/*.yaml``; absent or ``enabled: false``: no changes)."""

    enabled: bool = False
    fraction: float = 0.5  # share of episodes whose path changes (once)
    switch_range: list[float] = field(default_factory=lambda: [1.0, 4.0])  # s after the episode start
    offsets: list[float] = field(default_factory=lambda: [0.3, 0.6])  # joint offset of each variant (rad)
    ramps: list[float] = field(default_factory=lambda: [1.0, 0.3])  # its ramp (rad of arc length)
    slots: int = 1024  # branch rows in the path bank (episodes on a branch at once)
    lead_s: float = 0.1  # the branch's second knot: q + lead_s v (s)
    margin: float = 0.02  # branch knots this far inside the position limits (rad)
    arc_step: float = 0.01  # polyline spacing of the branch's arc-length table (rad), Richardson-extrapolated

    def __post_init__(self) -> None:
        rng = list(self.switch_range)
        if len(rng) != 2 or not 0 < rng[0] <= rng[1]:
            raise ValueError(f"path_change.switch_range must be [min, max], 0 < min <= max, got {self.switch_range}")
        if not 0.0 <= self.fraction <= 1.0:
            raise ValueError(f"path_change.fraction must be in [0, 1], got {self.fraction}")
        if not self.offsets or len(self.offsets) != len(self.ramps) or min(self.ramps) <= 0 or min(self.offsets) < 0:
            raise ValueError("path_change.offsets and path_change.ramps must be lists of equal length, offsets >= 0, "
                             f"ramps > 0, got {self.offsets}, {self.ramps}")
        if self.slots < 1 or self.lead_s < 0 or self.margin < 0 or not self.arc_step > 0:
            raise ValueError("path_change.slots must be >= 1, lead_s and margin >= 0, arc_step > 0")

    @classmethod
    def from_run(cls, cfg: dict[str, Any]) -> PathChangeCfg | None:
        """The run config's ``path_change`` group, or None when it is absent or disabled."""
        sub = cfg.get("path_change")
        if not sub or not sub.get("enabled", False):
            return None
        unknown = set(sub) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"path_change: unknown keys {sorted(unknown)}")
        return cls(**sub)
