"""TOPP-RA followed by jerk-limited tracking with Ruckig: what a jerk-limited robot gets from a TOPP-RA plan.

TOPP-RA has no jerk limit (paper Table V): its accelerations jump, so a robot whose controller bounds the jerk
cannot execute the plan as timed. Here every control cycle Ruckig's online trajectory generator (the free
community build: one target state, here in its velocity interface) aims at the plan's velocity at that instant
plus a proportional pull to the plan's position, ``qd(t + lead_s) + gain (q(t) - q)`` (clipped to the velocity
limits; the lead starts the braking before the plan does), with zero acceleration, under the acceleration and
jerk limits, and the robot executes its first cycle. Ruckig's velocity interface ignores position limits, so the
commanded velocity is also capped by the speed from which a jerk-limited stop ends inside them
(:func:`stopping_speeds`, 0.35 of it: with 0.8 of it 131 samples of 200 iiwa7 target-point segments left the
limits, with 0.5 of it 20 samples of the 1200 iiwa7 random segments did). After the plan ends the target is its
end at rest (position interface); the motion ends when Ruckig reports that target reached. Aiming the position
interface at the plan's moving state instead made Ruckig back up first (reaching a position at a velocity sooner
than the plan allows can mean starting further back: 4.8 cm on the line below), and a gain of 5 without the lead
overshot the line's end by 10 cm.

Reported per segment: the duration until then, the executed samples' largest and mean distance from the path
(joint space: the nearest plan sample, 1/240 s apart along the path, searched forward from the last match)
and the limit violations of the executed samples, jerk included. On a straight line of 3 rad (limits 1 rad/s,
2 rad/s^2, 20 rad/s^3) TOPP-RA takes 3.50 s, the jerk-limited optimum is 3.60 s and the tracked motion 3.64 s
(tests/test_toppra.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from pathrl.baselines.toppra_path import PathLimits, limit_counts

if TYPE_CHECKING:
    from pathrl.baselines.toppra import ToppraResult

__all__ = ["TrackSettings", "Tracked", "ruckig_tracked", "stopping_speeds", "track_plan"]


@dataclass(frozen=True)
class Tracked:
    """One tracked plan: duration (s), deviation from the path (rad), executed samples (T, M) at the control rate."""

    duration_s: float
    max_dev_rad: float
    mean_dev_rad: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray


def stopping_speeds(q: np.ndarray, pos: np.ndarray, acc: np.ndarray, jerk: np.ndarray, vel: np.ndarray,
                    margin: float = 0.35) -> tuple[np.ndarray, np.ndarray]:
    """Velocity bounds (M,) from which a jerk-limited stop still ends inside the position limits (M, 2): a stop
    from v with acceleration a and jerk j covers about v^2 / (2 a) + v a / (2 j), solved for v at the distance to
    each limit, times `margin`; capped at the velocity limits."""
    def speed(d: np.ndarray) -> np.ndarray:
        d = np.maximum(d, 0.0)
        b = acc * acc / (2.0 * jerk)
        return np.minimum(margin * (np.sqrt(b * b + 2.0 * acc * d) - b), vel)

    return -speed(q - pos[:, 0]), speed(pos[:, 1] - q)


@dataclass(frozen=True)
class TrackSettings:
    """How :func:`track_plan` follows a plan (module docstring): the pull to the plan's position `gain` (1/s), the
    plan's velocity taken `lead_s` ahead (s), at most `max_extra_s` (s) after the plan's end to reach it, and
    `window` plan samples searched ahead of the last match for the nearest one."""

    gain: float = 2.0
    lead_s: float = 0.05
    max_extra_s: float = 10.0
    window: int = 240


def track_plan(q: np.ndarray, qd: np.ndarray, limits: PathLimits, control_rate: float,
               settings: TrackSettings = TrackSettings()) -> Tracked:
    """Track the plan sampled at `control_rate` (q, qd: (T, M), the first sample at rest) with Ruckig under the
    velocity, acceleration and jerk `limits` (M,) and the position limits (M, 2; None: none) (module docstring)."""
    from ruckig import ControlInterface, InputParameter, OutputParameter, Result, Ruckig

    vel, acc, jerk, pos = limits.vel, limits.acc, limits.jerk, limits.pos
    gain, window = settings.gain, settings.window

    m = q.shape[1]
    otg, inp, out = Ruckig(m, 1.0 / control_rate), InputParameter(m), OutputParameter(m)
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = vel.tolist(), acc.tolist(), jerk.tolist()
    if pos is not None:
        inp.min_position, inp.max_position = pos[:, 0].tolist(), pos[:, 1].tolist()
    inp.current_position, inp.current_velocity, inp.current_acceleration = q[0].tolist(), [0.0] * m, [0.0] * m
    inp.control_interface = ControlInterface.Velocity
    inp.target_acceleration = [0.0] * m
    cur = q[0].copy()
    rows = [(q[0], np.zeros(m), np.zeros(m))]
    last = len(q) - 1
    lead = int(round(settings.lead_s * control_rate))
    for k in range(1, last + 1 + int(settings.max_extra_s * control_rate)):
        if k == last + 1:  # the plan has ended: to its end, at rest
            inp.control_interface = ControlInterface.Position
            inp.target_position, inp.target_velocity = q[last].tolist(), [0.0] * m
        elif k <= last:
            ahead = min(k + lead, last)
            lo, hi = (-vel, vel) if pos is None else stopping_speeds(cur, pos, acc, jerk, vel)
            inp.target_velocity = np.clip(qd[ahead] + gain * (q[k] - cur), lo, hi).tolist()
        res = otg.update(inp, out)
        if res not in (Result.Working, Result.Finished):
            raise RuntimeError(f"ruckig failed ({res}) at cycle {k}")
        cur = np.asarray(out.new_position)
        rows.append((cur, np.asarray(out.new_velocity), np.asarray(out.new_acceleration)))
        out.pass_to_input(inp)
        if k > last and res == Result.Finished:
            break
    p, v, a = (np.asarray(x) for x in zip(*rows, strict=True))
    dev, j = np.empty(len(p)), 0
    for i, x in enumerate(p):  # nearest plan sample, searched forward from the last match (the robot lags)
        d = np.linalg.norm(q[j:j + window] - x, axis=1)
        j += int(d.argmin())
        dev[i] = d.min()
    return Tracked((len(p) - 1) / control_rate, float(dev.max()), float(dev.mean()), p, v, a)


def ruckig_tracked(res: ToppraResult, limits: PathLimits, control_rate: float) -> dict[str, Any]:
    """Duration, path deviation and limit violations (jerk included) of `res`'s plan tracked by Ruckig
    (:func:`track_plan`)."""
    tr = track_plan(res.q, res.qd, limits, control_rate)
    viol = limit_counts(tr.q, tr.qd, tr.qdd, limits, control_rate)
    return {"duration_s": tr.duration_s, "max_dev_rad": tr.max_dev_rad, "mean_dev_rad": tr.mean_dev_rad,
            "violations": viol}
