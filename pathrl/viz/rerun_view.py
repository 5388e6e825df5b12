"""Rerun recordings (``.rrd``) of pathrl MCAP files: evaluation episodes and training runs.

Reads MCAP only (``episodes.mcap`` written by :func:`pathrl.eval.evaluate.write_episodes_mcap`, ``run.mcap``
written by :class:`pathrl.train.mcap_logger.McapLogWriter`); every ``rerun`` call of the project lives here.

Episodes recording (one recording per file, application id ``pathrl``), two timelines:

* ``time`` (seconds): the selected episodes back to back, episode k on
  ``[start_k, start_k + duration_k]`` with a gap of :data:`EPISODE_GAP_S` between episodes (the summary table
  lists every ``start_k``). Scrubbing it animates the robot and draws the plots.
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

import importlib.util
import math
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pathrl.logging.mcap_io import iter_messages

MCAP_MAGIC = b"\x89MCAP0\r\n"
EPISODE_TOPICS = ("/eval/robot", "/eval/joint_state")
RUN_TOPICS = ("/train/scalars", "/run/config")
KNOWN_EVAL = {"/eval/robot", "/eval/reference", "/eval/joint_state", "/eval/tcp", "/eval/episode_metrics"}
EPISODE_GAP_S = 0.5
ACTIVE_TAB = 0
QUANTITIES = ("position", "velocity", "acceleration", "jerk")
UNITS = {"position": "rad", "velocity": "rad/s", "acceleration": "rad/s²", "jerk": "rad/s³"}
MOVABLE = ("revolute", "continuous", "prismatic")
TCP_COLORS = ((230, 40, 40), (240, 110, 200), (255, 160, 40))
GREEN, RED, GREY = (40, 190, 70), (230, 40, 40), (140, 140, 140)


class ViewError(ValueError):
    """The input cannot be shown (not an MCAP, missing channels, bad selection)."""


# ------------------------------------------------------------------------------------------------ reading
def check_mcap(path: Path) -> None:
    """Raise ViewError unless `path` is an existing MCAP file."""
    if not path.exists():
        raise ViewError(f"no such file or directory: {path}")
    if not path.is_file():
        raise ViewError(f"not a file: {path}")
    with open(path, "rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise ViewError(f"{path}: not an MCAP file")


def kind_of(path: Path) -> str:
    """``"episodes"`` or ``"run"`` by the channels of an MCAP file."""
    check_mcap(path)
    topics = _topics(path)
    if all(t in topics for t in EPISODE_TOPICS):
        return "episodes"
    if "/train/scalars" in topics or "/run/config" in topics:
        return "run"
    found = ", ".join(sorted(topics)) or "none"
    raise ViewError(
        f"{path}: no pathrl channels (need {' + '.join(EPISODE_TOPICS)} or /train/scalars); found: {found}"
    )


def _topics(path: Path) -> set[str]:
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        if summary is not None and summary.channels:
            return {c.topic for c in summary.channels.values()}
    except Exception:  # unfinished file: scan it
        pass
    return {t for t, _, _ in iter_messages(path)}


@dataclass
class RobotInfo:
    name: str
    joint_names: list[str]
    path_joints: list[str]
    limits: dict[str, np.ndarray]  # quantity -> (D, 2)
    urdf: str
    tcp_links: list[str]

    @property
    def path_index(self) -> np.ndarray:
        return np.array([self.joint_names.index(j) for j in self.path_joints], dtype=np.int64)


@dataclass
class Episode:
    episode: int
    t: np.ndarray  # (N,) s
    q: np.ndarray  # (N, D)
    v: np.ndarray
    a: np.ndarray
    tcp: np.ndarray | None = None  # (N, T, 3)
    ref_s: np.ndarray | None = None  # (R,)
    ref_q: np.ndarray | None = None  # (R, M)
    ref_tcp: np.ndarray | None = None  # (R, T, 3)
    path: str = ""
    metrics: dict[str, Any] = field(default_factory=dict)
    extras: dict[str, list[dict[str, Any]]] = field(default_factory=dict)


def read_episodes(path: Path) -> tuple[RobotInfo, list[Episode]]:
    """Robot description and all episodes (sorted by id) of an ``episodes.mcap``."""
    robot: RobotInfo | None = None
    states: dict[int, list[dict]] = {}
    tcps: dict[int, list[dict]] = {}
    refs: dict[int, dict] = {}
    metrics: dict[int, dict] = {}
    extras: dict[int, dict[str, list[dict]]] = {}
    for topic, _, msg in iter_messages(path):
        if topic == "/eval/robot":
            robot = _robot_info(path, msg)
        elif topic == "/eval/joint_state":
            states.setdefault(int(msg["episode"]), []).append(msg)
        elif topic == "/eval/tcp":
            tcps.setdefault(int(msg["episode"]), []).append(msg)
        elif topic == "/eval/reference":
            refs[int(msg["episode"])] = msg
        elif topic == "/eval/episode_metrics":
            metrics[int(msg["episode"])] = msg
        elif topic.startswith("/eval/") and isinstance(msg, dict) and "episode" in msg and "t" in msg:
            extras.setdefault(int(msg["episode"]), {}).setdefault(topic.removeprefix("/eval/"), []).append(
                msg
            )
    if robot is None:
        raise ViewError(f"{path}: no /eval/robot message")
    if not states:
        raise ViewError(f"{path}: no /eval/joint_state messages")
    episodes = []
    for ep in sorted(states):
        rows = sorted(states[ep], key=lambda m: m["t"])
        e = Episode(
            ep,
            np.array([m["t"] for m in rows], dtype=np.float64),
            *(
                np.array([m[k] for m in rows], dtype=np.float64)
                for k in ("position", "velocity", "acceleration")
            ),
        )
        if e.q.ndim != 2 or e.q.shape[1] != len(robot.joint_names):
            raise ViewError(
                f"{path}: episode {ep}: joint_state has {e.q.shape[-1]} joints, "
                f"robot has {len(robot.joint_names)}"
            )
        if ep in tcps and len(tcps[ep]) == len(rows):
            e.tcp = np.array(
                [m["position"] for m in sorted(tcps[ep], key=lambda m: m["t"])], dtype=np.float64
            )
        if ep in refs:
            r = refs[ep]
            e.ref_s = np.asarray(r["s"], dtype=np.float64)
            e.ref_q = np.asarray(r["position"], dtype=np.float64)
            e.ref_tcp = np.asarray(r["tcp_position"], dtype=np.float64)
            e.path = str(r.get("path", ""))
        e.metrics = metrics.get(ep, {})
        e.path = e.path or str(e.metrics.get("path", ""))
        e.extras = extras.get(ep, {})
        episodes.append(e)
    return robot, episodes


def _robot_info(path: Path, msg: dict) -> RobotInfo:
    try:
        names = [str(j) for j in msg["joint_names"]]
        d = len(names)
        limits = {}
        for q, key in zip(
            QUANTITIES,
            ("position_limits", "velocity_limits", "acceleration_limits", "jerk_limits"),
            strict=True,
        ):
            if key in msg:
                arr = np.asarray(msg[key], dtype=np.float64)
                if arr.shape != (d, 2):
                    raise ValueError(f"{key} has shape {arr.shape}, expected ({d}, 2)")
                limits[q] = arr
        return RobotInfo(
            str(msg.get("robot", "robot")),
            names,
            [str(j) for j in msg.get("path_joints", names)],
            limits,
            str(msg.get("urdf", "")),
            [str(t) for t in msg.get("tcp_links", [])],
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise ViewError(f"{path}: malformed /eval/robot message ({exc})") from None


def select_episodes(
    episodes: list[Episode], ids: Sequence[int] | None = None, worst: int | None = None
) -> list[Episode]:
    """`ids` in the given order, or the `worst` episodes by ``cart_pos_dev_mean_cm`` (worst first), or all."""
    if ids is not None:
        by_id = {e.episode: e for e in episodes}
        missing = [i for i in ids if i not in by_id]
        if missing:
            lo, hi = min(by_id), max(by_id)
            raise ViewError(
                f"episodes not in the file: {', '.join(map(str, missing))} "
                f"(it has {len(by_id)} episodes, ids {lo}..{hi})"
            )
        return [by_id[i] for i in ids]
    if worst is not None:
        scored = [e for e in episodes if _finite(e.metrics.get("cart_pos_dev_mean_cm"))]
        if not scored:
            raise ViewError("--worst needs /eval/episode_metrics with cart_pos_dev_mean_cm")
        return sorted(scored, key=lambda e: -float(e.metrics["cart_pos_dev_mean_cm"]))[:worst]
    return episodes


def _finite(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def read_run(path: Path) -> tuple[dict[str, Any] | None, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """(config message or None, {tag: (iterations, values)}) of a ``run.mcap``."""
    config = None
    rows: dict[str, dict[int, float]] = {}
    for topic, _, msg in iter_messages(path, RUN_TOPICS):
        if topic == "/run/config":
            config = msg
        elif isinstance(msg, dict) and "iteration" in msg:
            it = int(msg["iteration"])
            for tag, val in (msg.get("values") or {}).items():
                if isinstance(val, (int, float)) and not isinstance(val, bool):
                    rows.setdefault(str(tag), {})[it] = float(val)
    curves = {
        tag: (np.array(sorted(d), dtype=np.int64), np.array([d[i] for i in sorted(d)], dtype=np.float64))
        for tag, d in sorted(rows.items())
    }
    return config, curves


# ------------------------------------------------------------------------------------------ derived data
def jerk(a: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Finite difference of decision-step accelerations: (N-1, D) at t[1:]."""
    dt = np.diff(t)[:, None]
    return np.diff(a, axis=0) / np.where(dt > 0, dt, np.nan)


