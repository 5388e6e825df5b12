"""The robot model in a recording: the URDF (found, cleaned up for Rerun's loader), its fixed joints and the
movable joints' transforms over the episodes."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import numpy as np

from pathrl.viz.reading import Episode, RobotInfo
from pathrl.viz.rrd import episode_times, esc, rerun_sdk, send_columns, time_column

__all__ = ["MOVABLE", "anchor_to_robot_base", "log_joint_transforms", "log_robot", "resolve_urdf", "sanitize_urdf"]

MOVABLE = ("revolute", "continuous", "prismatic")


def resolve_urdf(robot: RobotInfo) -> Path | None:
    """The URDF named in the file, or (written on another machine) the one of the conf robot of that name."""
    if robot.urdf and Path(robot.urdf).is_file():
        return Path(robot.urdf)
    try:
        from pathrl.robot.external import load_robot_by_name

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


def log_robot(rec, robot: RobotInfo, tdir: Path, notes: list[str]):
    """URDF visual geometry (static) and the fixed joints' transforms (static, ``/world/fixed_transforms``).

    The movable joints are logged only temporally (``/world/joint_transforms``): a frame must be defined by
    one entity, so the loader's static zero-pose joint transforms are not sent.
    """
    rr = rerun_sdk()
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
                f"world/fixed_transforms/{esc(joint.name)}",
                joint.compute_transform(0.0, clamp=False),
                static=True,
            )
    return tree


def log_joint_transforms(
    rec, tree, robot: RobotInfo, episodes: list[Episode], starts: np.ndarray, notes: list[str]
) -> None:
    """All movable joints: the logged ones per step, the others (e.g. fingers) at 0 from the first instant."""
    rr = rerun_sdk()
    time_idx = [time_column(episode_times(episodes, starts))]
    ends = np.array([s + e.t[-1] for e, s in zip(episodes, starts, strict=True)])
    ep_idx = [time_column(ends), rr.TimeColumn("episode", sequence=[e.episode for e in episodes])]
    q_all = np.concatenate([e.q for e in episodes])
    q_final = np.array([e.q[-1] for e in episodes])
    col = {name: j for j, name in enumerate(robot.joint_names)}
    for joint in tree.joints():
        if joint.joint_type not in MOVABLE:
            continue
        if joint.name in col:
            j = col[joint.name]
            send_columns(
                rec,
                "world/joint_transforms",
                time_idx,
                joint.compute_transform_columns(q_all[:, j], clamp=False),
            )
            send_columns(
                rec,
                "world/joint_transforms",
                ep_idx,
                joint.compute_transform_columns(q_final[:, j], clamp=False),
            )
        else:
            send_columns(
                rec,
                "world/joint_transforms",
                [
                    time_column([starts[0] + episodes[0].t[0]]),
                    rr.TimeColumn("episode", sequence=[episodes[0].episode]),
                ],
                joint.compute_transform_columns([0.0], clamp=False),
            )
    missing = [n for n in robot.joint_names if tree.get_joint_by_name(n) is None]
    if missing:
        notes.append(f"joints not in the URDF (not animated): {', '.join(missing)}")


def anchor_to_robot_base(rec, root_frame: str, episodes: list[Episode]) -> None:
    """Put /world and the path entities in the URDF root link frame (the frame of all logged positions)."""
    rr = rerun_sdk()
    extras = sorted({n for e in episodes for n in e.extras})
    for ent in [
        "world",
        "world/reference",
        "world/executed",
        "world/tcp",
        "world/reference_point",
        *(f"world/{esc(n)}" for n in extras),
    ]:
        rec.log(ent, rr.CoordinateFrame(root_frame), static=True)
