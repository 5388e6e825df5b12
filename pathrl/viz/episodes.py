"""Rerun recordings (``.rrd``) of evaluation episodes.

Reads MCAP only (``episodes.mcap`` written by :func:`pathrl.eval.evaluate.write_episodes_mcap`, ``run.mcap``
written by :class:`pathrl.train.mcap_logger.McapLogWriter`; :mod:`pathrl.viz.reading`). Run recordings:
:mod:`pathrl.viz.runs`; layouts: :mod:`pathrl.viz.blueprint`; the robot model: :mod:`pathrl.viz.urdf`.

Episodes recording (one recording per file, application id ``pathrl``), two timelines:

* ``time`` (seconds): the selected episodes back to back, episode k on
  ``[start_k, start_k + duration_k]`` with a gap of :data:`pathrl.viz.rrd.EPISODE_GAP_S` between episodes (the
  summary table lists every ``start_k``). Scrubbing it animates the robot and draws the plots.
* ``episode`` (sequence = the episode id): one row per episode (reference, complete executed path, final
  robot pose, metrics text, metric scalars), for stepping through episodes one at a time.

Entities::

    /world                                 right-handed, z up (the URDF root link frame)
    /world/<urdf robot name>/...           URDF visual geometry (rr.urdf.UrdfTree), static; frames = links
    /world/fixed_transforms/<joint>        fixed joints (static)
    /world/joint_transforms                movable joints (send_columns of compute_transform_columns)
    /world/reference                       reference TCP path(s), green line strips, per episode
    /world/executed                        executed TCP path(s), red, growing (complete on `episode`)
    /world/tcp, /world/reference_point     executed TCP now / reference at equal arc length (points)
    /world/<extra>                         points of optional channels such as /eval/ball, /eval/pelvis
    /joints/<joint>/<quantity>             position, velocity, acceleration, jerk (scalars)
    /joints/<joint>/<quantity>/limits      the lower/upper limit as two constant series
    /progress/fraction                     executed joint-space arc length / reference length
    /deviation/joint_rad                   |q_path - q_ref(s_exec)| at equal arc length (as the metrics)
    /deviation/cartesian_cm/<tcp link>     |tcp - tcp_ref(s_exec)| in cm
    /metrics/episode                       markdown table of the current episode's metrics
    /metrics/summary                       markdown table of all selected episodes (static)
    /metrics/source                        input file and selection (static)
    /episode_metrics/<key>                 numeric episode metrics on the `episode` timeline

Run recording: ``/training/<tag>`` scalars on the ``iteration`` timeline (RSL-RL's ``.../time`` tags on
``train_time``, seconds), ``/training/config`` (static markdown of the config message).

Both recordings carry a default blueprint (layout); the viewer opens at the end of the timeline.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pathrl.viz.blueprint import episodes_blueprint
from pathrl.viz.reading import (
    QUANTITIES,
    Episode,
    RobotInfo,
    ViewError,
    finite,
    jerk,
    progress_and_deviation,
    read_episodes,
    select_episodes,
)
from pathrl.viz.rrd import (
    EPISODE_GAP_S,
    GREEN,
    GREY,
    RED,
    TCP_COLORS,
    UNITS,
    ConvertStats,
    episode_starts,
    esc,
    removed_on_error,
    rerun_sdk,
    send_columns,
    time_column,
)
from pathrl.viz.urdf import anchor_to_robot_base, log_joint_transforms, log_robot

__all__ = ["SUMMARY_COLS", "episodes_to_rrd", "metrics_markdown", "summary_markdown"]


def episodes_to_rrd(
    src: Path, out: Path, ids: Sequence[int] | None = None, worst: int | None = None, timeline: str = "time"
) -> ConvertStats:
    """Convert (a selection of) the episodes of `src` into the recording `out`.

    `timeline` is the one the viewer opens on, at its end: ``time`` (the episodes back to back) or
    ``episode`` (one row per episode).
    """
    if timeline not in ("time", "episode"):
        raise ViewError(f"timeline must be time or episode, got {timeline!r}")
    t0 = time.perf_counter()
    robot, episodes = read_episodes(src)
    chosen = select_episodes(episodes, ids, worst)
    notes: list[str] = []
    rr = rerun_sdk()
    rec = rr.RecordingStream("pathrl")
    tmp = out.with_name(out.name + ".tmp")
    rec.save(tmp, default_blueprint=episodes_blueprint(robot, chosen, timeline))
    rec.send_recording_name(f"{src.parent.name}/{src.name}")
    with removed_on_error(tmp), tempfile.TemporaryDirectory(prefix="pathrl-view-") as tdir:
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rec.log(
            "metrics/source",
            rr.TextDocument(
                f"`{src}`: robot **{robot.name}**, {len(episodes)} episodes in the file, {len(chosen)} shown",
                media_type="text/markdown",
            ),
            static=True,
        )
        starts = episode_starts(chosen)
        tree = log_robot(rec, robot, Path(tdir), notes)
        if tree is not None:
            log_joint_transforms(rec, tree, robot, chosen, starts, notes)
            anchor_to_robot_base(rec, tree.root_link().name, chosen)
        derived = [progress_and_deviation(e, robot) for e in chosen]
        _log_paths(rec, chosen, starts, derived)
        _log_series(rec, robot, chosen, starts, derived)
        _log_metrics(rec, chosen, starts)
        _log_extras(rec, chosen, starts)
        rec.flush()
        rec.disconnect()
        tmp.replace(out)  # inside: a failed rename (out is a directory) removes the temp file
    return ConvertStats(out, "episodes", len(chosen), time.perf_counter() - t0, out.stat().st_size, notes)


def _strip_columns(strips: list[np.ndarray], per_row: int, **kw):
    rr = rerun_sdk()
    cols = rr.LineStrips3D.columns(strips=strips, **kw)
    return cols.partition([per_row] * (len(strips) // per_row)) if per_row != 1 else cols


def _log_paths(
    rec, episodes: list[Episode], starts: np.ndarray, derived: list[dict[str, np.ndarray]]
) -> None:
    rr = rerun_sdk()
    rec.log("world/reference", rr.LineStrips3D.from_fields(colors=[GREEN], radii=0.006), static=True)
    rec.log("world/executed", rr.LineStrips3D.from_fields(colors=[RED], radii=0.006), static=True)
    rec.log("world/tcp", rr.Points3D.from_fields(colors=[RED], radii=0.012), static=True)
    rec.log("world/reference_point", rr.Points3D.from_fields(colors=[GREEN], radii=0.009), static=True)
    with_ref = [(e, s) for e, s in zip(episodes, starts, strict=True) if e.ref_tcp is not None]
    if with_ref:
        n_tcp = with_ref[0][0].ref_tcp.shape[1]
        strips = [e.ref_tcp[:, k] for e, _ in with_ref for k in range(n_tcp)]
        send_columns(
            rec,
            "world/reference",
            [
                time_column([s + e.t[0] for e, s in with_ref]),
                rr.TimeColumn("episode", sequence=[e.episode for e, _ in with_ref]),
            ],
            _strip_columns(strips, n_tcp),
        )
    with_tcp = [(e, s) for e, s in zip(episodes, starts, strict=True) if e.tcp is not None]
    if not with_tcp:
        return
    n_tcp = with_tcp[0][0].tcp.shape[1]
    # growing trail on `time`: row k holds tcp[: k + 1] (a single point is drawn as nothing)
    trail = [e.tcp[: max(k + 1, 2)][:, i] for e, _ in with_tcp for k in range(len(e.t)) for i in range(n_tcp)]
    times = np.concatenate([s + e.t for e, s in with_tcp])
    send_columns(rec, "world/executed", [time_column(times)], _strip_columns(trail, n_tcp))
    full = [e.tcp[:, i] for e, _ in with_tcp for i in range(n_tcp)]
    send_columns(
        rec,
        "world/executed",
        [
            time_column([s + e.t[-1] for e, s in with_tcp]),
            rr.TimeColumn("episode", sequence=[e.episode for e, _ in with_tcp]),
        ],
        _strip_columns(full, n_tcp),
    )
    pts = np.concatenate([e.tcp for e, _ in with_tcp])
    send_columns(
        rec,
        "world/tcp",
        [time_column(times)],
        rr.Points3D.columns(positions=pts.reshape(-1, 3)).partition([n_tcp] * len(pts)),
    )
    with_ref_pt = [
        (e, s, d) for e, s, d in zip(episodes, starts, derived, strict=True) if "reference_tcp" in d
    ]
    if with_ref_pt:
        ref_pts = np.concatenate([d["reference_tcp"] for _, _, d in with_ref_pt])
        send_columns(
            rec,
            "world/reference_point",
            [time_column(np.concatenate([s + e.t for e, s, _ in with_ref_pt]))],
            rr.Points3D.columns(positions=ref_pts.reshape(-1, 3)).partition(
                [ref_pts.shape[1]] * len(ref_pts)
            ),
        )


def _scalar_series(rec, entity: str, times: np.ndarray, values: np.ndarray) -> None:
    rr = rerun_sdk()
    send_columns(rec, entity, [time_column(times)], rr.Scalars.columns(scalars=values))


def _with_gaps(
    episodes: list[Episode], starts: np.ndarray, per_episode: list[np.ndarray], times: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate per-episode series with a NaN row in each gap (the plot line breaks between episodes)."""
    ts, vs = [], []
    for i, (e, s, v, t) in enumerate(zip(episodes, starts, per_episode, times, strict=True)):
        ts.append(t)
        vs.append(v)
        if i + 1 < len(episodes):
            ts.append(np.array([s + e.t[-1] + EPISODE_GAP_S / 2]))
            vs.append(np.full((1, *v.shape[1:]), np.nan))
    return np.concatenate(ts), np.concatenate(vs)


