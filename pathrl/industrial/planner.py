"""Path planner of the calibrated controller model: a program read as a queue with a finite look-ahead.

:func:`plan` turns a MoveL / MoveJ program and a speed command v (mm/s) into joint setpoints at the
interpolation rate, the way an industrial path planner does it, instruction by instruction:

1. **Preparation and zones.** Instruction i (the move to waypoint i) must be prepared while the robot is still
   on the previous segment; that takes ``prep_s`` seconds. If the incoming segment lasts less than that at the
   command speed (L_{i-1} / v < ``prep_s``), the zone at waypoint i cannot be planned and **degrades to a fine
   point** (the robot stops there): a :class:`CornerEvent` ("corner path", as the controller's event log calls
   it) is reported. Otherwise the zone **shrinks** to half of the shorter adjacent segment, and its used
   radius depends on speed: r_i = min(zone, L_{i-1} / 2, L_i / 2, v ``corner_s``) (a corner is traversed in
   about ``corner_s`` seconds at most, so a slow move cuts its corners less).
2. **Geometry.** Positions: lines with quadratic blends inside each zone
   (:func:`pathrl.industrial.program.blend_polyline`). Orientation: the waypoint rotations as rotation vectors
   in the chart of the middle waypoint, linear in the polyline's arc length, then **blended across each
   zone** by a moving average over the zone's orientation radius (``ori_zone_factor`` x r_i): the angular
   velocity changes continuously instead of jumping at the waypoints (no axis-acceleration spikes there).
   MoveJ blends in joint space as in :mod:`pathrl.industrial.program`.
3. **Speed.** The largest path speed from rest to rest under the command, the axis speeds and accelerations
   (:class:`PlannerParams`, the reference's identified figures), a TCP acceleration and zero speed at fine
   points, **and the finite look-ahead**: at any point the planner holds only the next ``lookahead``
   instructions, so the speed must allow stopping at the last one it holds:
   sdot^2 <= 2 a_tcp (s_horizon - s). A forward and a backward running minimum give the profile.
4. **Time law.** s(t) at ``rate`` Hz, smoothed by a moving average of ``fir_s`` seconds (a jerk limit), and the
   joint setpoints q(s(t)), moving-averaged over ``joint_fir_s`` seconds (the interpolator's joint-space
   smoothing: it leaves lines alone and cuts a curve of curvature kappa by about v^2 kappa T^2 / 24, a
   speed-dependent cut that reaches the tool orientation too), with their first and second time derivatives
   (finite differences). The window shrinks at the motion's start (``joint_fir_ends="start"``: it never
   averages the rest before the start in, so the start ramp is the time law's, not 0.18 s of smoothing) and
   runs over the held end point at the stop, so the stop is smoothed over the full window; "shrink" shrinks it
   at the stop too (an abrupt stop that leaves ~1 mm of gear vibration at rest), "hold" pads both ends with
   the rest position (the first calibration's behaviour).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from pathrl.industrial import arm
from pathrl.industrial.program import DEFAULT_SEED, Program, blend_polyline

__all__ = ["CornerEvent", "Plan", "PlannerParams", "blend_orientations", "lookahead", "moving_average",
           "moving_average_in_motion", "plan",
           "plan_zones", "speed_profile"]

DEG = np.pi / 180.0


@dataclass(frozen=True)
class PlannerParams:
    """Planner settings (units in the comments). Axis limits default to the reference's figures
    (``../shared/reference/abb_irb6640_recorded.md``): speeds of the datasheet with axes 4 / 5 at 190 / 140 deg/s,
    accelerations identified in RobotStudio (axes 1-3: the medians of their configuration-dependent ranges)."""

    step_mm: float = 0.5  # mm, geometric sampling of the path
    lookahead: int = 5  # instructions held ahead of the current one
    prep_s: float = 0.008  # s, preparation time of one instruction (two 4 ms interpolation ticks)
    corner_s: float = 0.06  # s, longest time spent in a corner (speed-dependent zone use)
    ori_zone_factor: float = 1.5  # orientation zone / position zone (ABB's z10 has 15 mm for the orientation)
    tcp_acc: float = 4000.0  # mm/s^2, path acceleration (tangential and centripetal)
    beta: float = 0.3  # share of the axis acceleration budget for the tangential part (calibrated)
    fir_s: float = 0.048  # s, moving average of s(t) (calibrated: with beta, the start ramp)
    joint_fir_s: float = 0.18  # s, moving average of the joint setpoints (cuts curves by ~ v^2 kappa T^2 / 24)
    joint_fir_ends: str = "start"  # window at the motion's ends: "start" shrinks it at the start only, "shrink"
    # at the start and the stop, "hold" at neither (pads with rest); "start" is calibrated (docs/industrial.md)
    vel_limits: list[float] = field(default_factory=lambda: [100.0, 90.0, 90.0, 190.0, 140.0, 190.0])  # deg/s
    acc_limits: list[float] = field(default_factory=lambda: [7.6, 5.0, 10.3, 42.5, 36.8, 50.5])  # rad/s^2

    def __post_init__(self) -> None:
        for key in ("step_mm", "tcp_acc", "corner_s", "ori_zone_factor"):
            if not getattr(self, key) > 0.0:
                raise ValueError(f"planner.{key} must be > 0, got {getattr(self, key)}")
        if self.lookahead < 1 or min(self.prep_s, self.fir_s, self.joint_fir_s) < 0 or not 0 < self.beta < 1:
            raise ValueError("planner: need lookahead >= 1, prep_s, fir_s, joint_fir_s >= 0, 0 < beta < 1")
        if self.joint_fir_ends not in ("shrink", "start", "hold"):
            raise ValueError(f"planner.joint_fir_ends must be shrink, start or hold, got {self.joint_fir_ends!r}")
        if len(self.vel_limits) != 6 or len(self.acc_limits) != 6:
            raise ValueError("planner: vel_limits and acc_limits need 6 values (axes 1-6)")


@dataclass(frozen=True)
class CornerEvent:
    """A zone the planner could not keep: waypoint index, the incoming segment's duration at the command (s),
    and what happened ("fine point")."""

    waypoint: int
    segment_s: float
    action: str = "fine point"


@dataclass(frozen=True)
class Plan:
    """Planned motion: times t (n,) s, joint setpoints q (n, 6) rad with velocities qd and accelerations qdd,
    the path parameter s (n,) mm and speed sdot (n,) mm/s, the zone radii used (m,) mm and the corner events."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    s: np.ndarray
    sdot: np.ndarray
    radii: np.ndarray
    events: tuple[CornerEvent, ...] = field(default_factory=tuple)


