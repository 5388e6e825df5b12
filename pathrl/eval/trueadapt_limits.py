"""Limit check of evaluated TrueAdapt episodes: every commanded control-rate setpoint against the robot's limits.

:class:`LimitCounter` is an ``on_step`` hook of :func:`pathrl.eval.trueadapt.run_trajectories` (and ``evaluate``).
Per decision step it checks the step's setpoints (the env's linear acceleration interpolation, 240 Hz) of every
episode that was still running, the step's start included (so the jerk across the step boundary is checked), with
:func:`pathrl.limits.check.limit_violations` (float64, relative tolerance 1e-6), like the Sec. VI-D validation.
"""

from __future__ import annotations

import torch
from torch import Tensor

from pathrl.envs.trueadapt import TrueAdaptEnv
from pathrl.limits.check import KINDS, limit_violations
from pathrl.limits.feasible import JointLimits

__all__ = ["LimitCounter"]


class LimitCounter:
    """Counts (setpoint, joint) limit violations of the episodes an evaluation runs, against `limits` (default:
    the env's own); switches on the env's ``record_setpoints``. ``counts`` holds per kind and ``"total"``;
    ``checked`` the (setpoint, joint) pairs."""

    def __init__(self, env: TrueAdaptEnv, limits: JointLimits | None = None) -> None:
        env.record_setpoints = True
        self.env = env
        self.limits = env.limits if limits is None else limits
        self.counts = dict.fromkeys((*KINDS, "total"), 0)
        self.checked = 0
        self._start: tuple[Tensor, Tensor, Tensor] | None = None

    def __call__(self, stepped: Tensor) -> None:
        """`stepped` (n,) bool: which of envs 0..n-1 ran an episode step just now (all False right after start)."""
        env = self.env
        n = len(stepped)
        if bool(stepped.any()) and self._start is not None:
            idx = stepped.nonzero().squeeze(1).to(env.device)
            p0, v0, a0 = (x[idx].unsqueeze(1) for x in self._start)
            s = env.last_step
            q = torch.cat([p0, s["q_control"][idx]], dim=1)
            v = torch.cat([v0, s["v_control"][idx]], dim=1)
            a = torch.cat([a0, s["a_control"][idx]], dim=1)
            c = limit_violations(q, v, a, self.limits, 1.0 / env.cfg.control_rate)
            for k in self.counts:
                self.counts[k] += int(c[k].sum())
            self.checked += int(s["q_control"][idx].numel())
        self._start = (env.pos[:n].clone(), env.vel[:n].clone(), env.acc[:n].clone())