def _log_series(
    rec, robot: RobotInfo, episodes: list[Episode], starts: np.ndarray, derived: list[dict[str, np.ndarray]]
) -> None:
    rr = rerun_sdk()
    t_end = float(starts[-1] + episodes[-1].t[-1])
    t_begin = float(starts[0] + episodes[0].t[0])
    data = {
        "position": [e.q for e in episodes],
        "velocity": [e.v for e in episodes],
        "acceleration": [e.a for e in episodes],
        "jerk": [jerk(e.a, e.t) for e in episodes],
    }
    times = {q: [s + e.t for e, s in zip(episodes, starts, strict=True)] for q in QUANTITIES}
    times["jerk"] = [s + e.t[1:] for e, s in zip(episodes, starts, strict=True)]
    for q in QUANTITIES:
        t_cat, v_cat = _with_gaps(episodes, starts, data[q], times[q])
        for j, name in enumerate(robot.joint_names):
            ent = f"joints/{esc(name)}/{q}"
            rec.log(
                ent,
                rr.SeriesLines(names=f"{name} {q} [{UNITS[q]}]", colors=[(50, 120, 220)], widths=1.5),
                static=True,
            )
            _scalar_series(rec, ent, t_cat, v_cat[:, j])
            if q in robot.limits:
                rec.log(
                    f"{ent}/limits",
                    rr.SeriesLines(names=["lower limit", "upper limit"], colors=[GREY, GREY], widths=1.0),
                    static=True,
                )
                lim = robot.limits[q][j]
                send_columns(
                    rec,
                    f"{ent}/limits",
                    [time_column([t_begin, t_end])],
                    rr.Scalars.columns(scalars=np.array([lim, lim])),
                )
    have = [(e, s, d) for e, s, d in zip(episodes, starts, derived, strict=True) if d]
    if not have:
        return
    eps, sts, ds = [h[0] for h in have], np.array([h[1] for h in have]), [h[2] for h in have]
    tt = [s + e.t for e, s in zip(eps, sts, strict=True)]
    rec.log(
        "progress/fraction",
        rr.SeriesLines(names="path progress (arc length fraction)", colors=[GREEN]),
        static=True,
    )
    _scalar_series(rec, "progress/fraction", *_with_gaps(eps, sts, [d["fraction"] for d in ds], tt))
    rec.log(
        "deviation/joint_rad",
        rr.SeriesLines(names="joint deviation [rad]", colors=[(200, 120, 30)]),
        static=True,
    )
    _scalar_series(rec, "deviation/joint_rad", *_with_gaps(eps, sts, [d["joint_rad"] for d in ds], tt))
    if all("cartesian_cm" in d for d in ds):
        t_cat, v_cat = _with_gaps(eps, sts, [d["cartesian_cm"] for d in ds], tt)
        links = robot.tcp_links or [f"tcp{k}" for k in range(v_cat.shape[1])]
        for k in range(v_cat.shape[1]):
            ent = f"deviation/cartesian_cm/{esc(links[k] if k < len(links) else f'tcp{k}')}"
            rec.log(
                ent,
                rr.SeriesLines(
                    names=f"TCP deviation {links[k] if k < len(links) else k} [cm]",
                    colors=[TCP_COLORS[k % len(TCP_COLORS)]],
                ),
                static=True,
            )
            _scalar_series(rec, ent, t_cat, v_cat[:, k])


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, dict)):
        return "…"
    return str(v)