def plan_zones(points: np.ndarray, zone: float, v: float, params: PlannerParams
               ) -> tuple[np.ndarray, np.ndarray, list[CornerEvent]]:
    """Zone radii (m,) mm, fine-point mask (m,) and corner events of waypoints (m, 3) mm at command v mm/s
    (module doc, step 1). The first and last waypoints are fine points."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    if np.any(seg <= 0.0):
        raise ValueError("two consecutive waypoints coincide")
    m = len(points)
    fine = np.zeros(m, dtype=bool)
    fine[0] = fine[-1] = True
    radii = np.zeros(m)
    events = []
    for i in range(1, m - 1):
        seg_s = seg[i - 1] / v
        if zone > 0.0 and seg_s < params.prep_s:
            fine[i] = True
            events.append(CornerEvent(i, float(seg_s)))
            continue
        radii[i] = min(zone, 0.5 * seg[i - 1], 0.5 * seg[i], v * params.corner_s)
        fine[i] = radii[i] <= 0.0
    return radii, fine, events


def blend_orientations(rotations: np.ndarray, knots: np.ndarray, radii: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Rotations (K, 3, 3) at polyline arc positions u (K,) mm: rotation vectors of `rotations` (m, 3, 3) in the
    chart of the middle one, linear between `knots` (m,) mm, moving-averaged over +-radii (m,) around each
    interior knot (a quadratic blend: continuous angular velocity)."""
    ref = Rotation.from_matrix(rotations[len(rotations) // 2])
    chart = (ref.inv() * Rotation.from_matrix(rotations)).as_rotvec()  # (m, 3)
    lin = np.stack([np.interp(u, knots, chart[:, j]) for j in range(3)], axis=1)
    slope = np.diff(chart, axis=0) / np.diff(knots)[:, None]  # (m-1, 3) per mm
    for i in np.nonzero(radii[1:-1] > 0.0)[0] + 1:
        r, c = radii[i], knots[i]
        inside = np.abs(u - c) < r
        if not inside.any():
            continue
        d = slope[i] - slope[i - 1]
        x = u[inside] - c
        lin[inside] += d * ((x + r) ** 2 / (4.0 * r) - np.maximum(x, 0.0))[:, None]
    return (ref * Rotation.from_rotvec(lin)).as_matrix()


def _geometry(program: Program, radii: np.ndarray, step: float, tool: arm.Tool, ori_factor: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blended path: joints (K, 6), TCP positions (K, 3) and the arc position of every waypoint on it (m,)."""
    seed_q = DEFAULT_SEED if program.q_seed is None else np.asarray(program.q_seed, dtype=np.float64)
    cum = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(program.positions, axis=0), axis=1))]
    if program.move == "L":
        p, u = blend_polyline(program.positions, radii, step)
        rot = blend_orientations(program.rotations, cum, np.minimum(radii * ori_factor, _half_segments(cum)), u)
        q = arm.ik_path(p, rot @ tool.rot.T, seed_q, tool.offset)
    else:
        qw = arm.ik_path(program.positions, program.rotations @ tool.rot.T, seed_q, tool.offset)
        joint_len = np.linalg.norm(np.diff(qw, axis=0), axis=1)
        frac = np.zeros(len(qw))
        cart = np.diff(cum)
        frac[1:-1] = radii[1:-1] / np.maximum(np.minimum(cart[:-1], cart[1:]), 1e-9)
        jr = frac * np.r_[0.0, np.minimum(joint_len[:-1], joint_len[1:]), 0.0]
        q, uq = blend_polyline(qw, jr, max(step * joint_len.sum() / max(cum[-1], 1e-9), 1e-6))
        p, _ = arm.fk(q, tool.offset)
        qcum = np.r_[0.0, np.cumsum(joint_len)]
        u = np.interp(uq, qcum, cum)
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    keep = np.r_[True, np.diff(s) > 1e-6]
    q, p, s, u = q[keep], p[keep], s[keep], u[keep]
    su = np.linspace(0.0, s[-1], max(int(np.ceil(s[-1] / step)), 2) + 1)
    qu = np.stack([np.interp(su, s, q[:, j]) for j in range(6)], axis=1)
    pu = np.stack([np.interp(su, s, p[:, j]) for j in range(3)], axis=1)
    s_wp = np.interp(cum, u, s)
    return qu, pu, s_wp


def _half_segments(cum: np.ndarray) -> np.ndarray:
    """Half of the shorter adjacent segment at each knot (m,), 0 at the ends."""
    seg = np.diff(cum)
    out = np.zeros(len(cum))
    out[1:-1] = 0.5 * np.minimum(seg[:-1], seg[1:])
    return out


def lookahead(s: np.ndarray, w_max: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """Path speed (K,) mm/s over arc length s (K,): rest to rest, below sqrt(w_max), path acceleration and
    deceleration at most `acc` (K,). Forward and backward running minima over sdot^2."""
    w = w_max.copy()
    w[0] = w[-1] = 0.0
    budget = np.r_[0.0, np.cumsum(2.0 * acc[:-1] * np.diff(s))]
    w = np.minimum(w, budget + np.minimum.accumulate(w - budget))
    back = np.r_[0.0, np.cumsum(2.0 * acc[::-1][:-1] * -np.diff(s[::-1]))]
    w_rev = w[::-1]
    w = np.minimum(w_rev, back + np.minimum.accumulate(w_rev - back))[::-1]
    return np.sqrt(np.maximum(w, 0.0))


def speed_profile(s: np.ndarray, q: np.ndarray, p: np.ndarray, v: float, s_stop: np.ndarray, horizon: np.ndarray,
                  params: PlannerParams) -> np.ndarray:
    """Path speed (K,) mm/s along arc length s (K,) of joints q (K, 6) and TCP p (K, 3): the module doc's step 3.
    `s_stop` are the fine points' arc positions, `horizon` (K,) the arc position of the last instruction held."""
    vmax, amax = DEG * np.asarray(params.vel_limits), np.asarray(params.acc_limits)
    qs = np.gradient(q, s, axis=0)
    qss = np.gradient(qs, s, axis=0)
    kappa = np.linalg.norm(np.gradient(np.gradient(p, s, axis=0), s, axis=0), axis=1)
    tiny = 1e-12
    w = np.full(len(s), float(v) ** 2)
    w = np.minimum(w, np.min((vmax / np.maximum(np.abs(qs), tiny)) ** 2, axis=1))
    w = np.minimum(w, np.min((1 - params.beta) * amax / np.maximum(np.abs(qss), tiny), axis=1))
    w = np.minimum(w, params.tcp_acc / np.maximum(kappa, tiny))
    acc = np.minimum(params.tcp_acc, np.min(params.beta * amax / np.maximum(np.abs(qs), tiny), axis=1))
    w = np.minimum(w, 2.0 * params.tcp_acc * np.maximum(horizon - s, 0.0))
    w[np.searchsorted(s, s_stop).clip(0, len(s) - 1)] = 0.0
    return lookahead(s, w, acc)


def moving_average(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average of n samples along axis 0 of x (N, ...), the ends held (same length)."""
    if n <= 1:
        return x
    pad = (n - 1) // 2, n - 1 - (n - 1) // 2
    xp = np.concatenate([np.repeat(x[:1], pad[0], 0), x, np.repeat(x[-1:], pad[1], 0)])
    c = np.cumsum(np.concatenate([np.zeros_like(x[:1]), xp]), axis=0)
    return (c[n:] - c[:-n]) / n


def moving_average_in_motion(x: np.ndarray, n: int, first: int, last: int, shrink_stop: bool = True) -> np.ndarray:
    """Centred moving average of about n samples (the odd window 2 ((n - 1) // 2) + 1) along axis 0 of x (N, ...)
    whose half-width shrinks near sample `first` (the motion's start) and, with `shrink_stop`, near `last` (its
    stop) so that it never averages the rest there in; without it the window runs past `last` over x held at
    x[last] (the stop is smoothed over the full window). x is kept before `first` (and after `last` if shrunk)."""
    half = (n - 1) // 2
    if half < 1 or last - first < 2:
        return x
    if not shrink_stop:
        x = np.concatenate([x[:last + 1], np.repeat(x[last:last + 1], max(len(x) - 1 - last, 0) + half, 0)])
        last = len(x) - 1 - half
    i = np.arange(first, last + 1)
    h = np.minimum(half, i - first)
    if shrink_stop:
        h = np.minimum(h, last - i)
    c = np.cumsum(np.concatenate([np.zeros_like(x[:1]), x]), axis=0)
    out = x.copy()
    out[first:last + 1] = (c[i + h + 1] - c[i - h]) / (2 * h + 1).reshape(-1, *([1] * (x.ndim - 1)))
    return out if shrink_stop else out[:len(out) - half]


def _joint_smoothing(qt: np.ndarray, st: np.ndarray, params: PlannerParams, rate: float) -> np.ndarray:
    """The joint setpoints (n, 6) moving-averaged over joint_fir_s, the window's ends per joint_fir_ends."""
    n = int(round(params.joint_fir_s * rate))
    if params.joint_fir_ends == "hold":
        return moving_average(qt, n)
    moving = np.nonzero(st != st[0])[0]
    if len(moving) == 0:
        return qt
    first, last = int(moving[0]) - 1, int(np.nonzero(st != st[-1])[0][-1]) + 1
    return moving_average_in_motion(qt, n, max(first, 0), min(last, len(st) - 1), params.joint_fir_ends == "shrink")


def _time_law(s: np.ndarray, sdot: np.ndarray, params: PlannerParams, rate: float) -> np.ndarray:
    """s(t) (n,) at `rate` Hz, moving-averaged over fir_s. Between two samples both at rest (two fine points
    closer than the path sampling, e.g. waypoints moved next to each other) the move takes 2 sqrt(ds / tcp_acc),
    rest to rest at the TCP acceleration, instead of ds / 0."""
    ds, both = np.diff(s), sdot[:-1] + sdot[1:]
    dt = np.where(both > 1e-6, 2.0 * ds / np.maximum(both, 1e-6), 2.0 * np.sqrt(ds / params.tcp_acc))
    t = np.r_[0.0, np.cumsum(dt)]
    grid = np.arange(0.0, t[-1] + 1.0 / rate, 1.0 / rate)
    st = np.interp(grid, t, s)
    n = max(int(round(params.fir_s * rate)), 1)
    if n > 1:
        padded = np.r_[np.full(n - 1, st[0]), st, np.full(n - 1, st[-1])]
        st = np.convolve(padded, np.ones(n) / n, mode="valid")
    return st


def plan(program: Program, v: float, params: PlannerParams | None = None, tool: arm.Tool | None = None,
         rate: float = 250.0, settle_s: float = 0.3) -> Plan:
    """Plan `program` at speed command `v` mm/s (module doc), setpoints at `rate` Hz; `settle_s` seconds at rest
    are appended."""
    params = PlannerParams() if params is None else params
    tool = arm.DEFAULT_TOOL if tool is None else tool
    if not v > 0.0:
        raise ValueError(f"speed command must be > 0 mm/s, got {v}")
    radii, fine, events = plan_zones(program.positions, program.zone, v, params)
    q, p, s_wp = _geometry(program, radii, params.step_mm, tool, params.ori_zone_factor)
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    if not arm.within_limits(q).all():
        raise ValueError("the program's path leaves the IRB 6640 axis ranges")
    seg_of = np.clip(np.searchsorted(s_wp, s, side="right") - 1, 0, len(s_wp) - 2)
    last = np.minimum(seg_of + 1 + params.lookahead, len(s_wp) - 1)
    # the horizon ends at the first fine point among the instructions held (or the last one held)
    fine_idx = np.nonzero(fine)[0]
    nxt_fine = fine_idx[np.searchsorted(fine_idx, seg_of + 1)]
    horizon = s_wp[np.minimum(last, nxt_fine)]
    horizon = np.where(np.minimum(last, nxt_fine) == len(s_wp) - 1, s[-1], horizon)
    sdot = speed_profile(s, q, p, v, s_wp[fine][1:-1], horizon, params)
    st = _time_law(s, sdot, params, rate)
    st = np.r_[st, np.full(int(round(settle_s * rate)), st[-1])]
    qt = np.stack([np.interp(st, s, q[:, j]) for j in range(6)], axis=1)
    qt = _joint_smoothing(qt, st, params, rate)
    dt = 1.0 / rate
    qd = np.gradient(qt, dt, axis=0)
    qdd = np.gradient(qd, dt, axis=0)
    t = np.arange(len(st)) * dt
    return Plan(t, qt, qd, qdd, st, np.gradient(st, dt), radii, tuple(events))