def progress_and_deviation(e: Episode, robot: RobotInfo) -> dict[str, np.ndarray]:
    """Executed joint-space arc length vs the reference at equal arc length (the metrics' definition).

    Progress = executed arc length / reference arc length, capped at 1 (the reference lookup is clamped at
    the segment end, as in :mod:`pathrl.eval.metrics`). Reference TCPs between the 200 logged samples are
    interpolated linearly. Returns fraction (N,), joint_rad (N,), reference_tcp (N, T, 3) and cartesian_cm
    (N, T) when the file has TCPs.
    """
    if e.ref_s is None or e.ref_q is None or len(e.ref_s) < 2:
        return {}
    qp = e.q[:, robot.path_index]
    s_exec = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(qp, axis=0), axis=1))])
    s0, s1 = float(e.ref_s[0]), float(e.ref_s[-1])
    s_ref = np.clip(s0 + s_exec, s0, s1)
    out = {"fraction": np.minimum(s_exec / max(s1 - s0, 1e-12), 1.0)}
    q_ref = np.stack([np.interp(s_ref, e.ref_s, e.ref_q[:, j]) for j in range(e.ref_q.shape[1])], axis=1)
    out["joint_rad"] = np.linalg.norm(qp - q_ref, axis=1)
    if e.ref_tcp is not None and e.ref_tcp.ndim == 3:
        r = e.ref_tcp
        tcp_ref = np.stack(
            [[np.interp(s_ref, e.ref_s, r[:, k, c]) for c in range(3)] for k in range(r.shape[1])]
        )
        out["reference_tcp"] = tcp_ref.transpose(2, 0, 1)  # (N, T, 3)
        if e.tcp is not None and e.tcp.shape[1:] == r.shape[1:]:
            out["cartesian_cm"] = 100.0 * np.linalg.norm(e.tcp - out["reference_tcp"], axis=2)
    return out