def metrics_markdown(e: Episode, start: float) -> str:
    """Markdown table of one episode's metrics, with its start on the ``time`` timeline (`start` + its first time,
    s)."""
    head = f"### Episode {e.episode}" + (f" — `{e.path}`" if e.path else "")
    rows = [("timeline `time` start", f"{start + e.t[0]:.2f} s"), ("decision steps", str(len(e.t) - 1))]
    rows += [(k, _fmt(v)) for k, v in e.metrics.items() if k not in ("episode", "path")]
    return "\n".join([head, "", "| metric | value |", "|---|---|", *[f"| {k} | {v} |" for k, v in rows]])


SUMMARY_COLS = (
    "duration_s",
    "termination",
    "cart_pos_dev_mean_cm",
    "cart_pos_dev_max_cm",
    "joint_dev_mean_rad",
    "limit_violations",
)


def summary_markdown(episodes: list[Episode], starts: np.ndarray) -> str:
    """Markdown table of all episodes: id, path, start on the ``time`` timeline (s) and the summary metrics they
    have."""
    cols = [c for c in SUMMARY_COLS if any(c in e.metrics for e in episodes)]
    lines = ["| episode | path | start [s] | " + " | ".join(cols) + " |", "|---" * (3 + len(cols)) + "|"]
    for e, s in zip(episodes, starts, strict=True):
        vals = [_fmt(e.metrics.get(c, "")) for c in cols]
        lines.append(f"| {e.episode} | {e.path} | {s + e.t[0]:.2f} | " + " | ".join(vals) + " |")
    return "### Episodes on the `time` timeline\n\n" + "\n".join(lines)


