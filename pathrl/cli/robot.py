"""``pathrl-robot``: check a robot YAML from outside the package and print its summary.

    pathrl-robot check FILE.yaml        # validate (URDF, joints, limits, TCPs) and print the limits table
    pathrl-robot list                   # the shipped robots and those on PATHRL_ROBOT_PATH

A robot YAML beside a URDF (keys: docs/your_robot.md, pathrl/robot/external.py) is found by every CLI as ``robot=NAME``
once its directory (or the file) is on ``PATHRL_ROBOT_PATH``. Bad input -> one line on stderr, exit code 2.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from pathrl.cli.common import UserError, run_cli

__all__ = ["cmd_check", "cmd_list", "main"]


def cmd_check(path: str) -> None:
    """Validate `path` and print the robot's limits, TCP and workspace coverage."""
    import numpy as np

    from pathrl.robot.external import load_robot_file
    from pathrl.robot.kinematics import ForwardKinematics
    from pathrl.robot.model import RobotConfigError

    try:
        spec = load_robot_file(path)
    except RobotConfigError as exc:
        raise UserError(str(exc)) from None
    print(f"robot     {spec.name}  ({spec.dof} joints, {spec.path_dof} path joints)  urdf {spec.urdf}")
    print(f"{'joint':24s} {'lower':>8s} {'upper':>8s} {'vel':>7s} {'acc':>7s} {'jerk':>8s}   (rad, /s, /s^2, /s^3; "
          "position range after the margin)")
    for i, j in enumerate(spec.joints):
        lo, hi = spec.pos_limits[i]
        print(f"{j:24s} {lo:8.4f} {hi:8.4f} {spec.vel_limits[i]:7.3f} {spec.acc_limits[i]:7.2f} "
              f"{spec.jerk_limits[i]:8.1f}")
    fk = ForwardKinematics(spec)
    mid = spec.pos_limits.mean(axis=1)
    rng = np.random.default_rng(0)
    q = spec.pos_limits[:, 0] + rng.random((2000, spec.dof)) * np.diff(spec.pos_limits, axis=1)[:, 0]
    tcp = fk.tcp_positions_np(np.vstack([mid[None], q]))  # (N, T, 3)
    ws = spec.workspace
    inside = ((tcp[1:] >= ws[:, 0]) & (tcp[1:] <= ws[:, 1])).all(axis=(1, 2)).mean()
    for k, t in enumerate(spec.tcps):
        at = np.round(tcp[0, k], 3).tolist()
        print(f"tcp       {t.link} + {list(t.offset)} m: at the middle of the range {at} m")
    print(f"workspace x {ws[0].tolist()} y {ws[1].tolist()} z {ws[2].tolist()} m: {100 * inside:.0f} % of 2000 uniform "
          "configurations put every TCP inside (random paths start only there)")
    if inside == 0:
        raise UserError(f"{path}: no sampled configuration puts the TCP inside the workspace box; widen it")
    print("ok")


def cmd_list() -> None:
    """The shipped robots and those on PATHRL_ROBOT_PATH."""
    from pathrl.config.paths import CONF_DIR
    from pathrl.robot.external import ROBOT_PATH_ENV, robot_files
    from pathrl.robot.model import RobotConfigError

    for p in sorted((CONF_DIR / "robot").glob("*.yaml")):
        print(f"{p.stem:16s} shipped")
    try:
        for name, p in robot_files().items():
            print(f"{name:16s} {p}  ({ROBOT_PATH_ENV})")
    except RobotConfigError as exc:
        raise UserError(str(exc)) from None


def _main(argv: list[str]) -> None:
    if not argv or argv[0] in ("-h", "--help"):
        if argv:
            print(__doc__.strip())
            return
        raise UserError("missing command; usage: pathrl-robot {check FILE, list}")
    if argv[0] == "check":
        if len(argv) != 2:
            raise UserError("usage: pathrl-robot check FILE.yaml")
        cmd_check(argv[1])
    elif argv[0] == "list" and len(argv) == 1:
        cmd_list()
    else:
        raise UserError(f"unknown command {' '.join(argv)!r}; usage: pathrl-robot {{check FILE, list}}")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``pathrl-robot`` (argv: sys.argv[1:]); returns the exit code."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
