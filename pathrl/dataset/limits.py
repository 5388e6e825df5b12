"""Do a dataset's paths stay inside the robot's position limits? (pure; :mod:`pathrl.dataset.io` acts on it)"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from pathrl.paths.inside import INSIDE_TOL

if TYPE_CHECKING:
    from pathrl.robot.model import RobotSpec

__all__ = ["LIMIT_TOL", "limit_excess"]

#: Knots may leave the robot's position range by this much (rad) and still count as inside it (rounding).
LIMIT_TOL = INSIDE_TOL


def limit_excess(knots_list: Sequence[np.ndarray], robot: RobotSpec) -> dict[str, Any]:
    """How far the knots (each (K, M), path joints) leave the robot's position limits: the number of paths that
    leave them by more than :data:`LIMIT_TOL`, the largest excess (rad) and the joint where it occurs."""
    lim = robot.pos_limits[robot.path_index]
    excess = [np.maximum(lim[:, 0] - k, k - lim[:, 1]).max(0) for k in knots_list]  # (M,) per path
    worst = np.max(excess, axis=0) if excess else np.zeros(robot.path_dof)
    j = int(np.argmax(worst))
    return {"paths_outside": int(sum(bool((e > LIMIT_TOL).any()) for e in excess)), "paths": len(knots_list),
            "max_excess_rad": float(max(worst[j], 0.0)), "joint": robot.path_joints[j]}