# ---------------------------------------------------------------------------------------------- URDF
def resolve_urdf(robot: RobotInfo) -> Path | None:
    """The URDF named in the file, or (written on another machine) the one of the conf robot of that name."""
    if robot.urdf and Path(robot.urdf).is_file():
        return Path(robot.urdf)
    try:
        from pathrl.robot.model import load_robot_by_name

        return load_robot_by_name(robot.name).urdf
    except Exception:
        return None


_VEC_ATTR = re.compile(r'\b(xyz|rpy)="([^"]*)"')
_FILENAME = re.compile(r'filename="([^"]*)"')


def sanitize_urdf(urdf: Path, out_dir: Path) -> Path:
    """A copy of `urdf` that Rerun's loader accepts: comma-free vectors, absolute mesh paths.

    ``armar6*.urdf`` has ``rpy="a, b c"`` (Rerun: "Wrong vector element count"); ``package://<pkg>/`` is
    rewritten to the installed Python package ``<pkg>`` and relative mesh names to the URDF's directory.
    Returns `urdf` itself when nothing needs changing.
    """
    text = urdf.read_text()

    def vec(m: re.Match) -> str:
        return f'{m[1]}="{" ".join(m[2].replace(",", " ").split())}"'

    def mesh(m: re.Match) -> str:
        name = m[1]
        if name.startswith("package://"):
            pkg, _, rest = name.removeprefix("package://").partition("/")
            spec = importlib.util.find_spec(pkg)
            if spec is None or not spec.submodule_search_locations:
                return m[0]
            return f'filename="{Path(next(iter(spec.submodule_search_locations))) / rest}"'
        if "://" in name or Path(name).is_absolute():
            return m[0]
        return f'filename="{(urdf.parent / name).resolve()}"'

    fixed = _FILENAME.sub(mesh, _VEC_ATTR.sub(vec, text))
    if fixed == text:
        return urdf
    out = out_dir / urdf.name
    out.write_text(fixed)
    return out


