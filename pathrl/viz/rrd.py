"""Shared pieces of the Rerun recordings: the ``rerun`` import, column sends, the ``time`` index, entity
names, the episodes' placement on the ``time`` timeline, colours and units. Every ``rerun`` call of the project
lives in :mod:`pathrl.viz`."""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pathrl.viz.reading import Episode

__all__ = [
    "ConvertStats", "EPISODE_GAP_S", "GREEN", "GREY", "RED", "TCP_COLORS", "UNITS", "episode_starts", "episode_times",
    "esc", "is_time_tag", "removed_on_error", "rerun_sdk", "send_columns", "tag_entity", "time_column",
]

EPISODE_GAP_S = 0.5
UNITS = {"position": "rad", "velocity": "rad/s", "acceleration": "rad/s²", "jerk": "rad/s³"}
TCP_COLORS = ((230, 40, 40), (240, 110, 200), (255, 160, 40))
GREEN, RED, GREY = (40, 190, 70), (230, 40, 40), (140, 140, 140)


@dataclass
class ConvertStats:
    """What a conversion wrote: output file, kind, items (episodes or scalar tags), seconds, bytes and warnings."""

    out: Path
    kind: str
    items: int  # episodes or scalar tags
    seconds: float
    bytes: int
    warnings: list[str] = field(default_factory=list)


def rerun_sdk():
    """The ``rerun`` module, imported on first use."""
    import rerun as rr

    return rr


def send_columns(rec, entity: str, indexes: list, columns) -> None:
    """Send columnar data of `entity` to the recording `rec` (strict: bad data raises instead of warning)."""
    rec.send_columns(entity, indexes=indexes, columns=columns, strict=True)


def time_column(seconds: Any):
    """The ``time`` index (seconds rounded to whole nanoseconds, so 4.1 s is 4_100_000_000 ns)."""
    ns = np.round(np.asarray(seconds, dtype=np.float64) * 1e9).astype("timedelta64[ns]")
    return rerun_sdk().TimeColumn("time", duration=ns)


def esc(part: str) -> str:
    """`part` escaped as one entity path part."""
    return rerun_sdk().escape_entity_path_part(part)


@contextmanager
def removed_on_error(path: Path):
    """Context manager: `path` is deleted if the block raises (no half-written output)."""
    try:
        yield
    except BaseException:
        path.unlink(missing_ok=True)
        raise


def episode_starts(episodes: list[Episode]) -> np.ndarray:
    """Offsets (n,) s that place the episodes one after another on the ``time`` timeline, ``EPISODE_GAP_S`` apart."""
    starts, t = [], 0.0
    for e in episodes:
        starts.append(t - float(e.t[0]))
        t += float(e.t[-1] - e.t[0]) + EPISODE_GAP_S
    return np.array(starts)


def episode_times(episodes: list[Episode], starts: np.ndarray) -> np.ndarray:
    """All episodes' times (sum N,) s on the ``time`` timeline, shifted by their `starts`."""
    return np.concatenate([s + e.t for e, s in zip(episodes, starts, strict=True)])


def is_time_tag(tag: str) -> bool:
    """True for a scalar tag that is a timing (ends in ``/time``)."""
    return tag.endswith("/time")


def tag_entity(tag: str) -> str:
    """The entity path of a training scalar tag, under ``training/``."""
    return "training/" + "/".join(esc(p) for p in tag.split("/") if p)
