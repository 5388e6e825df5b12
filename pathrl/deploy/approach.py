"""The end of a followed path: a jerk-limited move from the robot's commanded state to the last knot, at rest.

The tracking env ends a path by braking once it counts the end as reached (arc length covered, or close to the end
knot): the robot comes to rest a little short of the last knot (0.01-0.14 rad). A robot cell wants the last
waypoint itself. From the state at which the env reaches the end, Ruckig (free build, state to state, no
waypoints) plans the time-optimal jerk-limited move to the last knot at rest under the robot's velocity,
acceleration and jerk limits; it is accepted only if its position extrema lie inside the position range. Its
acceleration is piecewise linear in time (constant jerk per phase), so samples at any control rate are exact and
their finite-difference jerk is at most the limit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from ruckig import InputParameter, Result, Ruckig, Trajectory

__all__ = ["Approach", "plan_approach"]

#: Ruckig plans against the limits times this factor (its own float rounding stays inside the checked limits).
LIMIT_SCALE = 1.0 - 1e-9


@dataclass(frozen=True)
class Approach:
    """A planned final approach: `duration` (s), sampled with :meth:`sample`."""

    trajectory: Trajectory
    duration: float
    target: np.ndarray  # (D,) rad

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration (T, D) at times `t` (T,) s after the approach's start (held at the
        target, at rest, after its end)."""
        d = len(self.target)
        out = np.empty((3, len(t), d))
        for i, ti in enumerate(t):
            if ti >= self.duration:
                out[0, i], out[1, i], out[2, i] = self.target, 0.0, 0.0
            else:
                p, v, a = self.trajectory.at_time(float(ti))[:3]
                out[0, i], out[1, i], out[2, i] = p, v, a
        return out[0], out[1], out[2]


def plan_approach(p: np.ndarray, v: np.ndarray, a: np.ndarray, target: np.ndarray, vel: np.ndarray,
                  acc: np.ndarray, jerk: np.ndarray, pos_limits: np.ndarray) -> Approach | None:
    """The time-optimal jerk-limited move from (p, v, a) (D,) to `target` (D,) at rest, or None if Ruckig finds
    none or it leaves `pos_limits` (D, 2) (rad; a start or target on a limit within rounding counts as inside).
    Limits vel, acc, jerk: (D,) magnitudes."""
    d = len(p)
    otg, inp, traj = Ruckig(d), InputParameter(d), Trajectory(d)
    inp.max_velocity = (LIMIT_SCALE * vel).tolist()
    inp.max_acceleration = (LIMIT_SCALE * acc).tolist()
    inp.max_jerk = (LIMIT_SCALE * jerk).tolist()
    inp.current_position, inp.current_velocity, inp.current_acceleration = p.tolist(), v.tolist(), a.tolist()
    inp.target_position, inp.target_velocity, inp.target_acceleration = target.tolist(), [0.0] * d, [0.0] * d
    try:
        res = otg.calculate(inp, traj)
    except RuntimeError:  # ruckig raises on input it cannot take (e.g. a state outside its limits)
        return None
    if res not in (Result.Working, Result.Finished):
        return None
    ext = traj.position_extrema
    lo = np.array([e.min for e in ext])
    hi = np.array([e.max for e in ext])
    # the range, widened to the start and the target where they sit on a limit within rounding (accepted paths may)
    low = np.minimum(pos_limits[:, 0], np.minimum(p, target)) - 1e-12
    high = np.maximum(pos_limits[:, 1], np.maximum(p, target)) + 1e-12
    if (lo < low).any() or (hi > high).any():
        return None
    return Approach(traj, float(traj.duration), np.asarray(target, dtype=np.float64).copy())
