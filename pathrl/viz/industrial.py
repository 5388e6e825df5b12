"""Rerun recordings (``.rrd``) of one industrial waypoint optimisation (``industrial.mcap``).

Reads the file :mod:`pathrl.industrial.record` writes (topics: :mod:`pathrl.logging.schema`, ``INDUSTRIAL_*``).
Positions are shown in metres (the file's mm / 1000), in the robot base frame (z up). Timeline ``iteration``
(sequence): execution k of the optimisation, 0 = the baseline profile.

Entities::

    /world/target                     target TCP path (green line strip), static
    /world/baseline                   executed path of the baseline profile (iteration 0, grey), static
    /world/best                       executed path of the best profile (blue), static
    /world/executed                   executed path of iteration k (red)
    /world/waypoints                  waypoints of iteration k (orange points)
    /world/robot_base                 the arm's base origin (point)
    /magnified/...                    the same paths with every deviation from the target scaled by the
                                      factor in the view's name (millimetre errors on a metre-long path)
    /error/max_mm, /error/mean_mm     max / mean position error of iteration k (mm), /error/spec the 0.5 mm spec
    /error/profile                    bar chart: max error along the target (mm, abscissa: target arc length mm)
    /summary                          markdown: target, method, error per iteration, best iteration
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pathrl.logging.mcap_io import iter_messages
from pathrl.logging.schema import (
    INDUSTRIAL_ERROR,
    INDUSTRIAL_EXECUTED,
    INDUSTRIAL_SUMMARY,
    INDUSTRIAL_TARGET,
    INDUSTRIAL_WAYPOINTS,
)
from pathrl.viz.reading import ViewError
from pathrl.viz.rrd import GREEN, GREY, RED, ConvertStats, removed_on_error, rerun_sdk, send_columns

__all__ = [
    "IndustrialRecording", "error_profile", "industrial_blueprint", "industrial_to_rrd", "magnified", "magnify_factor",
    "read_industrial", "summary_markdown",
]

MM = 1e-3  # the file's mm in the recording's metres
BLUE, ORANGE = (40, 110, 230), (255, 150, 30)
PROFILE_BINS = 200


@dataclass
class IndustrialRecording:
    """The content of an ``industrial.mcap``: target message and positions (n, 3) mm, per iteration k the
    waypoints (m, 3) mm, executed positions (N, 3) mm and error message, and the summary (None if absent)."""

    target: dict[str, Any]
    target_p: np.ndarray
    waypoints: dict[int, np.ndarray] = field(default_factory=dict)
    executed: dict[int, np.ndarray] = field(default_factory=dict)
    errors: dict[int, dict[str, Any]] = field(default_factory=dict)
    summary: dict[str, Any] | None = None

    @property
    def iterations(self) -> list[int]:
        """The recorded iterations, in order."""
        return sorted(self.executed)


def read_industrial(path: Path) -> IndustrialRecording:
    """Read an ``industrial.mcap`` (ViewError if its target or executions are missing or malformed)."""
    target = None
    parts: dict[str, dict[int, Any]] = {INDUSTRIAL_WAYPOINTS: {}, INDUSTRIAL_EXECUTED: {}, INDUSTRIAL_ERROR: {}}
    summary = None
    for topic, _, msg in iter_messages(path):
        if topic == INDUSTRIAL_TARGET:
            target = msg
        elif topic in parts:
            parts[topic][int(msg["iteration"])] = msg
        elif topic == INDUSTRIAL_SUMMARY:
            summary = msg
    if target is None:
        raise ViewError(f"{path}: no {INDUSTRIAL_TARGET} message")
    if not parts[INDUSTRIAL_EXECUTED]:
        raise ViewError(f"{path}: no {INDUSTRIAL_EXECUTED} messages")
    try:
        rec = IndustrialRecording(target, _points(target["positions"]), summary=summary)
        for k, m in parts[INDUSTRIAL_EXECUTED].items():
            rec.executed[k] = _points(m["positions"])
        for k, m in parts[INDUSTRIAL_WAYPOINTS].items():
            rec.waypoints[k] = _points(m["positions"])
        rec.errors = parts[INDUSTRIAL_ERROR]
    except (KeyError, TypeError, ValueError) as exc:
        raise ViewError(f"{path}: malformed industrial message ({exc})") from None
    return rec


def _points(x: Any) -> np.ndarray:
    p = np.asarray(x, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2:
        raise ValueError(f"expected positions (n >= 2, 3), got shape {p.shape}")
    return p


def magnify_factor(rec: IndustrialRecording, share: float = 0.05) -> float:
    """A round factor (1, 2, 5 x 10^k) that shows the largest deviation at about `share` of the target's size."""
    worst = max((float(e.get("max_pos_mm", 0.0)) for e in rec.errors.values()), default=0.0)
    size = float(np.linalg.norm(np.ptp(rec.target_p, axis=0)))
    if worst <= 0.0 or size <= 0.0:
        return 1.0
    raw = share * size / worst
    if raw <= 1.0:
        return 1.0
    exp = 10.0 ** np.floor(np.log10(raw))
    return float(max(m for m in (1.0, 2.0, 5.0) if m * exp <= raw) * exp)


