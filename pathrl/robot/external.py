"""Robots by name (:func:`load_robot_by_name`): a shipped ``conf/robot/<name>.yaml``, or a robot from outside the
package: one YAML beside a URDF, found by every CLI through ``PATHRL_ROBOT_PATH``.

``PATHRL_ROBOT_PATH`` holds directories and YAML files separated by ``os.pathsep`` (``:``); every ``*.yaml`` in them
is a robot named by its ``name`` (default: the file's stem), usable as ``robot=NAME`` in every CLI (registered with
Hydra's config store by the CLI layer) and by :func:`load_robot_by_name`. A name of a shipped
robot cannot be reused. The YAML has the keys of ``conf/robot/*.yaml`` (``pathrl.schema.RobotCfg``), with
these differences:

- ``urdf``: a path relative to the YAML's directory, an absolute path, or ``pybullet_data:<file>`` (the URDFs that
  ship with pybullet);
- ``position_limits`` and ``velocity_limits``: read from the URDF's ``<limit lower upper velocity>`` of each joint
  when missing (or ``urdf``); ``velocity_scale`` (default 1) scales the URDF velocities;
- ``acceleration_limits``: required, a list (one per joint) or one number for all joints (URDFs have none);
- ``jerk_limits``: a list or one number; when missing, :data:`JERK_PER_ACCELERATION` times the acceleration limits
  (the rule of the paper's iiwa configuration: jerk = 20 x acceleration);
- ``deviation_weights``: default 1 for every path joint; ``path_joints``: default ``joints``;
- ``tcps``: a list of ``{link, offset}`` (a URDF link and a translation in its frame, m), required.

The expanded config (every limit explicit, the URDF path absolute) is what a training run stores, so a trained
model loads without the variable.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from pathrl.config.paths import CONF_DIR
from pathrl.robot.model import RobotConfigError, RobotSpec, load_robot

__all__ = ["JERK_PER_ACCELERATION", "ROBOT_PATH_ENV", "expand_robot_file", "load_robot_by_name", "load_robot_file",
           "robot_files", "urdf_limits"]

ROBOT_PATH_ENV = "PATHRL_ROBOT_PATH"
#: Jerk limit per acceleration limit (1/s) when a robot YAML gives none.
JERK_PER_ACCELERATION = 20.0


def robot_files(env: str | None = None) -> dict[str, Path]:
    """{file stem: YAML file} of the robots on ``PATHRL_ROBOT_PATH`` (or `env`); RobotConfigError for an entry that
    does not exist or a stem that two files (or a shipped robot) share."""
    value = os.environ.get(ROBOT_PATH_ENV, "") if env is None else env
    shipped = {p.stem for p in (CONF_DIR / "robot").glob("*.yaml")}
    out: dict[str, Path] = {}
    for entry in filter(None, value.split(os.pathsep)):
        p = Path(entry).expanduser()
        if p.is_dir():
            files = sorted(p.glob("*.yaml"))
        elif p.is_file():
            files = [p]
        else:
            raise RobotConfigError(f"{ROBOT_PATH_ENV}: {entry}: no such file or directory")
        for f in files:
            if f.stem in shipped:
                raise RobotConfigError(f"{f}: robot {f.stem!r} is a shipped robot; name the file otherwise")
            if f.stem in out and out[f.stem] != f.resolve():
                raise RobotConfigError(f"{ROBOT_PATH_ENV}: two robots named {f.stem!r}: {out[f.stem]} and {f}")
            out[f.stem] = f.resolve()
    return out


def _urdf_path(ref: str, base: Path) -> Path:
    """The URDF file of a robot YAML's ``urdf`` entry (`base`: the YAML's directory)."""
    if ref.startswith("pybullet_data:"):
        import pybullet_data

        path = Path(pybullet_data.getDataPath()) / ref.removeprefix("pybullet_data:")
    elif ref.startswith(("pathrl:", "armar:")):
        from pathrl.robot.model import resolve_urdf

        return resolve_urdf(ref)
    else:
        path = Path(ref).expanduser()
        path = path if path.is_absolute() else base / path
    if not path.is_file():
        raise RobotConfigError(f"URDF not found: {ref!r} -> {path}")
    return path.resolve()


def urdf_limits(urdf: Path, joints: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Position limits (D, 2) and velocity limits (D,) of `joints` from the URDF's ``<limit>`` elements (rad, rad/s;
    m, m/s for prismatic joints); a continuous joint has no position limit and is refused."""
    try:
        root = ET.parse(urdf).getroot()
    except (ET.ParseError, OSError) as exc:
        raise RobotConfigError(f"{urdf}: not a readable URDF ({exc})") from None
    found = {j.get("name"): j for j in root.findall("joint")}  # not the <joint> of <transmission>
    pos, vel = [], []
    for name in joints:
        j = found.get(name)
        if j is None:
            raise RobotConfigError(f"{urdf.name}: no joint {name!r} (joints: {', '.join(map(str, found))})")
        lim = j.find("limit")
        if j.get("type") not in ("revolute", "prismatic") or lim is None:
            raise RobotConfigError(f"{urdf.name}: joint {name!r} ({j.get('type')}) has no position limits; give "
                                   "position_limits in the robot YAML")
        try:
            pos.append([float(lim.get("lower")), float(lim.get("upper"))])
            vel.append(float(lim.get("velocity")))
        except (TypeError, ValueError):
            raise RobotConfigError(f"{urdf.name}: joint {name!r}: <limit> needs lower, upper and velocity") from None
    return np.asarray(pos), np.asarray(vel)


