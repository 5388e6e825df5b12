"""Rerun recordings (``.rrd``) of TrueAdapt adaptation episodes (``trueadapt.mcap``).

Reads the file :mod:`pathrl.eval.trueadapt_record` writes (topics: :mod:`pathrl.logging.schema`, ``TRUEADAPT_*``).
Timelines as in the episodes recording (:mod:`pathrl.viz.episodes`): ``time`` (s, the episodes back to back with
a gap of :data:`pathrl.viz.rrd.EPISODE_GAP_S`) and ``episode`` (sequence = the episode id; complete paths).

Entities::

    /world/<urdf robot name>/...       the robot (URDF, :mod:`pathrl.viz.urdf`) at the adapted joint positions
    /world/reference, /world/adapted   reference (green) and adapted (red, growing) TCP paths, line strips
    /world/reference_tcp, /world/tcp   the two TCPs now (points)
    /world/plate                       the plate (box) at the adapted pose
    /world/ball                        the ball (sphere; blue, red once the task has failed)
    /plate/...                         top view of the plate frame: edge, border (the on-plate failure line)
                                       and the ball (m)
    /joints/<joint>/reference|adapted  joint positions (rad)
    /deviation/max_rad                 max over joints of |q - q_ref| (rad)
    /ball/border                       max(|x| / h_x, |y| / h_y) of the ball (1 = the border)
    /metrics/episode, /metrics/summary markdown of the current / all episodes' outcome
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pathrl.logging.mcap_io import iter_messages
from pathrl.logging.schema import TRUEADAPT_EPISODE, TRUEADAPT_ROBOT, TRUEADAPT_STEP
from pathrl.viz.blueprint import _eye
from pathrl.viz.reading import Episode, RobotInfo, ViewError, _robot_info
from pathrl.viz.rrd import (
    EPISODE_GAP_S,
    GREEN,
    GREY,
    RED,
    ConvertStats,
    episode_starts,
    esc,
    removed_on_error,
    rerun_sdk,
    send_columns,
    time_column,
)
from pathrl.viz.urdf import log_joint_transforms, log_robot

__all__ = [
    "AdaptEpisode", "border_position", "outcome_markdown", "read_trueadapt", "trueadapt_blueprint", "trueadapt_to_rrd",
]

BLUE = (30, 144, 255)
STEP_FIELDS = ("reference", "position", "velocity", "acceleration", "reference_tcp", "tcp", "plate_quat_xyzw",
               "ball_xy", "ball_position", "ball_radius", "failed", "deviation")
PATH_ENTITIES = ("world", "world/reference", "world/adapted", "world/reference_tcp", "world/tcp", "world/plate",
                 "world/ball")


@dataclass
class AdaptEpisode:
    """One recorded episode: times t (S,) s, the step fields as arrays (S, ...) and its outcome message."""

    episode: int
    t: np.ndarray
    data: dict[str, np.ndarray]
    outcome: dict[str, Any] = field(default_factory=dict)

    def as_episode(self) -> Episode:
        """The :class:`pathrl.viz.reading.Episode` of the adapted motion (for the URDF animation)."""
        d = self.data
        return Episode(self.episode, self.t, d["position"], d["velocity"], d["acceleration"],
                       tcp=d["tcp"][:, None], ref_tcp=d["reference_tcp"][:, None])


def read_trueadapt(path: Path) -> tuple[RobotInfo, dict[str, Any], list[AdaptEpisode]]:
    """(robot, robot message, episodes sorted by id) of a ``trueadapt.mcap``; ViewError if it is incomplete."""
    robot_msg, steps, outcomes = None, {}, {}
    for topic, _, msg in iter_messages(path):
        if topic == TRUEADAPT_ROBOT:
            robot_msg = msg
        elif topic == TRUEADAPT_STEP:
            steps.setdefault(int(msg["episode"]), []).append(msg)
        elif topic == TRUEADAPT_EPISODE:
            outcomes[int(msg["episode"])] = msg
    if robot_msg is None:
        raise ViewError(f"{path}: no {TRUEADAPT_ROBOT} message")
    if not steps:
        raise ViewError(f"{path}: no {TRUEADAPT_STEP} messages")
    robot = _robot_info(path, robot_msg)
    episodes = []
    for ep in sorted(steps):
        rows = sorted(steps[ep], key=lambda m: m["step"])
        try:
            data = {k: np.array([m[k] for m in rows], dtype=np.float64) for k in STEP_FIELDS}
        except (KeyError, TypeError, ValueError) as exc:
            raise ViewError(f"{path}: episode {ep}: malformed {TRUEADAPT_STEP} message ({exc})") from None
        if data["position"].shape[1:] != (len(robot.joint_names),):
            raise ViewError(f"{path}: episode {ep}: {data['position'].shape[-1]} joints, robot has "
                            f"{len(robot.joint_names)}")
        episodes.append(AdaptEpisode(ep, np.array([m["t"] for m in rows], dtype=np.float64), data,
                                     outcomes.get(ep, {})))
    return robot, robot_msg, episodes


def trueadapt_to_rrd(src: Path, out: Path) -> ConvertStats:
    """Convert a ``trueadapt.mcap`` into the recording `out` (module doc)."""
    t0 = time.perf_counter()
    robot, robot_msg, episodes = read_trueadapt(src)
    notes: list[str] = []
    rr = rerun_sdk()
    rec = rr.RecordingStream("pathrl")
    tmp = out.with_name(out.name + ".tmp")
    rec.save(tmp, default_blueprint=trueadapt_blueprint(robot, episodes))
    rec.send_recording_name(f"{src.parent.name}/{src.name}")
    as_eps = [e.as_episode() for e in episodes]
    starts = episode_starts(as_eps)
    with removed_on_error(tmp), tempfile.TemporaryDirectory(prefix="pathrl-view-") as tdir:
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        tree = log_robot(rec, robot, Path(tdir), notes)
        if tree is not None:
            log_joint_transforms(rec, tree, robot, as_eps, starts, notes)
            for ent in PATH_ENTITIES:
                rec.log(ent, rr.CoordinateFrame(tree.root_link().name), static=True)
        _log_paths(rec, episodes, starts)
        _log_plate_and_ball(rec, robot_msg, episodes, starts)
        _log_series(rec, robot, robot_msg, episodes, starts)
        _log_outcomes(rec, src, robot_msg, episodes, starts)
        rec.flush()
        rec.disconnect()
        tmp.replace(out)  # inside: a failed rename (out is a directory) removes the temp file
    return ConvertStats(out, "trueadapt", len(episodes), time.perf_counter() - t0, out.stat().st_size, notes)


def _both_timelines(episodes: list[AdaptEpisode], starts: np.ndarray, at_end: bool) -> list:
    rr = rerun_sdk()
    times = [s + (e.t[-1] if at_end else e.t[0]) for e, s in zip(episodes, starts, strict=True)]
    return [time_column(times), rr.TimeColumn("episode", sequence=[e.episode for e in episodes])]


def _log_paths(rec, episodes: list[AdaptEpisode], starts: np.ndarray) -> None:
    rr = rerun_sdk()
    rec.log("world/reference", rr.LineStrips3D.from_fields(colors=[GREEN], radii=0.004), static=True)
    rec.log("world/adapted", rr.LineStrips3D.from_fields(colors=[RED], radii=0.004), static=True)
    rec.log("world/reference_tcp", rr.Points3D.from_fields(colors=[GREEN], radii=0.01), static=True)
    rec.log("world/tcp", rr.Points3D.from_fields(colors=[RED], radii=0.01), static=True)
    send_columns(rec, "world/reference", _both_timelines(episodes, starts, False),
                 rr.LineStrips3D.columns(strips=[e.data["reference_tcp"] for e in episodes]))
    trail = [e.data["tcp"][: max(k + 1, 2)] for e in episodes for k in range(len(e.t))]
    times = np.concatenate([s + e.t for e, s in zip(episodes, starts, strict=True)])
    send_columns(rec, "world/adapted", [time_column(times)], rr.LineStrips3D.columns(strips=trail))
    send_columns(rec, "world/adapted", _both_timelines(episodes, starts, True),
                 rr.LineStrips3D.columns(strips=[e.data["tcp"] for e in episodes]))
    for ent, key in (("world/reference_tcp", "reference_tcp"), ("world/tcp", "tcp")):
        send_columns(rec, ent, [time_column(times)],
                     rr.Points3D.columns(positions=np.concatenate([e.data[key] for e in episodes])))


def _log_plate_and_ball(rec, robot_msg: dict[str, Any], episodes: list[AdaptEpisode], starts: np.ndarray) -> None:
    rr = rerun_sdk()
    size = np.asarray(robot_msg.get("plate_size", [0.3393, 0.2715, 0.002]), dtype=np.float64)
    half = np.asarray(robot_msg.get("usable_half", size[:2] / 2), dtype=np.float64)
    times = np.concatenate([s + e.t for e, s in zip(episodes, starts, strict=True)])
    cat = {k: np.concatenate([e.data[k] for e in episodes]) for k in
           ("tcp", "plate_quat_xyzw", "ball_position", "ball_radius", "ball_xy", "failed")}
    quat = cat["plate_quat_xyzw"]
    centre = cat["tcp"] + _rotate(quat, np.array([0.0, 0.0, size[2] / 2]))
    rec.log("world/plate", rr.Boxes3D.from_fields(half_sizes=[size / 2], colors=[(200, 200, 210, 160)],
                                                  fill_mode="solid"), static=True)
    send_columns(rec, "world/plate", [time_column(times)],
                 rr.Boxes3D.columns(centers=centre, quaternions=quat))
    colors = np.where(cat["failed"][:, None] > 0.5, np.array(RED), np.array(BLUE)).astype(np.uint8)
    rec.log("world/ball", rr.Ellipsoids3D.from_fields(fill_mode="solid"), static=True)
    send_columns(rec, "world/ball", [time_column(times)],
                 rr.Ellipsoids3D.columns(centers=cat["ball_position"], colors=colors,
                                         half_sizes=np.repeat(cat["ball_radius"], 3).reshape(-1, 3)))
    edge, border = size[:2] / 2, half
    for ent, h, color in (("plate/edge", edge, GREY), ("plate/border", border, RED)):
        corners = np.array([[-h[0], -h[1]], [h[0], -h[1]], [h[0], h[1]], [-h[0], h[1]], [-h[0], -h[1]]])
        rec.log(ent, rr.LineStrips2D([corners], colors=[color], radii=0.002), static=True)
    top = cat["ball_xy"] * np.array([1.0, -1.0])  # a 2D view's y points down: plate +y is drawn up
    send_columns(rec, "plate/ball", [time_column(times)],
                 rr.Points2D.columns(positions=top, radii=cat["ball_radius"], colors=colors))


def _rotate(quat_xyzw: np.ndarray, v: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(quat_xyzw).apply(v)


def _gapped(episodes: list[AdaptEpisode], starts: np.ndarray,
            values: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Times and per-episode series concatenated with a NaN row between episodes (the plot line breaks there)."""
    ts, vs = [], []
    for i, (e, s, v) in enumerate(zip(episodes, starts, values, strict=True)):
        ts.append(s + e.t)
        vs.append(v)
        if i + 1 < len(episodes):
            ts.append(np.array([s + e.t[-1] + EPISODE_GAP_S / 2]))
            vs.append(np.full((1, *v.shape[1:]), np.nan))
    return np.concatenate(ts), np.concatenate(vs)


