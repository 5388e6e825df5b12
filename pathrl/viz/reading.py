"""Reading pathrl MCAP files for the viewer: episodes (``episodes.mcap``) and training runs (``run.mcap``).

Topics and message layouts: :mod:`pathrl.logging.schema`. Also the series derived from an episode as the
viewer plots them (jerk, progress and deviation at equal arc length).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pathrl.logging.mcap_io import MCAP_MAGIC, is_finished, iter_messages
from pathrl.logging.schema import (
    EPISODE_TOPICS,
    EVAL_EPISODE_METRICS,
    EVAL_JOINT_STATE,
    EVAL_PREFIX,
    EVAL_REFERENCE,
    EVAL_ROBOT,
    EVAL_TCP,
    LIMIT_FIELDS,
    RUN_CONFIG,
    RUN_TOPICS,
    TRAIN_SCALARS,
)

__all__ = [
    "Episode", "MCAP_MAGIC", "QUANTITIES", "RobotInfo", "ViewError", "check_mcap", "finite", "is_finished", "jerk",
    "kind_of", "progress_and_deviation", "read_episodes", "read_run", "select_episodes",
]

QUANTITIES = ("position", "velocity", "acceleration", "jerk")


class ViewError(ValueError):
    """The input cannot be shown (not an MCAP, missing channels, bad selection)."""


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
    if TRAIN_SCALARS in topics or RUN_CONFIG in topics:
        return "run"
    found = ", ".join(sorted(topics)) or "none"
    if not is_finished(path):
        raise ViewError(f"{path}: truncated or damaged MCAP (it ends without the MCAP footer); readable "
                        f"channels: {found}")
    raise ViewError(
        f"{path}: no pathrl channels (need {' + '.join(EPISODE_TOPICS)} or {TRAIN_SCALARS}); found: {found}"
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
    """The robot of a recording: joint and path-joint names, limits per quantity (D, 2), URDF text and TCP links."""

    name: str
    joint_names: list[str]
    path_joints: list[str]
    limits: dict[str, np.ndarray]  # quantity -> (D, 2)
    urdf: str
    tcp_links: list[str]

    @property
    def path_index(self) -> np.ndarray:
        """Indices (M,) of the path joints among all joints."""
        return np.array([self.joint_names.index(j) for j in self.path_joints], dtype=np.int64)


@dataclass
class Episode:
    """One recorded episode: times (N,) s, joint position / velocity / acceleration (N, D), TCP positions (N, T, 3), the
    reference (arc length (R,), joints (R, M), TCPs (R, T, 3)), path name, metrics and extra topics."""

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
        if topic == EVAL_ROBOT:
            robot = _robot_info(path, msg)
        elif topic == EVAL_JOINT_STATE:
            states.setdefault(int(msg["episode"]), []).append(msg)
        elif topic == EVAL_TCP:
            tcps.setdefault(int(msg["episode"]), []).append(msg)
        elif topic == EVAL_REFERENCE:
            refs[int(msg["episode"])] = msg
        elif topic == EVAL_EPISODE_METRICS:
            metrics[int(msg["episode"])] = msg
        elif topic.startswith(EVAL_PREFIX) and isinstance(msg, dict) and "episode" in msg and "t" in msg:
            extras.setdefault(int(msg["episode"]), {}).setdefault(topic.removeprefix(EVAL_PREFIX), []).append(
                msg
            )
    if robot is None:
        raise ViewError(f"{path}: no {EVAL_ROBOT} message")
    if not states:
        raise ViewError(f"{path}: no {EVAL_JOINT_STATE} messages")
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
        for q, key in zip(QUANTITIES, LIMIT_FIELDS, strict=True):
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
        raise ViewError(f"{path}: malformed {EVAL_ROBOT} message ({exc})") from None


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
        scored = [e for e in episodes if finite(e.metrics.get("cart_pos_dev_mean_cm"))]
        if not scored:
            raise ViewError(f"--worst needs {EVAL_EPISODE_METRICS} with cart_pos_dev_mean_cm")
        return sorted(scored, key=lambda e: -float(e.metrics["cart_pos_dev_mean_cm"]))[:worst]
    return episodes


def finite(x: Any) -> bool:
    """True for a finite int or float (not a bool)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def read_run(path: Path) -> tuple[dict[str, Any] | None, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """(config message or None, {tag: (iterations, values)}) of a ``run.mcap``."""
    config = None
    rows: dict[str, dict[int, float]] = {}
    for topic, _, msg in iter_messages(path, RUN_TOPICS):
        if topic == RUN_CONFIG:
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
