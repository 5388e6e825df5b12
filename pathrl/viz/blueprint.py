"""Default layouts (Rerun blueprints) of the episodes and run recordings."""

from __future__ import annotations

import numpy as np

from pathrl.viz.reading import QUANTITIES, Episode, RobotInfo
from pathrl.viz.rrd import UNITS, esc, is_time_tag, tag_entity

__all__ = ["ACTIVE_TAB", "episodes_blueprint", "run_blueprint"]

ACTIVE_TAB = 0


def episodes_blueprint(robot: RobotInfo, episodes: list[Episode], timeline: str = "time"):
    """The Rerun blueprint of evaluation episodes: 3D view and metrics, progress and deviation plots, the episode table
    and one tab per joint (position ... jerk, within its limits); opens on `timeline`."""
    import rerun.blueprint as rrb

    def joint_view(j: int, name: str, q: str):
        axis = None
        if q in robot.limits:  # limits inside the plot, not on its border
            lo, hi = (float(x) for x in robot.limits[q][j])
            pad = 0.08 * (hi - lo) if hi > lo else 1.0
            axis = rrb.ScalarAxis(range=(lo - pad, hi + pad))
        return rrb.TimeSeriesView(
            origin=f"/joints/{esc(name)}/{q}",
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


def run_blueprint(tags: list[str], has_config: bool):
    """One tab per tag group (``Loss``, ``Train``, ``Perf``, ...) with a grid of plots; config beside it."""
    import rerun.blueprint as rrb

    groups: dict[str, list[str]] = {}
    for tag in tags:
        group = tag.split("/")[0] if "/" in tag else "other"
        groups.setdefault(group + (" (timeline train_time)" if is_time_tag(tag) else ""), []).append(tag)
    tabs = [
        rrb.Grid(*[rrb.TimeSeriesView(origin=tag_entity(t), name=t) for t in ts], name=g)
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