def _on_target(target: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Target points (N, 3) at fractional indices u (N,)."""
    i0 = np.clip(np.floor(u).astype(int), 0, len(target) - 2)
    f = (u - i0)[:, None]
    return (1 - f) * target[i0] + f * target[i0 + 1]


def magnified(rec: IndustrialRecording, factor: float) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """Executed paths and waypoints per iteration with their deviation from the target scaled by `factor`:
    executed samples from their nearest target point (the file's ``target_index``), waypoint i from the target
    point it was sampled at (:func:`pathrl.industrial.trajectories.waypoint_indices`)."""
    from pathrl.industrial.trajectories import waypoint_indices

    ex = {}
    for k, p in rec.executed.items():
        u = rec.errors.get(k, {}).get("target_index")
        if u is None or len(u) != len(p):
            ex[k] = p
            continue
        base = _on_target(rec.target_p, np.asarray(u, dtype=np.float64))
        ex[k] = base + factor * (p - base)
    wp = {}
    for k, w in rec.waypoints.items():
        base = rec.target_p[waypoint_indices(len(rec.target_p), len(w))]
        wp[k] = base + factor * (w - base)
    return ex, wp


def error_profile(rec: IndustrialRecording, k: int, bins: int = PROFILE_BINS) -> tuple[np.ndarray, np.ndarray]:
    """(target arc length of each bin's centre (bins,) mm, max position error in the bin (bins,) mm) of
    iteration k; a bin no executed sample projects to is 0."""
    e = rec.errors[k]
    d = np.asarray(e["profile_mm"], dtype=np.float64)
    u = np.asarray(e["target_index"], dtype=np.float64)
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(rec.target_p, axis=0), axis=1))]
    arc = np.interp(u, np.arange(len(s)), s)
    edges = np.linspace(0.0, s[-1], bins + 1)
    idx = np.clip(np.searchsorted(edges, arc, side="right") - 1, 0, bins - 1)
    out = np.zeros(bins)
    np.maximum.at(out, idx, d)
    return (edges[:-1] + edges[1:]) / 2, out


def summary_markdown(rec: IndustrialRecording, src: Path) -> str:
    """Markdown summary of an industrial recording read from `src`: target, spec reached, best iteration, and per
    iteration its errors (mm, deg) and speed spread (%)."""
    t, s = rec.target, rec.summary or {}
    best = s.get("best_iteration")
    head = [f"### {t.get('name', '?')}: {t.get('method_name', t.get('method', '?'))}", "",
            f"`{src}`; pose {t.get('pose')}, Move{t.get('move', 'L')}, speed command {t.get('speed_mm_s', 0):.0f} mm/s"
            + (f", policy `{t['policy']}`" if t.get("policy") else ""), ""]
    if s:
        itr = s.get("iterations_to_spec")
        head += [f"0.5 mm spec: {'reached at iteration ' + str(itr) if itr is not None else 'not reached'}; "
                 f"best iteration {best}; {s.get('executions')} executions in {s.get('t_opt_s', 0.0):.2f} s", ""]
    rows = ["| iteration | max error (mm) | mean error (mm) | max ori. (deg) | speed std (%) |",
            "|---|---|---|---|---|"]
    nan = float("nan")
    for k in rec.iterations:
        e = rec.errors.get(k, {})
        mark = " (baseline)" if k == 0 else (" (best)" if k == best else "")
        rows.append(f"| {k}{mark} | {e.get('max_pos_mm', nan):.3f} | {e.get('mean_pos_mm', nan):.3f} "
                    f"| {e.get('max_ori_deg', nan):.2f} | {100 * e.get('speed_std_ratio', nan):.1f} |")
    return "\n".join(head + rows)


def industrial_to_rrd(src: Path, out: Path) -> ConvertStats:
    """Convert an ``industrial.mcap`` into the recording `out` (module doc)."""
    t0 = time.perf_counter()
    rec = read_industrial(src)
    factor = magnify_factor(rec)
    rr = rerun_sdk()
    stream = rr.RecordingStream("pathrl")
    tmp = out.with_name(out.name + ".tmp")
    stream.save(tmp, default_blueprint=industrial_blueprint(rec, factor))
    stream.send_recording_name(f"{src.parent.name}/{src.name}")
    with removed_on_error(tmp):
        for root in ("world", "magnified"):
            stream.log(root, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        stream.log("world/robot_base", rr.Points3D([[0.0, 0.0, 0.0]], radii=0.03, colors=[GREY],
                                                   labels=["IRB 6640 base"]), static=True)
        ex_mag, wp_mag = magnified(rec, factor)
        _log_paths(stream, "world", rec, rec.executed, rec.waypoints)
        _log_paths(stream, "magnified", rec, ex_mag, wp_mag)
        _log_errors(stream, rec)
        stream.log("summary", rr.TextDocument(summary_markdown(rec, src), media_type="text/markdown"), static=True)
        stream.flush()
        stream.disconnect()
        tmp.replace(out)  # inside: a failed rename (out is a directory) removes the temp file
    return ConvertStats(out, "industrial", len(rec.iterations), time.perf_counter() - t0, out.stat().st_size)


def _best(rec: IndustrialRecording) -> int:
    if rec.summary is not None and rec.summary.get("best_iteration") in rec.executed:
        return int(rec.summary["best_iteration"])
    return min(rec.iterations, key=lambda k: rec.errors.get(k, {}).get("max_pos_mm", np.inf))


def _log_paths(stream, root: str, rec: IndustrialRecording, executed: dict[int, np.ndarray],
               waypoints: dict[int, np.ndarray]) -> None:
    rr = rerun_sdk()
    its = rec.iterations
    stream.log(f"{root}/target", rr.LineStrips3D([rec.target_p * MM], colors=[GREEN], radii=0.002), static=True)
    stream.log(f"{root}/baseline", rr.LineStrips3D([executed[its[0]] * MM], colors=[GREY], radii=0.0015), static=True)
    stream.log(f"{root}/best", rr.LineStrips3D([executed[_best(rec)] * MM], colors=[BLUE], radii=0.0015), static=True)
    stream.log(f"{root}/executed", rr.LineStrips3D.from_fields(colors=[RED], radii=0.0025), static=True)
    send_columns(stream, f"{root}/executed", [rr.TimeColumn("iteration", sequence=its)],
                 rr.LineStrips3D.columns(strips=[executed[k] * MM for k in its]))
    have = sorted(waypoints)
    if have:
        stream.log(f"{root}/waypoints", rr.Points3D.from_fields(colors=[ORANGE], radii=0.0025), static=True)
        pts = np.concatenate([waypoints[k] for k in have]) * MM
        send_columns(stream, f"{root}/waypoints", [rr.TimeColumn("iteration", sequence=have)],
                     rr.Points3D.columns(positions=pts).partition([len(waypoints[k]) for k in have]))


def _log_errors(stream, rec: IndustrialRecording) -> None:
    rr = rerun_sdk()
    its = [k for k in rec.iterations if k in rec.errors]
    if not its:
        return
    spec = float((rec.summary or {}).get("spec_mm", 0.5))
    for key, name, color in (("max_pos_mm", "max error [mm]", RED), ("mean_pos_mm", "mean error [mm]", BLUE)):
        ent = f"error/{key.replace('_pos', '')}"
        stream.log(ent, rr.SeriesLines(names=name, colors=[color], widths=2.0), static=True)
        stream.log(ent, rr.SeriesPoints(names=name, colors=[color], markers="circle", marker_sizes=4.0), static=True)
        send_columns(stream, ent, [rr.TimeColumn("iteration", sequence=its)],
                     rr.Scalars.columns(scalars=[float(rec.errors[k][key]) for k in its]))
    stream.log("error/spec", rr.SeriesLines(names=f"spec {spec} mm", colors=[GREEN], widths=1.0), static=True)
    send_columns(stream, "error/spec", [rr.TimeColumn("iteration", sequence=[its[0], its[-1]])],
                 rr.Scalars.columns(scalars=[spec, spec]))
    for k in its:
        if "profile_mm" not in rec.errors[k] or "target_index" not in rec.errors[k]:
            continue
        stream.set_time("iteration", sequence=k)
        arc, err = error_profile(rec, k)
        stream.log("error/profile", rr.BarChart(err, abscissa=arc, color=RED))


def _eye(points: np.ndarray):
    """A camera above and in front of the path `points` (n, 3) m, looking at its centre."""
    import rerun.blueprint as rrb

    lo, hi = points.min(axis=0), points.max(axis=0)
    centre, size = (lo + hi) / 2, max(float(np.linalg.norm(hi - lo)), 0.1)
    direction = np.array([-0.35, -0.6, 1.0]) / np.linalg.norm([-0.35, -0.6, 1.0])
    return rrb.EyeControls3D(position=centre + 0.9 * size * direction, look_target=centre, eye_up=[0.0, 0.0, 1.0])


def industrial_blueprint(rec: IndustrialRecording, factor: float):
    """3D views (true scale, magnified) beside the error per iteration, the error profile and the summary."""
    import rerun.blueprint as rrb

    name = rec.target.get("name", "target")
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="/world", name=f"{name}: target (green), baseline (grey), best (blue), "
                                  "iteration (red), waypoints (orange)", eye_controls=_eye(rec.target_p * MM)),
                rrb.Spatial3DView(origin="/magnified", name=f"deviations from the target x{factor:g}",
                                  eye_controls=_eye(rec.target_p * MM)),
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="/error", contents=["/error/max_mm", "/error/mean_mm", "/error/spec"],
                                   name="position error per iteration [mm]"),
                rrb.BarChartView(origin="/error/profile", name="max error along the target [mm] vs arc length [mm]"),
                rrb.TextDocumentView(origin="/summary", name="summary"),
            ),
            column_shares=[3, 2],
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline="iteration", state="collapsed", play_state="following"),
    )