def border_position(ball_xy: np.ndarray, usable_half: np.ndarray) -> np.ndarray:
    """max(|x| / h_x, |y| / h_y) of ball positions (S, 2) in the plate frame: 1 on the on-plate failure border."""
    return (np.abs(ball_xy) / usable_half).max(axis=1)


def _log_series(rec, robot: RobotInfo, robot_msg: dict[str, Any], episodes: list[AdaptEpisode],
                starts: np.ndarray) -> None:
    rr = rerun_sdk()
    for key, label, color, width in (("reference", "reference", GREEN, 1.5), ("position", "adapted", RED, 3.0)):
        times, q = _gapped(episodes, starts, [e.data[key] for e in episodes])
        for j, name in enumerate(robot.joint_names):
            ent = f"joints/{esc(name)}/{label}"
            rec.log(ent, rr.SeriesLines(names=f"{name} {label} [rad]", colors=[color], widths=width), static=True)
            send_columns(rec, ent, [time_column(times)], rr.Scalars.columns(scalars=q[:, j]))
    half = np.asarray(robot_msg.get("usable_half", [1.0, 1.0]), dtype=np.float64)
    series = (("deviation/max_rad", "max |q - q_ref| [rad]", [e.data["deviation"] for e in episodes]),
              ("ball/border", "ball: max(|x|/h_x, |y|/h_y), 1 = border",
               [border_position(e.data["ball_xy"], half) for e in episodes]))
    for ent, label, values in series:
        rec.log(ent, rr.SeriesLines(names=label, colors=[BLUE]), static=True)
        times, v = _gapped(episodes, starts, values)
        send_columns(rec, ent, [time_column(times)], rr.Scalars.columns(scalars=v))
    rec.log("ball/border_line", rr.SeriesLines(names="border", colors=[RED], widths=1.0), static=True)
    t_end = float(starts[-1] + episodes[-1].t[-1])
    send_columns(rec, "ball/border_line", [time_column([float(starts[0]), t_end])],
                 rr.Scalars.columns(scalars=[1.0, 1.0]))


