"""Valid acceleration range per joint: the safety core of the action mapping.

At every decision step (period ``dt``, 0.1 s) the policy picks, per joint, the acceleration at the END
of the next step; within the step the acceleration is interpolated linearly (constant jerk). This
module computes the range of such end accelerations for which position, velocity, acceleration and jerk
limits hold during the step and can still be held afterwards (the joint can always brake in time).

The range reproduces ``klimits.PosVelJerkLimitation`` (1.1.3) with the settings of the original work
(``acceleration_after_max_vel_limit_factor=0.01``, ``set_velocity_after_max_pos_to_zero=True``,
``limit_velocity=True``, ``limit_position=True``) as a batched, loop-free torch computation:

* jerk: ``a0 -/+ jerk*dt``;
* velocity: the acceleration must be rampable to zero with full jerk before ``|v|`` exceeds the limit
  (TrueAdapt eqs. 11/12, with klimits' refinement that parks the ramp at ``-/+0.01*a_max`` on a knot);
* position: the lowest possible braking trajectory ("greedy": full jerk down, reduced jerk onto
  ``-a_max``, hold) must peak at or before the limit. This is solved exactly (closed form inside the
  step and for a peak in the hold phase, Newton's method on a convex function otherwise), where
  klimits' closed forms sometimes pick a wrong branch. Where klimits' own velocity rule forbids
  holding ``-a_max`` through the step in which the velocity reaches zero, that knot is raised
  ("velocity-aware"; klimits does not, and then steers into states where a limit must break);
* klimits' refinement that braking should end with ``v = 0`` on a decision step at the limit, which
  only shrinks the range;
* conflict resolution for states outside the valid set, and the final clip to ``[-a_max, a_max]``.

Work is spent only where a limit can bind: cheap per-element bounds skip the rest. Agreement with
klimits is measured in ``tests/test_limits.py``; safety of whole trajectories in
``tests/test_limits_property.py``.

The torch code here is the reference and runs on any device. For float64 CPU tensors the same
computation runs by default in a native build (``pathrl/native/valid_range.c``, one element at
a time, no per-op dispatch; ``tests/test_limits_native.py`` checks it against this code to 1e-9 of the
acceleration limit). Which code runs is the limit backend (:class:`pathrl.limits.backend.LimitBackend`): given
to :func:`valid_acceleration_range`, else the one in effect (an env's, a ``with backend.active():`` block's, else
native where available, kernels eager).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from pathrl import native
from pathrl.limits._braking import Side, greedy_bound, in_step_bound, pick, reach_top
from pathrl.limits._knot import knot_stop_bound
from pathrl.limits._velocity import velocity_bound, velocity_emergency, velocity_floor
from pathrl.limits.backend import LimitBackend, current
from pathrl.limits.kernels import kernel

__all__ = ["CONFLICT_TOL", "DEFAULT_DT", "KNOT_SLACK", "OUTSIDE_TOL", "PLAN_MARGIN", "SETTLE_FACTOR",
           "VEL_SKIP_MARGIN", "JointLimits", "acceleration_to_action", "action_to_acceleration",
           "valid_acceleration_range"]


DEFAULT_DT = 0.1
SETTLE_FACTOR = 0.01  # klimits acceleration_after_max_vel_limit_factor of the original work
CONFLICT_TOL = 1e-3  # klimits: ranges overlapping by less than this count as conflicting
OUTSIDE_TOL = 1e-9  # positions this far beyond a limit are rounding (stops end exactly on the limit)
KNOT_SLACK = 0.3  # the knot refinement lowers the greedy bound by less than this times acc (<0.2 seen)
VEL_SKIP_MARGIN = 0.25  # see _velocity_side
PLAN_MARGIN = 1e-10  # braking plans stop this far (rad or m) inside the limit; absorbs rounding


@dataclass(frozen=True)
class JointLimits:
    """Kinematic joint limits as float64 tensors.

    Attributes:
        pos: (D, 2) position limits [lower, upper] (rad or m).
        vel, acc, jerk: (D,) symmetric magnitude limits (per s, s^2, s^3).
    """

    pos: Tensor
    vel: Tensor
    acc: Tensor
    jerk: Tensor

    def __post_init__(self) -> None:
        d = self.vel.shape[0]
        if self.pos.shape != (d, 2) or any(t.shape != (d,) for t in (self.acc, self.jerk)):
            raise ValueError("JointLimits: expected pos (D, 2) and vel/acc/jerk (D,)")
        if bool((self.pos[:, 0] >= self.pos[:, 1]).any()):
            raise ValueError("JointLimits: empty position range")
        if any(bool((t <= 0).any()) for t in (self.vel, self.acc, self.jerk)):
            raise ValueError("JointLimits: vel/acc/jerk limits must be positive")

    @classmethod
    def from_arrays(cls, pos, vel, acc, jerk, device: str | torch.device = "cpu") -> JointLimits:
        """Build from array-likes (converted to float64 tensors on ``device``)."""

        def f(x) -> Tensor:
            return torch.as_tensor(np.asarray(x, dtype=np.float64), device=device)

        return cls(f(pos), f(vel), f(acc), f(jerk))

    @classmethod
    def from_robot(cls, spec, device: str | torch.device = "cpu") -> JointLimits:
        """Limits of a :class:`pathrl.robot.model.RobotSpec` (joint order of ``spec.joints``)."""
        return cls.from_arrays(spec.pos_limits, spec.vel_limits, spec.acc_limits, spec.jerk_limits, device)

    def to(self, device: str | torch.device) -> JointLimits:
        """Copy onto ``device``."""
        return JointLimits(*(t.to(device) for t in (self.pos, self.vel, self.acc, self.jerk)))

    @property
    def dof(self) -> int:
        """Number of joints D."""
        return int(self.vel.shape[0])


def _nearest_to_zero(a_min: Tensor, a_max: Tensor) -> Tensor:
    """The admissible acceleration nearest 0, ``clip(0, a_min, a_max)``; (N, D)."""
    return torch.minimum(torch.maximum(torch.zeros_like(a_min), a_min), a_max)


def action_to_acceleration(action: Tensor, a_min: Tensor, a_max: Tensor, hold: Tensor | None = None) -> Tensor:
    """Map actions in [-1, 1] (clipped) onto ``[a_min, a_max]``; all (N, D).

    Linear by default (the paper's mapping). Joints where ``hold`` (D,) bool is set map piecewise linearly
    around the admissible acceleration nearest 0, ``c = clip(0, a_min, a_max)``: -1 -> a_min, 0 -> c,
    1 -> a_max. Action 0 then keeps such a joint's velocity whenever the limits allow it, so a joint at rest
    stays at rest even at a position limit, where the linear mapping's midpoint would accelerate it.
    """
    action = action.clamp(-1.0, 1.0)
    linear = a_min + 0.5 * (1.0 + action) * (a_max - a_min)
    if hold is None or not bool(hold.any()):
        return linear
    c = _nearest_to_zero(a_min, a_max)
    centred = torch.where(action >= 0.0, c + action * (a_max - c), c + action * (c - a_min))
    return torch.where(hold, centred, linear)


def acceleration_to_action(acc: Tensor, a_min: Tensor, a_max: Tensor) -> Tensor:
    """Inverse of the centred mapping of :func:`action_to_acceleration`: the action in [-1, 1] whose
    acceleration is `acc` (clipped into ``[a_min, a_max]``); all (N, D)."""
    c = _nearest_to_zero(a_min, a_max)
    up = (acc - c) / (a_max - c).clamp(min=1e-12)
    down = (acc - c) / (c - a_min).clamp(min=1e-12)
    return torch.where(acc >= c, up, down).clamp(-1.0, 1.0)


def valid_acceleration_range(p: Tensor, v: Tensor, a: Tensor, limits: JointLimits, dt: float = DEFAULT_DT,
                             backend: LimitBackend | None = None) -> tuple[Tensor, Tensor]:
    """Valid range for the acceleration at the end of the next step.

    Args:
        p, v, a: (N, D) float64 position, velocity, acceleration at the current decision step.
        limits: joint limits (D joints).
        dt: decision step (s).
        backend: the limit code to run (None: the one in effect, :func:`pathrl.limits.backend.current`).

    Returns:
        ``(a_min, a_max)``, each (N, D), physical units, ``a_min <= a_max``, within ``[-acc, acc]``.
    """
    lo, hi, _ = _valid_range(p, v, a, limits, dt, stop_at_knot=True, backend=backend)
    return lo, hi


def _valid_range(p: Tensor, v: Tensor, a: Tensor, limits: JointLimits, dt: float, stop_at_knot: bool,
                 backend: LimitBackend | None = None) -> tuple[Tensor, Tensor, Tensor]:
    """:func:`valid_acceleration_range` plus a (N, D) mask: the jerk, velocity and position ranges
    overlap inside ``[-acc, acc]`` (no conflict had to be resolved; the state is in the valid set).

    ``stop_at_knot=False`` drops klimits' stop-on-a-knot refinement and the velocity-aware braking (the
    result then equals klimits with ``set_velocity_after_max_pos_to_zero=False``; tests only, it is not
    safe in general).

    Runs the native build (:mod:`pathrl.native`) for float64 CPU tensors if `backend` (None: the one in effect)
    has ``native`` set (the default) and the build is available, else the torch code below, its kernels compiled
    as `backend` says.
    """
    backend = backend or current()
    with backend.active():  # the kernels below (and the reach radius) compile as `backend` says
        if backend.native and native.applies(p, v, a, limits.pos, limits.vel, limits.acc, limits.jerk):
            return native.valid_range(p, v, a, limits.pos, limits.vel, limits.acc, limits.jerk,
                                      _reach_radius(limits, dt), dt, stop_at_knot)
        return _valid_range_torch(p, v, a, limits, dt, stop_at_knot)


def _valid_range_torch(p: Tensor, v: Tensor, a: Tensor, limits: JointLimits, dt: float,
                       stop_at_knot: bool) -> tuple[Tensor, Tensor, Tensor]:
    """The torch reference of :func:`_valid_range` (runs on any device and dtype)."""
    amax, jmax, vmax = limits.acc, limits.jerk, limits.vel
    # Side 0 bounds from above; side 1 is the mirrored joint, whose upper bound is minus the lower bound.
    p0, v0, a0 = torch.stack((p, -p)), torch.stack((v, -v)), torch.stack((a, -a))
    pmax = torch.stack((limits.pos[:, 1], -limits.pos[:, 0])).unsqueeze(1)  # (2, 1, D)
    jerk_hi = a0 + jmax * dt
    vel_hi = _velocity_side(v0, a0, vmax, amax, jmax, dt)
    cap = torch.minimum(torch.minimum(jerk_hi, vel_hi), amax)
    pos_hi, knot_hi = _position_side(p0, v0, a0, pmax, limits, dt, cap, stop_at_knot)
    lo, hi, overlap = _combine(jerk_hi, vel_hi, pos_hi, knot_hi)
    overlap &= (hi >= -amax) & (lo <= amax)
    return lo.clamp(-amax, amax), hi.clamp(-amax, amax), overlap


def _velocity_side(v0: Tensor, a0: Tensor, vmax: Tensor, amax: Tensor, jmax: Tensor, dt: float) -> Tensor:
    """(2, N, D) velocity upper bound per side (+inf where it cannot bind), klimits' emergency overrides.

    The bound depends on the state only through ``c = v0 + a0*dt/2`` (until ``c`` reaches the limit)
    and falls with ``c``; it is at least ``amax`` for ``c <= vmax - (amax*dt + amax**2/jmax)/2`` minus a
    margin of ``VEL_SKIP_MARGIN*amax*dt`` (the settling knot lowers it by < 0.08*amax*dt). Only the
    other elements are evaluated.
    """
    c = v0 + 0.5 * dt * a0
    skip_below = vmax - 0.5 * (amax * dt + amax * amax / jmax) - VEL_SKIP_MARGIN * amax * dt
    bound = torch.full_like(v0, float("inf"))
    urgent = torch.zeros_like(v0, dtype=torch.bool)
    idx = (c > skip_below).reshape(-1).nonzero().squeeze(-1)
    if idx.numel():
        joint = idx % v0.shape[-1]
        vs, as_ = pick(v0.reshape(-1), idx), pick(a0.reshape(-1), idx)
        lim = (pick(vmax, joint), pick(amax, joint), pick(jmax, joint))
        bound.view(-1)[idx] = velocity_bound(vs, as_, *lim, dt, SETTLE_FACTOR)
        urgent.view(-1)[idx] = velocity_emergency(vs, as_, lim[0], lim[1], dt)
    bound = torch.where(urgent.flip(0), amax, bound)  # the other side must brake: klimits leaves +acc here
    return torch.where(urgent, -amax, bound)


def _position_side(p0: Tensor, v0: Tensor, a0: Tensor, pmax: Tensor, limits: JointLimits, dt: float,
                   cap: Tensor, stop_at_knot: bool) -> tuple[Tensor, Tensor]:
    """(2, N, D) safe and knot-refined position upper bounds per side (+inf where irrelevant).

    Only elements whose braking could reach the limit for some ``x <= cap + KNOT_SLACK*acc`` are
    computed: a per-joint radius prunes most, a cheap per-element bound the rest.
    """
    amax, jmax, vmax = limits.acc, limits.jerk, limits.vel
    shape = p0.shape
    safe = torch.full(shape, float("inf"), dtype=p0.dtype, device=p0.device)
    knot = safe.clone()
    radius = _reach_radius(limits, dt)
    near = ((pmax - p0) <= radius).reshape(-1).nonzero().squeeze(-1)
    if near.numel() == 0:
        return safe, knot
    joint = near % shape[-1]
    side = near // (shape[-1] * shape[-2])
    s = Side(*(pick(t.reshape(-1), near) for t in (p0, v0, a0)), pmax[side, 0, joint],
             *(pick(t, joint) for t in (amax, jmax, vmax)))
    probe = pick(cap.reshape(-1), near) + KNOT_SLACK * s.amax
    keep = (reach_top(s.p, s.v, s.a, s.amax, s.jmax, dt, probe) >= s.pmax - 1e-9).nonzero().squeeze(-1)
    if keep.numel() == 0:
        return safe, knot
    sf, kn = _position_subset(s.take(keep), dt, pick(probe, keep), stop_at_knot)
    at = pick(near, keep)
    safe.view(-1).index_copy_(0, at, sf)
    knot.view(-1).index_copy_(0, at, kn)
    return safe, knot


def _reach_radius(limits: JointLimits, dt: float) -> Tensor:
    """(D,) farthest a joint at full speed can still travel towards a limit (cached per limits and ``dt``)."""
    cache = limits.__dict__.setdefault("_reach_radius", {})  # frozen dataclass: a plain per-instance cache
    if dt not in cache:
        zero = torch.zeros_like(limits.vel)
        amax = limits.acc
        cache[dt] = reach_top(zero, limits.vel, amax, amax, limits.jerk, dt, (1.0 + KNOT_SLACK) * amax)
    return cache[dt]


def _position_subset(s: Side, dt: float, probe: Tensor, stop_at_knot: bool) -> tuple[Tensor, Tensor]:
    """Safe (velocity-aware greedy) and knot-refined bounds for a flat subset of elements."""
    inside = in_step_bound(s, dt)
    s.pmax = s.pmax - PLAN_MARGIN  # plans end slightly inside, so the next in-step check has slack
    floor_at_rest = velocity_floor(torch.zeros_like(s.v), -s.amax, s.vmax, s.amax, s.jmax, dt, SETTLE_FACTOR)
    idx, greedy, safe, peak = greedy_bound(s, dt, probe, SETTLE_FACTOR, aware=floor_at_rest > -s.amax)
    after = torch.full_like(probe, float("inf"))
    plain, after_safe = after.clone(), after.clone()
    plain[idx], after_safe[idx] = greedy, safe
    outside = s.p > s.pmax + PLAN_MARGIN + OUTSIDE_TOL  # klimits: reach the limit at the step end
    recover = 6.0 * (s.pmax - s.p - s.v * dt) / dt**2 - 2.0 * s.a
    plain = torch.where(outside, recover, torch.minimum(inside, plain))
    if not stop_at_knot:  # klimits with set_velocity_after_max_pos_to_zero=False (tests only)
        return plain, plain
    safe_all = torch.where(outside, recover, torch.minimum(inside, after_safe))
    # klimits' refinement follows the greedy peak after the step even where the in-step bound is tighter.
    knot = torch.full_like(probe, float("inf"))
    knot[idx] = knot_stop_bound(s.take(idx), dt, peak)
    return safe_all, torch.where(outside, safe_all, torch.minimum(knot, safe_all))


@kernel(static=True)
def _combine(jerk_hi: Tensor, vel_hi: Tensor, pos_hi: Tensor, knot_hi: Tensor
             ) -> tuple[Tensor, Tensor, Tensor]:
    """Intersect the (2, N, D) per-side upper bounds; returns (lo, hi, overlap) in joint coordinates.

    Like klimits: the stop-on-a-knot position range replaces the plain one unless it is empty (by
    more than ``CONFLICT_TOL``). If the jerk, velocity and position ranges do not overlap (a state
    outside the valid set; never reached from inside it), klimits drops the jerk range, then the
    velocity range. Here the jerk range is dropped first as well, but then the position range: a
    velocity violation forced by an unreachable position bound snowballs (seen with jerk/acc ratios
    of 10/s), while a small position excess does not. The remaining range is reduced to its point
    closest to the dropped one.
    """
    lo_k, hi_k = -knot_hi[1], knot_hi[0]
    crossed = lo_k > hi_k
    mid = 0.5 * (lo_k + hi_k)
    refine = lo_k - hi_k < CONFLICT_TOL
    lo_p = torch.where(refine, torch.where(crossed, mid, lo_k), -pos_hi[1])
    hi_p = torch.where(refine, torch.where(crossed, mid, hi_k), pos_hi[0])
    lo_v, hi_v = -vel_hi[1], vel_hi[0]
    lo_j, hi_j = -jerk_hi[1], jerk_hi[0]
    lo = torch.maximum(torch.maximum(lo_j, lo_v), lo_p)
    hi = torch.minimum(torch.minimum(hi_j, hi_v), hi_p)
    overlap = lo <= hi
    lo_vp, hi_vp = torch.maximum(lo_v, lo_p), torch.minimum(hi_v, hi_p)
    bad_vp = lo_vp - hi_vp > CONFLICT_TOL  # velocity against position: keep velocity
    lo_vp = torch.where(bad_vp, torch.where(lo_p > hi_v, hi_v, lo_v), lo_vp)
    hi_vp = torch.where(bad_vp, lo_vp, hi_vp)
    bad = lo - hi > CONFLICT_TOL  # jerk against the rest: keep the rest
    lo = torch.where(bad, torch.where(lo_vp > hi_j, lo_vp, hi_vp), lo)
    hi = torch.where(bad, lo, hi)
    mid = 0.5 * (lo + hi)
    crossed = lo > hi
    return torch.where(crossed, mid, lo), torch.where(crossed, mid, hi), overlap
