"""Robot description used everywhere: joints, the joints that form the path, kinematic limits, TCPs.

A :class:`RobotSpec` is built from a robot config (``conf/robot/*.yaml``) and validated once; every
other module takes it as plain arrays. Joint order is the config's ``joints`` order.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["RobotConfigError", "RobotSpec", "Tcp", "load_robot", "resolve_urdf"]

ASSET_DIR = Path(__file__).resolve().parent.parent / "assets" / "urdf"


class RobotConfigError(ValueError):
    """A robot config is inconsistent (lengths, limits, unknown joints)."""


@dataclass(frozen=True)
class Tcp:
    """Tool centre point: a URDF link plus a translation in that link's frame (m)."""

    link: str
    offset: tuple[float, float, float]


@dataclass(frozen=True)
class RobotSpec:
    """Validated robot description.

    Attributes:
        pos_limits: (D, 2) usable position limits [lower, upper] (URDF limits shrunk by the margin).
        vel_limits, acc_limits, jerk_limits: (D,) symmetric magnitude limits.
        path_index: (M,) indices into ``joints`` of the joints that belong to the path.
        deviation_weights: (M,) per-path-joint weights of the training deviation (paper's R_d).
    """

    name: str
    urdf: Path
    fixed_base: bool
    joints: tuple[str, ...]
    path_joints: tuple[str, ...]
    path_index: np.ndarray
    pos_limits: np.ndarray
    vel_limits: np.ndarray
    acc_limits: np.ndarray
    jerk_limits: np.ndarray
    deviation_weights: np.ndarray
    tcps: tuple[Tcp, ...]
    workspace: np.ndarray  # (3, 2) Cartesian box [min, max] for x, y, z (m)
    floor_z: float

    @property
    def dof(self) -> int:
        """Number of controlled joints D."""
        return len(self.joints)

    @property
    def path_dof(self) -> int:
        """Number of joints M that belong to the path."""
        return len(self.path_joints)


def resolve_urdf(ref: str) -> Path:
    """Resolve ``pathrl:<file>`` (shipped asset), ``armar:<name>`` (armar package) or a file path."""
    if ref.startswith("pathrl:"):
        path = ASSET_DIR / ref.removeprefix("pathrl:")
    elif ref.startswith("armar:"):
        from armar import get_path_to_urdf_file

        path = Path(get_path_to_urdf_file(ref.removeprefix("armar:")))
    else:
        path = Path(os.path.expanduser(ref))
    if not path.is_file():
        raise RobotConfigError(f"URDF not found: {ref!r} -> {path}")
    return path


def _vec(cfg: Mapping[str, Any], key: str, n: int) -> np.ndarray:
    arr = np.asarray(cfg[key], dtype=np.float64)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise RobotConfigError(f"robot.{key}: expected {n} positive finite values, got {list(cfg[key])}")
    return arr


def load_robot(cfg: Mapping[str, Any]) -> RobotSpec:
    """Build and validate a :class:`RobotSpec` from a robot config mapping (YAML / OmegaConf)."""
    joints = tuple(str(j) for j in cfg["joints"])
    path_joints = tuple(str(j) for j in cfg["path_joints"])
    d = len(joints)
    if len(set(joints)) != d:
        raise RobotConfigError(f"robot.joints of {cfg['name']!r} contains duplicates")
    unknown = [j for j in path_joints if j not in joints]
    if unknown:
        raise RobotConfigError(f"robot.path_joints not in robot.joints: {unknown}")
    pos = np.asarray(cfg["position_limits"], dtype=np.float64)
    if pos.shape != (d, 2):
        raise RobotConfigError(f"robot.position_limits: expected {d} [lower, upper] pairs, got shape {pos.shape}")
    margin = float(cfg.get("position_margin", 0.0))
    pos = pos + np.array([margin, -margin])
    if np.any(pos[:, 0] >= pos[:, 1]):
        bad = [joints[i] for i in np.flatnonzero(pos[:, 0] >= pos[:, 1])]
        raise RobotConfigError(f"robot.position_limits: empty range after margin for {bad}")
    m = len(path_joints)
    weights = _vec(cfg, "deviation_weights", m)
    tcps = tuple(Tcp(str(t["link"]), tuple(float(x) for x in t["offset"])) for t in cfg["tcps"])
    if not tcps or any(len(t.offset) != 3 for t in tcps):
        raise RobotConfigError("robot.tcps: need at least one {link, offset: [x, y, z]}")
    ws = cfg["workspace"]
    workspace = np.array([ws["x"], ws["y"], ws["z"]], dtype=np.float64)
    return RobotSpec(
        name=str(cfg["name"]),
        urdf=resolve_urdf(str(cfg["urdf"])),
        fixed_base=bool(cfg.get("fixed_base", True)),
        joints=joints,
        path_joints=path_joints,
        path_index=np.array([joints.index(j) for j in path_joints], dtype=np.int64),
        pos_limits=pos,
        vel_limits=_vec(cfg, "velocity_limits", d),
        acc_limits=_vec(cfg, "acceleration_limits", d),
        jerk_limits=_vec(cfg, "jerk_limits", d),
        deviation_weights=weights,
        tcps=tcps,
        workspace=workspace,
        floor_z=float(cfg.get("floor_z", 0.0)),
    )
