"""Rerun recordings (``.rrd``) of pathrl MCAP files: the former single module, now re-exports.

Reading: :mod:`pathrl.viz.reading` (topics and layouts: :mod:`pathrl.logging.schema`); the robot model:
:mod:`pathrl.viz.urdf`; episodes recordings: :mod:`pathrl.viz.episodes`; run recordings: :mod:`pathrl.viz.runs`;
layouts: :mod:`pathrl.viz.blueprint`; shared recording pieces: :mod:`pathrl.viz.rrd`; opening them:
:mod:`pathrl.viz.viewer`. Industrial optimisations (``industrial.mcap``): :mod:`pathrl.viz.industrial`; TrueAdapt
episodes (``trueadapt.mcap``): :mod:`pathrl.viz.trueadapt`; :func:`kind_of` tells the four kinds apart.
"""

from __future__ import annotations

from pathlib import Path

from pathrl.logging.schema import EPISODE_TOPICS, INDUSTRIAL_TOPICS, KNOWN_EVAL, RUN_TOPICS, TRUEADAPT_TOPICS
from pathrl.viz.blueprint import ACTIVE_TAB
from pathrl.viz.episodes import SUMMARY_COLS, episodes_to_rrd, metrics_markdown, summary_markdown
from pathrl.viz.industrial import industrial_to_rrd
from pathrl.viz.reading import (
    MCAP_MAGIC,
    QUANTITIES,
    Episode,
    RobotInfo,
    ViewError,
    _topics,
    check_mcap,
    is_finished,
    jerk,
    progress_and_deviation,
    read_episodes,
    read_run,
    select_episodes,
)
from pathrl.viz.reading import kind_of as _episodes_or_run
from pathrl.viz.rrd import EPISODE_GAP_S, GREEN, GREY, RED, TCP_COLORS, UNITS, ConvertStats
from pathrl.viz.runs import run_to_rrd
from pathrl.viz.trueadapt import trueadapt_to_rrd
from pathrl.viz.urdf import MOVABLE, resolve_urdf, sanitize_urdf
from pathrl.viz.viewer import rerun_command, serve_web, spawn_viewer

__all__ = [
    "ACTIVE_TAB",
    "EPISODE_GAP_S",
    "EPISODE_TOPICS",
    "FILE_NAMES",
    "GREEN",
    "GREY",
    "KNOWN_EVAL",
    "MCAP_MAGIC",
    "MOVABLE",
    "QUANTITIES",
    "RED",
    "RUN_TOPICS",
    "SUMMARY_COLS",
    "TCP_COLORS",
    "UNITS",
    "ConvertStats",
    "Episode",
    "RobotInfo",
    "ViewError",
    "check_mcap",
    "episodes_to_rrd",
    "industrial_to_rrd",
    "is_finished",
    "jerk",
    "kind_of",
    "metrics_markdown",
    "progress_and_deviation",
    "read_episodes",
    "read_run",
    "rerun_command",
    "resolve_urdf",
    "run_to_rrd",
    "sanitize_urdf",
    "select_episodes",
    "serve_web",
    "spawn_viewer",
    "summary_markdown",
    "trueadapt_to_rrd",
]

#: MCAP file names ``pathrl-view DIR`` converts, in this order
FILE_NAMES = ("episodes.mcap", "run.mcap", "industrial.mcap", "trueadapt.mcap")


def kind_of(path: Path) -> str:
    """``"episodes"``, ``"run"``, ``"industrial"`` or ``"trueadapt"`` by the channels of an MCAP file."""
    check_mcap(path)
    topics = _topics(path)
    for kind, needed in (("industrial", INDUSTRIAL_TOPICS), ("trueadapt", TRUEADAPT_TOPICS)):
        if all(t in topics for t in needed):
            return kind
    try:
        return _episodes_or_run(path)
    except ViewError as exc:
        if not is_finished(path):  # cut off: the message says so, the other kinds' channels do not help
            raise
        raise ViewError(f"{exc} (or {' + '.join(INDUSTRIAL_TOPICS)} or {' + '.join(TRUEADAPT_TOPICS)})") from None