# ---------------------------------------------------------------------------------------------- writing
@dataclass
class ConvertStats:
    out: Path
    kind: str
    items: int  # episodes or scalar tags
    seconds: float
    bytes: int
    warnings: list[str] = field(default_factory=list)


def _rr():
    import rerun as rr

    return rr


def _send(rec, entity: str, indexes: list, columns) -> None:
    rec.send_columns(entity, indexes=indexes, columns=columns, strict=True)


def _time_column(seconds: Any):
    """The ``time`` index (seconds rounded to whole nanoseconds, so 4.1 s is 4_100_000_000 ns)."""
    ns = np.round(np.asarray(seconds, dtype=np.float64) * 1e9).astype("timedelta64[ns]")
    return _rr().TimeColumn("time", duration=ns)


def _esc(part: str) -> str:
    return _rr().escape_entity_path_part(part)


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
    rr = _rr()
    rec = rr.RecordingStream("pathrl")
    tmp = out.with_name(out.name + ".tmp")
    rec.save(tmp, default_blueprint=_episodes_blueprint(robot, chosen, timeline))
    rec.send_recording_name(f"{src.parent.name}/{src.name}")
    with _removed_on_error(tmp), tempfile.TemporaryDirectory(prefix="pathrl-view-") as tdir:
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rec.log(
            "metrics/source",
            rr.TextDocument(
                f"`{src}`: robot **{robot.name}**, {len(episodes)} episodes in the file, {len(chosen)} shown",
                media_type="text/markdown",
            ),
            static=True,
        )
        starts = _episode_starts(chosen)
        tree = _log_robot(rec, robot, Path(tdir), notes)
        if tree is not None:
            _log_joint_transforms(rec, tree, robot, chosen, starts, notes)
            _anchor_to_robot_base(rec, tree.root_link().name, chosen)
        derived = [progress_and_deviation(e, robot) for e in chosen]
        _log_paths(rec, chosen, starts, derived)
        _log_series(rec, robot, chosen, starts, derived)
        _log_metrics(rec, chosen, starts)
        _log_extras(rec, chosen, starts)
        rec.flush()
        rec.disconnect()
    tmp.replace(out)
    return ConvertStats(out, "episodes", len(chosen), time.perf_counter() - t0, out.stat().st_size, notes)


@contextmanager
def _removed_on_error(path: Path):
    try:
        yield
    except BaseException:
        path.unlink(missing_ok=True)
        raise


def _episode_starts(episodes: list[Episode]) -> np.ndarray:
    starts, t = [], 0.0
    for e in episodes:
        starts.append(t - float(e.t[0]))
        t += float(e.t[-1] - e.t[0]) + EPISODE_GAP_S
    return np.array(starts)


