"""Evaluate a TrueAdapt policy (or the reference without adaptation) on given trajectories of a bank.

Paper metrics (TrueAdapt Sec. VIII, Table I), per trajectory: success (on plate: the ball never reaches the
border; in place: never more than ``max_ball_offset`` from its start; and no joint deviated beyond the
termination threshold), the fraction of the trajectory executed before the task failed, the mean normalised
|acceleration| and |jerk| over joints and steps, and the mean distance of the ball from its start (error distance).
For diagnosis also why a trajectory failed: ``lost`` (the task failed: ball at the border / too far from its start /
off the plate) and ``deviation_end`` (the episode was cut by the joint deviation termination).
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from pathrl.envs.trueadapt import TrueAdaptEnv

Policy = Callable[[TrueAdaptEnv], Tensor]


def reference_policy(env: TrueAdaptEnv) -> Tensor:
    """No adaptation: replay the reference's accelerations."""
    return env.reference_actions()


def evaluate(env: TrueAdaptEnv, policy: Policy, trajectories: Tensor) -> dict[str, Tensor]:
    """Run every trajectory (bank indices (M,)) once, ``env.num_envs`` at a time; per-trajectory metrics (M,).

    The env must have ``autoreset=False``: an env whose episode ended keeps stepping until its batch is done,
    and only its first ending counts.
    """
    if env.cfg.autoreset:
        raise ValueError("evaluate: build the env with autoreset=False")
    keys = ("success", "fraction", "acc", "jerk", "offset")
    flags = {"lost": "failed", "deviation_end": "dev_terminated"}
    out = {k: torch.zeros(len(trajectories), dtype=torch.float64) for k in (*keys, *flags)}
    n = env.num_envs
    for lo in range(0, len(trajectories), n):
        batch = trajectories[lo:lo + n]
        ids = torch.arange(len(batch), device=env.device)
        env.start(ids, batch.to(env.device))
        pending = torch.zeros(n, dtype=torch.bool, device=env.device)
        pending[ids] = True
        while bool(pending.any()):
            with torch.no_grad():
                env.step(policy(env))
            done = env.last_step["dones"] & pending
            if bool(done.any()):
                m = env.episode_metrics(done)
                at = lo + done.nonzero().squeeze(1).cpu()
                out["success"][at] = env.last_step["success"][done].double().cpu()
                for k, name in flags.items():
                    out[k][at] = env.last_step[name][done].double().cpu()
                for k in keys[1:]:
                    out[k][at] = m[k].cpu()
                pending &= ~done
    return out


def summary(metrics: dict[str, Tensor]) -> dict[str, float]:
    """Means over trajectories (success and fraction as shares, offset in m)."""
    return {k: float(v.mean()) for k, v in metrics.items()} | {"episodes": len(metrics["success"])}