OUTCOME_COLS = ("trajectory", "steps", "success", "failed", "dev_terminated", "fraction", "acc", "jerk", "offset")


def outcome_markdown(episodes: list[AdaptEpisode], starts: np.ndarray, src: Path, mode: str) -> str:
    """All episodes' outcomes as a markdown table (the metrics of :mod:`pathrl.eval.trueadapt`)."""
    lines = [f"### TrueAdapt {mode}: `{src}`", "", "| episode | start [s] | " + " | ".join(OUTCOME_COLS) + " |",
             "|---" * (2 + len(OUTCOME_COLS)) + "|"]
    for e, s in zip(episodes, starts, strict=True):
        cells = [_fmt(e.outcome.get(c, "")) for c in OUTCOME_COLS]
        lines.append(f"| {e.episode} | {s + e.t[0]:.2f} | " + " | ".join(cells) + " |")
    ok = [e.outcome.get("success") for e in episodes if "success" in e.outcome]
    if ok:
        lines += ["", f"success: {sum(float(x) for x in ok):.0f} / {len(ok)}"]
    return "\n".join(lines)


def _fmt(v: Any) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _log_outcomes(rec, src: Path, robot_msg: dict[str, Any], episodes: list[AdaptEpisode],
                  starts: np.ndarray) -> None:
    rr = rerun_sdk()
    mode = str(robot_msg.get("mode", ""))
    rec.log("metrics/summary", rr.TextDocument(outcome_markdown(episodes, starts, src, mode),
                                               media_type="text/markdown"), static=True)
    texts = [f"### Episode {e.episode}\n\n" + "\n".join(f"- {c}: {_fmt(e.outcome[c])}" for c in OUTCOME_COLS
                                                         if c in e.outcome) for e in episodes]
    send_columns(rec, "metrics/episode", _both_timelines(episodes, starts, False),
                 rr.TextDocument.columns(text=texts, media_type=["text/markdown"] * len(texts)))


