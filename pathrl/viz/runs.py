"""Rerun recordings (``.rrd``) of training runs (``run.mcap``): ``/training/<tag>`` scalars on the
``iteration`` timeline (RSL-RL's ``.../time`` tags on ``train_time``, seconds) and ``/training/config`` (static
markdown of the config message)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from pathrl.logging.schema import RUN_CONFIG, TRAIN_SCALARS
from pathrl.viz.blueprint import run_blueprint
from pathrl.viz.reading import ViewError, read_run
from pathrl.viz.rrd import ConvertStats, is_time_tag, removed_on_error, rerun_sdk, send_columns, tag_entity

__all__ = ["run_to_rrd"]


def run_to_rrd(src: Path, out: Path) -> ConvertStats:
    """Convert the training curves (and config) of a ``run.mcap`` into the recording `out`.

    Tags ending in ``/time`` (RSL-RL's ``Train/mean_reward/time``: step = elapsed seconds) go on the
    ``train_time`` timeline (seconds), every other tag on ``iteration``.
    """
    t0 = time.perf_counter()
    config, curves = read_run(src)
    if not curves and config is None:
        raise ViewError(f"{src}: no {TRAIN_SCALARS} or {RUN_CONFIG} messages")
    rr = rerun_sdk()
    rec = rr.RecordingStream("pathrl")
    tmp = out.with_name(out.name + ".tmp")
    rec.save(tmp, default_blueprint=run_blueprint(list(curves), config is not None))
    rec.send_recording_name(f"{src.parent.name}/{src.name}")
    with removed_on_error(tmp):
        for tag, (its, vals) in curves.items():
            ent = tag_entity(tag)
            rec.log(ent, rr.SeriesLines(names=tag), static=True)
            index = (
                rr.TimeColumn("train_time", duration=its.astype(np.float64))
                if is_time_tag(tag)
                else rr.TimeColumn("iteration", sequence=its)
            )
            send_columns(rec, ent, [index], rr.Scalars.columns(scalars=vals))
        if config is not None:
            rec.log(
                "training/config",
                rr.TextDocument(_config_markdown(config), media_type="text/markdown"),
                static=True,
            )
        rec.flush()
        rec.disconnect()
        tmp.replace(out)  # inside: a failed rename (out is a directory) removes the temp file
    return ConvertStats(out, "run", len(curves), time.perf_counter() - t0, out.stat().st_size)


def _config_markdown(config: Any) -> str:
    import yaml

    body = (
        yaml.safe_dump(config, sort_keys=False, default_flow_style=False)
        if isinstance(config, dict)
        else str(config)
    )
    return f"### Run config\n\n```yaml\n{body}```\n"