def _log_metrics(rec, episodes: list[Episode], starts: np.ndarray) -> None:
    rr = rerun_sdk()
    idx = [
        time_column([s + e.t[0] for e, s in zip(episodes, starts, strict=True)]),
        rr.TimeColumn("episode", sequence=[e.episode for e in episodes]),
    ]
    texts = [metrics_markdown(e, s) for e, s in zip(episodes, starts, strict=True)]
    send_columns(
        rec,
        "metrics/episode",
        idx,
        rr.TextDocument.columns(text=texts, media_type=["text/markdown"] * len(texts)),
    )
    rec.log(
        "metrics/summary",
        rr.TextDocument(summary_markdown(episodes, starts), media_type="text/markdown"),
        static=True,
    )
    keys = sorted({k for e in episodes for k, v in e.metrics.items() if finite(v) and k != "episode"})
    for k in keys:
        have = [e for e in episodes if finite(e.metrics.get(k))]
        order = np.argsort([e.episode for e in have])
        send_columns(
            rec,
            f"episode_metrics/{esc(k)}",
            [rr.TimeColumn("episode", sequence=[have[i].episode for i in order])],
            rr.Scalars.columns(scalars=[float(have[i].metrics[k]) for i in order]),
        )


def _log_extras(rec, episodes: list[Episode], starts: np.ndarray) -> None:
    """Optional per-step channels (``/eval/ball``, ``/eval/pelvis``, ...): their ``position`` as points."""
    rr = rerun_sdk()
    names = sorted({n for e in episodes for n in e.extras})
    for i, name in enumerate(names):
        times, pts, sizes = [], [], []
        for e, s in zip(episodes, starts, strict=True):
            for m in e.extras.get(name, []):
                p = (
                    np.asarray(m.get("position", []), dtype=np.float64).reshape(-1, 3)
                    if "position" in m
                    else None
                )
                if p is None or p.size == 0:
                    continue
                times.append(s + float(m["t"]))
                pts.append(p)
                sizes.append(len(p))
        if not times:
            continue
        color = [(30, 144, 255), (255, 165, 0), (160, 32, 240)][i % 3]
        rec.log(f"world/{esc(name)}", rr.Points3D.from_fields(colors=[color], radii=0.02), static=True)
        send_columns(
            rec,
            f"world/{esc(name)}",
            [time_column(times)],
            rr.Points3D.columns(positions=np.concatenate(pts)).partition(sizes),
        )