def _times(episodes: list[Episode], starts: np.ndarray) -> np.ndarray:
    return np.concatenate([s + e.t for e, s in zip(episodes, starts, strict=True)])


def _log_robot(rec, robot: RobotInfo, tdir: Path, notes: list[str]):
    """URDF visual geometry (static) and the fixed joints' transforms (static, ``/world/fixed_transforms``).

    The movable joints are logged only temporally (``/world/joint_transforms``): a frame must be defined by
    one entity, so the loader's static zero-pose joint transforms are not sent.
    """
    rr = _rr()
    urdf = resolve_urdf(robot)
    if urdf is None:
        notes.append(f"URDF {robot.urdf!r} not found and no conf robot {robot.name!r}: robot model not shown")
        return None
    try:
        tree = rr.urdf.UrdfTree.from_file_path(sanitize_urdf(urdf, tdir), "world")
        chunks = [
            c
            for c in tree.stream(include_joint_transforms=False).to_chunks()
            if "/collision_geometries/" not in str(c.entity_path)
        ]
    except Exception as exc:  # a URDF Rerun cannot load: show the rest
        notes.append(f"{urdf}: Rerun could not load the URDF ({str(exc).splitlines()[0]}); robot not shown")
        return None
    rec.send_chunks(chunks)
    for joint in tree.joints():  # one static entity per fixed joint (a static entity keeps one row)
        if joint.joint_type not in MOVABLE:
            rec.log(
                f"world/fixed_transforms/{_esc(joint.name)}",
                joint.compute_transform(0.0, clamp=False),
                static=True,
            )
    return tree


def _log_joint_transforms(
    rec, tree, robot: RobotInfo, episodes: list[Episode], starts: np.ndarray, notes: list[str]
) -> None:
    """All movable joints: the logged ones per step, the others (e.g. fingers) at 0 from the first instant."""
    rr = _rr()
    time_idx = [_time_column(_times(episodes, starts))]
    ends = np.array([s + e.t[-1] for e, s in zip(episodes, starts, strict=True)])
    ep_idx = [_time_column(ends), rr.TimeColumn("episode", sequence=[e.episode for e in episodes])]
    q_all = np.concatenate([e.q for e in episodes])
    q_final = np.array([e.q[-1] for e in episodes])
    col = {name: j for j, name in enumerate(robot.joint_names)}
    for joint in tree.joints():
        if joint.joint_type not in MOVABLE:
            continue
        if joint.name in col:
            j = col[joint.name]
            _send(
                rec,
                "world/joint_transforms",
                time_idx,
                joint.compute_transform_columns(q_all[:, j], clamp=False),
            )
            _send(
                rec,
                "world/joint_transforms",
                ep_idx,
                joint.compute_transform_columns(q_final[:, j], clamp=False),
            )
        else:
            _send(
                rec,
                "world/joint_transforms",
                [
                    _time_column([starts[0] + episodes[0].t[0]]),
                    rr.TimeColumn("episode", sequence=[episodes[0].episode]),
                ],
                joint.compute_transform_columns([0.0], clamp=False),
            )
    missing = [n for n in robot.joint_names if tree.get_joint_by_name(n) is None]
    if missing:
        notes.append(f"joints not in the URDF (not animated): {', '.join(missing)}")


def _anchor_to_robot_base(rec, root_frame: str, episodes: list[Episode]) -> None:
    """Put /world and the path entities in the URDF root link frame (the frame of all logged positions)."""
    rr = _rr()
    extras = sorted({n for e in episodes for n in e.extras})
    for ent in [
        "world",
        "world/reference",
        "world/executed",
        "world/tcp",
        "world/reference_point",
        *(f"world/{_esc(n)}" for n in extras),
    ]:
        rec.log(ent, rr.CoordinateFrame(root_frame), static=True)


