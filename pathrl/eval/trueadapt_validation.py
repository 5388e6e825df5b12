"""Limit validation like TrueAdapt Sec. VI-D: many random trajectories whose every acceleration is drawn from the
valid range (or is its maximum), integrated with linear acceleration interpolation and checked at the control rate.

Each trajectory starts at rest at a uniform random position inside the position limits (position, velocity and
acceleration 0 are always in the valid set). Every decision step the next acceleration is uniform in the valid
range (``mode="random"``, the paper's Fig. 6), or its upper end (``mode="max"``, Fig. 5: limited first by the jerk,
then by the acceleration, velocity and position limits). The step's control-rate setpoints, the jerk within the
step included, are counted by :func:`pathrl.limits.check.limit_violations` (float64, relative tolerance 1e-6).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import torch

from pathrl.limits.check import KINDS, limit_violations
from pathrl.limits.feasible import JointLimits, valid_acceleration_range
from pathrl.limits.integrate import end_of_step, interpolate_step

__all__ = ["MODES", "ValidationResult", "trace", "validate"]

MODES = ("random", "max")


@dataclass
class ValidationResult:
    """Outcome of a limit validation: trajectories, steps, mode, setpoints checked, violations per kind (and ``total``),
    the largest |v| / v_max, |a| / a_max, |j| / j_max reached and wall time (s)."""

    trajectories: int
    steps: int  # decision steps per trajectory
    mode: str
    setpoints_checked: int  # (setpoint, joint) pairs
    violations: dict[str, int] = field(default_factory=dict)  # per kind and "total"
    max_ratio: dict[str, float] = field(default_factory=dict)  # max |v| / v_max, |a| / a_max, |j| / j_max reached
    seconds: float = 0.0


def validate(limits: JointLimits, trajectories: int, steps: int, dt: float = 0.05, control_rate: float = 240.0,
             mode: str = "random", seed: int = 0, batch: int = 20_000) -> ValidationResult:
    """Run and check `trajectories` random trajectories of `steps` decision steps (``batch`` at a time)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    n_sub = int(round(control_rate * dt))
    g = torch.Generator().manual_seed(seed)
    counts = dict.fromkeys((*KINDS, "total"), 0)
    top = {"velocity": 0.0, "acceleration": 0.0, "jerk": 0.0}
    lo_p, hi_p = limits.pos[:, 0], limits.pos[:, 1]
    t0, checked = time.perf_counter(), 0
    for start in range(0, trajectories, batch):
        n = min(batch, trajectories - start)
        p = lo_p + (hi_p - lo_p) * torch.rand(n, limits.dof, generator=g, dtype=torch.float64)
        v, a = torch.zeros_like(p), torch.zeros_like(p)
        for _ in range(steps):
            lo, hi = valid_acceleration_range(p, v, a, limits, dt)
            u = torch.rand(p.shape, generator=g, dtype=torch.float64)
            a1 = hi if mode == "max" else lo + u * (hi - lo)
            q_c, v_c, a_c = interpolate_step(p, v, a, a1, dt, n_sub)
            a_c = torch.cat([a.unsqueeze(1), a_c], dim=1)  # the step's start: its jerk is checked too
            q_c, v_c = torch.cat([p.unsqueeze(1), q_c], dim=1), torch.cat([v.unsqueeze(1), v_c], dim=1)
            c = limit_violations(q_c, v_c, a_c, limits, 1.0 / control_rate)
            for k in counts:
                counts[k] += int(c[k].sum())
            top["velocity"] = max(top["velocity"], float((v_c.abs() / limits.vel).max()))
            top["acceleration"] = max(top["acceleration"], float((a_c.abs() / limits.acc).max()))
            top["jerk"] = max(top["jerk"], float(((a1 - a).abs() / dt / limits.jerk).max()))
            checked += n_sub * p.numel()
            p, v = end_of_step(p, v, a, a1, dt)
            a = a1
    return ValidationResult(trajectories, steps, mode, checked, counts, top, time.perf_counter() - t0)


def trace(limits: JointLimits, steps: int, dt: float = 0.05, control_rate: float = 240.0, mode: str = "random",
          seed: int = 0, start: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """One trajectory of :func:`validate` recorded at the control rate (for plots like the paper's Figs. 5-6).

    `start`: (D,) initial position (default: uniform inside the limits). Returns t (T,) and p, v, a, j (T, D)
    from t = 0 (rest) to steps * dt; j is the (constant) jerk of the step a sample ends, 0 at t = 0.
    """
    n_sub = int(round(control_rate * dt))
    g = torch.Generator().manual_seed(seed)
    lo_p, hi_p = limits.pos[:, 0], limits.pos[:, 1]
    p = (lo_p + (hi_p - lo_p) * torch.rand(limits.dof, generator=g, dtype=torch.float64) if start is None
         else start.to(torch.float64).clone()).unsqueeze(0)
    v, a = torch.zeros_like(p), torch.zeros_like(p)
    out = {"p": [p], "v": [v], "a": [a], "j": [torch.zeros_like(p)]}
    for _ in range(steps):
        lo, hi = valid_acceleration_range(p, v, a, limits, dt)
        a1 = hi if mode == "max" else lo + torch.rand(p.shape, generator=g, dtype=torch.float64) * (hi - lo)
        q_c, v_c, a_c = interpolate_step(p, v, a, a1, dt, n_sub)
        out["p"].append(q_c[0])
        out["v"].append(v_c[0])
        out["a"].append(a_c[0])
        out["j"].append(((a1 - a) / dt).expand(n_sub, -1))
        p, v = end_of_step(p, v, a, a1, dt)
        a = a1
    res = {k: torch.cat(x) for k, x in out.items()}
    res["t"] = torch.arange(len(res["p"]), dtype=torch.float64) / control_rate
    return res