def _per_joint(value: Any, n: int, key: str) -> list[float]:
    """A list of `n` floats from a list or one number."""
    if isinstance(value, (int, float)):
        return [float(value)] * n
    try:
        out = [float(x) for x in value]
    except (TypeError, ValueError):
        raise RobotConfigError(f"robot.{key}: expected a number or {n} numbers, got {value!r}") from None
    if len(out) != n:
        raise RobotConfigError(f"robot.{key}: expected {n} values (one per joint), got {len(out)}")
    return out


def expand_robot_file(path: str | os.PathLike) -> dict[str, Any]:
    """The explicit robot config of a robot YAML (module docstring): URDF path absolute, every limit a list."""
    import yaml

    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise RobotConfigError(f"{path}: cannot read ({str(exc).splitlines()[0]})") from None
    if not isinstance(raw, dict):
        raise RobotConfigError(f"{path}: expected a mapping of robot keys")
    try:
        cfg = dict(raw)
        for key in ("urdf", "joints", "acceleration_limits", "tcps", "workspace"):
            if key not in cfg:
                raise RobotConfigError(f"robot.{key} is required")
        cfg.setdefault("name", path.stem)
        if cfg["name"] != path.stem:
            raise RobotConfigError(f"robot.name {cfg['name']!r} must be the file's stem {path.stem!r} (robot=NAME "
                                   "finds it by file name)")
        urdf = _urdf_path(str(cfg["urdf"]), path.parent)
        cfg["urdf"] = str(urdf)
        joints = [str(j) for j in cfg["joints"]]
        cfg.setdefault("path_joints", joints)
        n = len(joints)
        pos, vel = (urdf_limits(urdf, joints) if cfg.get("position_limits", "urdf") == "urdf"
                    or cfg.get("velocity_limits", "urdf") == "urdf" else (None, None))
        if cfg.get("position_limits", "urdf") == "urdf":
            cfg["position_limits"] = pos.tolist()
        if cfg.get("velocity_limits", "urdf") == "urdf":
            cfg["velocity_limits"] = (float(cfg.pop("velocity_scale", 1.0)) * vel).tolist()
        cfg.pop("velocity_scale", None)
        cfg["acceleration_limits"] = _per_joint(cfg["acceleration_limits"], n, "acceleration_limits")
        if "jerk_limits" in cfg:
            cfg["jerk_limits"] = _per_joint(cfg["jerk_limits"], n, "jerk_limits")
        else:
            cfg["jerk_limits"] = [JERK_PER_ACCELERATION * a for a in cfg["acceleration_limits"]]
        cfg.setdefault("deviation_weights", [1.0] * len(cfg["path_joints"]))
        load_robot(cfg)  # every check of a shipped robot
    except RobotConfigError as exc:
        raise RobotConfigError(f"{path}: {exc}") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise RobotConfigError(f"{path}: {type(exc).__name__}: {exc}") from None
    return cfg


def load_robot_file(path: str | os.PathLike) -> RobotSpec:
    """The :class:`RobotSpec` of a robot YAML outside the package, its TCP links checked against the URDF."""
    from pathrl.robot.kinematics import ForwardKinematics

    spec = load_robot(expand_robot_file(path))
    fk = ForwardKinematics(spec)
    try:
        fk.tcp_positions_np(spec.pos_limits.mean(axis=1)[None])
    except (KeyError, ValueError) as exc:
        raise RobotConfigError(f"{path}: tcps: {exc}") from None
    return spec


def load_robot_by_name(name: str, conf_dir: Path = CONF_DIR) -> RobotSpec:
    """Load ``conf/robot/<name>.yaml``, or a robot YAML on ``PATHRL_ROBOT_PATH`` (outside Hydra: tests, tools,
    notebooks)."""
    from omegaconf import OmegaConf

    path = conf_dir / "robot" / f"{name}.yaml"
    if not path.is_file():
        external = robot_files()
        if name in external:  # a robot YAML on PATHRL_ROBOT_PATH (this module)
            return load_robot(expand_robot_file(external[name]))
        choices = sorted({p.stem for p in (conf_dir / "robot").glob("*.yaml")} | set(external))
        raise RobotConfigError(f"unknown robot {name!r}; choose one of {choices} (more: PATHRL_ROBOT_PATH)")
    cfg = OmegaConf.to_container(OmegaConf.load(path), resolve=True)
    return load_robot(cfg)