def _strip_columns(strips: list[np.ndarray], per_row: int, **kw):
    rr = _rr()
    cols = rr.LineStrips3D.columns(strips=strips, **kw)
    return cols.partition([per_row] * (len(strips) // per_row)) if per_row != 1 else cols


def _log_paths(
    rec, episodes: list[Episode], starts: np.ndarray, derived: list[dict[str, np.ndarray]]
) -> None:
    rr = _rr()
    rec.log("world/reference", rr.LineStrips3D.from_fields(colors=[GREEN], radii=0.006), static=True)
    rec.log("world/executed", rr.LineStrips3D.from_fields(colors=[RED], radii=0.006), static=True)
    rec.log("world/tcp", rr.Points3D.from_fields(colors=[RED], radii=0.012), static=True)
    rec.log("world/reference_point", rr.Points3D.from_fields(colors=[GREEN], radii=0.009), static=True)
    with_ref = [(e, s) for e, s in zip(episodes, starts, strict=True) if e.ref_tcp is not None]
    if with_ref:
        n_tcp = with_ref[0][0].ref_tcp.shape[1]
        strips = [e.ref_tcp[:, k] for e, _ in with_ref for k in range(n_tcp)]
        _send(
            rec,
            "world/reference",
            [
                _time_column([s + e.t[0] for e, s in with_ref]),
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
    _send(rec, "world/executed", [_time_column(times)], _strip_columns(trail, n_tcp))
    full = [e.tcp[:, i] for e, _ in with_tcp for i in range(n_tcp)]
    _send(
        rec,
        "world/executed",
        [
            _time_column([s + e.t[-1] for e, s in with_tcp]),
            rr.TimeColumn("episode", sequence=[e.episode for e, _ in with_tcp]),
        ],
        _strip_columns(full, n_tcp),
    )
    pts = np.concatenate([e.tcp for e, _ in with_tcp])
    _send(
        rec,
        "world/tcp",
        [_time_column(times)],
        rr.Points3D.columns(positions=pts.reshape(-1, 3)).partition([n_tcp] * len(pts)),
    )
    with_ref_pt = [
        (e, s, d) for e, s, d in zip(episodes, starts, derived, strict=True) if "reference_tcp" in d
    ]
    if with_ref_pt:
        ref_pts = np.concatenate([d["reference_tcp"] for _, _, d in with_ref_pt])
        _send(
            rec,
            "world/reference_point",
            [_time_column(np.concatenate([s + e.t for e, s, _ in with_ref_pt]))],
            rr.Points3D.columns(positions=ref_pts.reshape(-1, 3)).partition(
                [ref_pts.shape[1]] * len(ref_pts)
            ),
        )


def _scalar_series(rec, entity: str, times: np.ndarray, values: np.ndarray) -> None:
    rr = _rr()
    _send(rec, entity, [_time_column(times)], rr.Scalars.columns(scalars=values))


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
    rr = _rr()
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
            ent = f"joints/{_esc(name)}/{q}"
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
                _send(
                    rec,
                    f"{ent}/limits",
                    [_time_column([t_begin, t_end])],
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
            ent = f"deviation/cartesian_cm/{_esc(links[k] if k < len(links) else f'tcp{k}')}"
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
    cols = [c for c in SUMMARY_COLS if any(c in e.metrics for e in episodes)]
    lines = ["| episode | path | start [s] | " + " | ".join(cols) + " |", "|---" * (3 + len(cols)) + "|"]
    for e, s in zip(episodes, starts, strict=True):
        vals = [_fmt(e.metrics.get(c, "")) for c in cols]
        lines.append(f"| {e.episode} | {e.path} | {s + e.t[0]:.2f} | " + " | ".join(vals) + " |")
    return "### Episodes on the `time` timeline\n\n" + "\n".join(lines)


def _log_metrics(rec, episodes: list[Episode], starts: np.ndarray) -> None:
    rr = _rr()
    idx = [
        _time_column([s + e.t[0] for e, s in zip(episodes, starts, strict=True)]),
        rr.TimeColumn("episode", sequence=[e.episode for e in episodes]),
    ]
    texts = [metrics_markdown(e, s) for e, s in zip(episodes, starts, strict=True)]
    _send(
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
    keys = sorted({k for e in episodes for k, v in e.metrics.items() if _finite(v) and k != "episode"})
    for k in keys:
        have = [e for e in episodes if _finite(e.metrics.get(k))]
        order = np.argsort([e.episode for e in have])
        _send(
            rec,
            f"episode_metrics/{_esc(k)}",
            [rr.TimeColumn("episode", sequence=[have[i].episode for i in order])],
            rr.Scalars.columns(scalars=[float(have[i].metrics[k]) for i in order]),
        )


def _log_extras(rec, episodes: list[Episode], starts: np.ndarray) -> None:
    """Optional per-step channels (``/eval/ball``, ``/eval/pelvis``, ...): their ``position`` as points."""
    rr = _rr()
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
        rec.log(f"world/{_esc(name)}", rr.Points3D.from_fields(colors=[color], radii=0.02), static=True)
        _send(
            rec,
            f"world/{_esc(name)}",
            [_time_column(times)],
            rr.Points3D.columns(positions=np.concatenate(pts)).partition(sizes),
        )


def _episodes_blueprint(robot: RobotInfo, episodes: list[Episode], timeline: str = "time"):
    import rerun.blueprint as rrb

    def joint_view(j: int, name: str, q: str):
        axis = None
        if q in robot.limits:  # limits inside the plot, not on its border
            lo, hi = (float(x) for x in robot.limits[q][j])
            pad = 0.08 * (hi - lo) if hi > lo else 1.0
            axis = rrb.ScalarAxis(range=(lo - pad, hi + pad))
        return rrb.TimeSeriesView(
            origin=f"/joints/{_esc(name)}/{q}",
            name=f"{name} {q} [{UNITS[q]}]",
            axis_y=axis,
            plot_legend=rrb.PlotLegend(visible=False),
        )

    joint_tabs = [
        rrb.Vertical(*[joint_view(j, name, q) for q in QUANTITIES], name=name)
        for j, name in enumerate(robot.joint_names)
    ]
    overview = rrb.Vertical(
        rrb.TimeSeriesView(origin="/deviation/cartesian_cm", name="TCP deviation at equal arc length [cm]"),
        rrb.TimeSeriesView(origin="/deviation/joint_rad", name="joint deviation at equal arc length [rad]"),
        rrb.TimeSeriesView(
            origin="/progress",
            name="path progress (fraction of the reference arc length)",
            axis_y=rrb.ScalarAxis(range=(0.0, 1.05)),
        ),
        name="progress & deviation",
    )
    table = rrb.Vertical(
        rrb.TextDocumentView(origin="/metrics/summary", name="episodes"),
        rrb.TimeSeriesView(origin="/episode_metrics", name="metrics per episode (timeline: episode)"),
        name="episodes",
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(
                    origin="/world",
                    name=f"{robot.name}: reference (green) vs executed (red)",
                    eye_controls=_eye(episodes),
                ),
                rrb.TextDocumentView(origin="/metrics/episode", name="episode metrics"),
                row_shares=[5, 3],
            ),
            rrb.Tabs(overview, *joint_tabs, table, active_tab=ACTIVE_TAB),
            column_shares=[3, 2],
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=timeline, state="collapsed", play_state="following"),
    )


def _eye(episodes: list[Episode]):
    """A camera looking at the robot base and all TCP paths from the front right, slightly above."""
    import rerun.blueprint as rrb

    pts = [np.zeros((1, 3))]
    for e in episodes:
        for arr in (e.tcp, e.ref_tcp):
            if arr is not None:
                pts.append(arr.reshape(-1, 3))
    pts = np.concatenate(pts)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    hi[2] = max(hi[2] + 0.25, 1.0)  # the robot reaches above its TCP paths
    target = (lo + hi) / 2
    size = float(np.linalg.norm(hi - lo))
    direction = np.array([1.0, -1.3, 0.55]) / np.linalg.norm([1.0, -1.3, 0.55])
    return rrb.EyeControls3D(
        position=target + direction * max(0.8 * size, 1.0), look_target=target, eye_up=[0.0, 0.0, 1.0]
    )


def run_to_rrd(src: Path, out: Path) -> ConvertStats:
    """Convert the training curves (and config) of a ``run.mcap`` into the recording `out`.

    Tags ending in ``/time`` (RSL-RL's ``Train/mean_reward/time``: step = elapsed seconds) go on the
    ``train_time`` timeline (seconds), every other tag on ``iteration``.
    """
    t0 = time.perf_counter()
    config, curves = read_run(src)
    if not curves and config is None:
        raise ViewError(f"{src}: no /train/scalars or /run/config messages")
    rr = _rr()
    rec = rr.RecordingStream("pathrl")
    tmp = out.with_name(out.name + ".tmp")
    rec.save(tmp, default_blueprint=_run_blueprint(list(curves), config is not None))
    rec.send_recording_name(f"{src.parent.name}/{src.name}")
    with _removed_on_error(tmp):
        for tag, (its, vals) in curves.items():
            ent = _tag_entity(tag)
            rec.log(ent, rr.SeriesLines(names=tag), static=True)
            index = (
                rr.TimeColumn("train_time", duration=its.astype(np.float64))
                if _is_time_tag(tag)
                else rr.TimeColumn("iteration", sequence=its)
            )
            _send(rec, ent, [index], rr.Scalars.columns(scalars=vals))
        if config is not None:
            rec.log(
                "training/config",
                rr.TextDocument(_config_markdown(config), media_type="text/markdown"),
                static=True,
            )
        rec.flush()
        rec.disconnect()
    tmp.replace(out)
    return ConvertStats(out, "run", len(curves), time.perf_counter() - t0, out.stat().st_size)


def _is_time_tag(tag: str) -> bool:
    return tag.endswith("/time")


def _tag_entity(tag: str) -> str:
    return "training/" + "/".join(_esc(p) for p in tag.split("/") if p)


def _config_markdown(config: Any) -> str:
    import yaml

    body = (
        yaml.safe_dump(config, sort_keys=False, default_flow_style=False)
        if isinstance(config, dict)
        else str(config)
    )
    return f"### Run config\n\n```yaml\n{body}```\n"


def _run_blueprint(tags: list[str], has_config: bool):
    """One tab per tag group (``Loss``, ``Train``, ``Perf``, ...) with a grid of plots; config beside it."""
    import rerun.blueprint as rrb

    groups: dict[str, list[str]] = {}
    for tag in tags:
        group = tag.split("/")[0] if "/" in tag else "other"
        groups.setdefault(group + (" (timeline train_time)" if _is_time_tag(tag) else ""), []).append(tag)
    tabs = [
        rrb.Grid(*[rrb.TimeSeriesView(origin=_tag_entity(t), name=t) for t in ts], name=g)
        for g, ts in groups.items()
    ]
    parts = []
    if tabs:
        parts.append(rrb.Tabs(*tabs, name="training curves"))
    if has_config:
        parts.append(rrb.TextDocumentView(origin="/training/config", name="config"))
    layout = rrb.Horizontal(*parts, column_shares=[3, 1]) if len(parts) == 2 else parts[0]
    return rrb.Blueprint(
        layout,
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline="iteration", state="collapsed", play_state="following"),
    )


# --------------------------------------------------------------------------------------------- viewer
def rerun_command() -> list[str]:
    """The bundled ``rerun`` CLI (next to the interpreter, else ``python -m rerun``)."""
    exe = Path(sys.executable).with_name("rerun")
    if exe.is_file():
        return [str(exe)]
    found = shutil.which("rerun")
    return [found] if found else [sys.executable, "-m", "rerun"]


def spawn_viewer(files: Iterable[Path]) -> subprocess.Popen:
    """Open the native viewer on `files` (detached)."""
    return subprocess.Popen([*rerun_command(), *map(str, files)], start_new_session=True)


def serve_web(files: Iterable[Path], port: int = 9090) -> int:
    """Serve `files` in Rerun's web viewer (blocks until interrupted); returns the viewer's exit code."""
    try:
        return subprocess.call(
            [*rerun_command(), "--serve-web", "--web-viewer-port", str(port), *map(str, files)]
        )
    except KeyboardInterrupt:  # the normal way to stop serving
        return 0
