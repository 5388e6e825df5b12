"""Count kinematic limit violations of sampled trajectories (learned policies and TOPP-RA alike).

Tolerance: a sample violates a limit only if it exceeds it by more than ``rtol`` times the limit's
scale: the magnitude limit for velocity, acceleration and jerk, and the width of the position range
for position. The default ``rtol = 1e-6`` absorbs floating-point rounding of exact-at-the-limit
trajectories (time-optimal ones ride their limits) but no real excess.
"""

from __future__ import annotations

import torch
from torch import Tensor

from pathrl.limits.feasible import JointLimits

__all__ = ["KINDS", "limit_violations"]


KINDS = ("position", "velocity", "acceleration", "jerk")


def limit_violations(p: Tensor, v: Tensor, a: Tensor, limits: JointLimits, dt_control: float,
                     rtol: float = 1e-6) -> dict[str, Tensor]:
    """Number of violating samples per kind and in total.

    Args:
        p, v, a: (N, T, D) or (T, D) control-rate samples (position, velocity, acceleration).
        limits: joint limits (D joints).
        dt_control: sample period (s); the jerk is the finite difference of consecutive accelerations
            divided by it (exact for piecewise-linear accelerations whose knots are samples).
        rtol: relative tolerance (see module docstring).

    Returns:
        ``{"position", "velocity", "acceleration", "jerk", "total"}``: int64 counts of (sample, joint)
        pairs, shape (N,) or () for (T, D) input. Jerk has T-1 samples per joint.
    """
    lo, hi = limits.pos[:, 0], limits.pos[:, 1]
    pos_tol = rtol * (hi - lo)
    jerk = (a[..., 1:, :] - a[..., :-1, :]) / dt_control
    bad = {
        "position": (p < lo - pos_tol) | (p > hi + pos_tol),
        "velocity": v.abs() > limits.vel * (1.0 + rtol),
        "acceleration": a.abs() > limits.acc * (1.0 + rtol),
        "jerk": jerk.abs() > limits.jerk * (1.0 + rtol),
    }
    counts = {k: m.sum(dim=(-2, -1)) for k, m in bad.items()}
    counts["total"] = torch.stack([counts[k] for k in KINDS]).sum(0)
    return counts