def trueadapt_blueprint(robot: RobotInfo, episodes: list[AdaptEpisode]):
    """3D scene and the plate's top view beside tabs: joints (reference vs adapted), ball and deviation, outcomes."""
    import rerun.blueprint as rrb

    joints = rrb.Grid(*[rrb.TimeSeriesView(origin=f"/joints/{esc(n)}", name=f"{n} [rad]") for n in robot.joint_names],
                      name="joints: reference (green) vs adapted (red)")
    task = rrb.Vertical(rrb.TimeSeriesView(origin="/ball", name="ball position relative to the border"),
                        rrb.TimeSeriesView(origin="/deviation", name="deviation from the reference [rad]"),
                        name="ball & deviation")
    table = rrb.Vertical(rrb.TextDocumentView(origin="/metrics/summary", name="episodes"),
                         rrb.TextDocumentView(origin="/metrics/episode", name="episode"), name="outcomes")
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="/world", name=f"{robot.name}: reference (green) vs adapted (red) TCP",
                                  eye_controls=_eye([e.as_episode() for e in episodes])),
                rrb.Spatial2DView(origin="/plate", name="ball on the plate (top view: +x right, +y up, m; "
                                  "red: border)"),
                row_shares=[3, 2],
            ),
            rrb.Tabs(joints, task, table),
            column_shares=[3, 2],
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline="time", state="collapsed", play_state="following"),
    )
