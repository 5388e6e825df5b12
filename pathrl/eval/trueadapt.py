"""Evaluate a TrueAdapt policy (or the reference without adaptation) on given trajectories of a bank.

Paper metrics (TrueAdapt Sec. VIII, Table I), per trajectory: success (on plate: the ball never reaches the
border; in place: never more than ``max_ball_offset`` from its start; and no joint deviated beyond the
termination threshold), the fraction of the trajectory executed before the task failed, the mean normalised
|acceleration| and |jerk| over joints and steps, and the mean distance of the ball from its start (error distance).
For diagnosis also why a trajectory failed: ``lost`` (the task failed: ball at the border / too far from its start /
off the plate) and ``deviation_end`` (the episode was cut by the joint deviation termination: its
``env.termination`` reason is ``DEVIATION``).
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from pathrl.envs.terminations import TerminationReason
from pathrl.envs.trueadapt import TrueAdaptEnv
from pathrl.eval.rollout import reset_memory

__all__ = ["METRICS", "OUTCOMES", "ObservingPolicy", "evaluate", "reference_policy", "run_trajectories", "summary"]

Policy = Callable[[TrueAdaptEnv], Tensor]


def reference_policy(env: TrueAdaptEnv) -> Tensor:
    """No adaptation: replay the reference's accelerations."""
    return env.reference_actions()


class ObservingPolicy:
    """A :data:`Policy` of an actor (observations -> actions (N, D)), e.g. a policy network or a controller:
    ``policy(env)`` acts on the env's observations; ``reset()`` clears a recurrent actor's memory (a new batch of
    episodes starts)."""

    def __init__(self, actor: Callable[..., Tensor]):
        self.actor = actor

    def __call__(self, env: TrueAdaptEnv) -> Tensor:
        """The actor's actions (N, D) on the env's current observations."""
        return self.actor(env.get_observations())

    def reset(self) -> None:
        """Clear the actor's hidden state, if it has one."""
        reset_memory(self.actor)


#: Per-trajectory outcomes (0/1) and metrics of :func:`run_trajectories`: success and failed (the ball was lost,
#: ``env.failed``) from ``env.last_step``, dev_terminated from ``env.termination``.
OUTCOMES = ("success", "failed", "dev_terminated")
METRICS = ("fraction", "acc", "jerk", "offset")


def run_trajectories(env: TrueAdaptEnv, policy: Policy, batch: Tensor,
                     on_step: Callable[[Tensor], None] | None = None) -> dict[str, Tensor]:
    """Run the trajectories `batch` (bank indices (n,), n <= num_envs) in envs 0..n-1 to their first ending; per
    trajectory (n,) float64 CPU values of :data:`OUTCOMES` and :data:`METRICS`. `on_step(stepped)` runs after the
    start (stepped all False) and after every step, stepped (n,) bool marking the episodes that were still running
    in it (a recorder's hook). Envs whose episode ended keep stepping until the batch is done (autoreset off),
    their ball no longer simulated (``env.simulated``)."""
    if env.cfg.autoreset:
        raise ValueError("run_trajectories: build the env with autoreset=False")
    n = len(batch)
    ids = torch.arange(n, device=env.device)
    env.start(ids, batch.to(env.device))
    reset_memory(policy)
    out = {k: torch.zeros(n, dtype=torch.float64) for k in (*OUTCOMES, *METRICS)}
    pending = torch.zeros(env.num_envs, dtype=torch.bool, device=env.device)
    pending[ids] = True
    if on_step is not None:
        on_step(torch.zeros(n, dtype=torch.bool))
    env.simulated = pending.clone()  # the ball of an ended episode is not simulated (its values are never read)
    try:
        while bool(pending.any()):
            with torch.no_grad():
                env.step(policy(env))
            if on_step is not None:
                on_step(pending[:n].cpu())
            done = (env.termination != TerminationReason.NONE) & pending
            if bool(done.any()):
                _record_ended(env, done, n, out)
                pending &= ~done
                env.simulated = pending.clone()
    finally:
        env.simulated = None
    return out


def _record_ended(env: TrueAdaptEnv, done: Tensor, n: int, out: dict[str, Tensor]) -> None:
    """Write the outcomes and metrics of the episodes that ended in this step (done (N,) bool) into `out`."""
    m = env.episode_metrics(done)
    at = done[:n].nonzero().squeeze(1).cpu()
    outcome = {"success": env.last_step["success"], "failed": env.last_step["failed"],
               "dev_terminated": env.termination == TerminationReason.DEVIATION}
    for k in OUTCOMES:
        out[k][at] = outcome[k][done].double().cpu()
    for k in METRICS:
        out[k][at] = m[k].double().cpu()


def evaluate(env: TrueAdaptEnv, policy: Policy, trajectories: Tensor,
             on_step: Callable[[Tensor], None] | None = None) -> dict[str, Tensor]:
    """Run every trajectory (bank indices (M,)) once, ``env.num_envs`` at a time; per-trajectory metrics (M,):
    :data:`METRICS`, ``success``, ``lost`` (the task failed) and ``deviation_end`` (cut by the deviation limit).
    `on_step`: :func:`run_trajectories`' hook, for every batch (e.g. ``trueadapt_limits.LimitCounter``).

    The env must have ``autoreset=False``: an env whose episode ended keeps stepping until its batch is done,
    and only its first ending counts.
    """
    names = {"success": "success", "lost": "failed", "deviation_end": "dev_terminated", **{k: k for k in METRICS}}
    out = {k: torch.zeros(len(trajectories), dtype=torch.float64) for k in names}
    for lo in range(0, len(trajectories), env.num_envs):
        batch = run_trajectories(env, policy, trajectories[lo:lo + env.num_envs], on_step)
        for k, name in names.items():
            out[k][lo:lo + len(batch[name])] = batch[name]
    return out


def summary(metrics: dict[str, Tensor]) -> dict[str, float]:
    """Means over trajectories (success and fraction as shares, offset in m)."""
    return {k: float(v.mean()) for k, v in metrics.items()} | {"episodes": len(metrics["success"])}
