"""Deterministic evaluation of a trained policy on an episode plan; records control-rate setpoints."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import torch
from tensordict import TensorDict
from torch import Tensor

from pathrl.envs.terminations import TerminationReason
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.limits.integrate import interpolate_step
from pathrl.paths.segments import Segments

__all__ = ["EpisodeRecord", "Policy", "reset_memory", "rollout"]


Policy = Callable[[TensorDict], Tensor]


@dataclass
class EpisodeRecord:
    """One evaluated episode. Arrays are at decision steps (T+1 incl. the start) and control rate."""

    episode: int
    path: int
    start_s: float
    end_s: float
    steps: int
    termination: str  # the TerminationReason's label: robot_stopped | deviation | task_failed | time_out
    reached_end: bool
    finish_step: int  # step in which the end of the path was reached (-1: never)
    pos: Tensor  # (T+1, D) decision-step states
    vel: Tensor
    acc: Tensor
    setpoints: Tensor  # (T*C+1, D) control-rate positions incl. the start
    setpoint_vel: Tensor
    setpoint_acc: Tensor
    extra: dict = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        """Episode duration (s): decision steps times the decision period."""
        return float(self.extra["dt"]) * self.steps


def reset_memory(policy: object) -> None:
    """Clear a recurrent policy's hidden state before a batch of new episodes (``policy.reset()``, as rsl-rl's
    models have it; a memoryless policy's reset does nothing, a plain function has none)."""
    reset = getattr(policy, "reset", None)
    if callable(reset):
        reset()


def rollout(env: PathTrackingEnv, policy: Policy, plan: Segments, progress: Callable[[int], None] | None = None,
            ) -> list[EpisodeRecord]:
    """Run every segment of `plan` once with `policy` (batches of env.num_envs); no auto-reset."""
    records: list[EpisodeRecord] = []
    n = env.num_envs
    c = int(round(env.cfg.control_rate * env.cfg.dt))
    for b0 in range(0, len(plan), n):
        ids = torch.arange(b0, min(b0 + n, len(plan)))
        records += _rollout_batch(env, policy, plan, ids, c)
        if progress is not None:
            progress(len(ids))
    return records


def _rollout_batch(env: PathTrackingEnv, policy: Policy, plan: Segments, ids: Tensor, c: int) -> list[EpisodeRecord]:
    k = len(ids)
    dev = env.device
    env_ids = torch.arange(k, device=dev)
    seg = plan.subset(ids).to(dev)
    env.start_segments(env_ids, seg)
    reset_memory(policy)
    active = torch.zeros(env.num_envs, dtype=torch.bool, device=dev)
    active[:k] = True
    done_step = torch.full((env.num_envs,), -1, dtype=torch.long, device=dev)
    term = [TerminationReason.TIME_OUT.label] * k  # episodes still running after the longest budget
    states = [(env.pos.clone(), env.vel.clone(), env.acc.clone())]
    series: list[dict[str, Tensor]] = []  # feedback values after every step (empty without a task)
    max_steps = int(math.ceil(float(env.budget[:k].max()))) + 1
    env.simulated = active.clone()  # the feedback of ended episodes is not simulated
    try:
        for t in range(max_steps):
            with torch.inference_mode():
                actions = policy(env.get_observations())
            _, _, dones, _ = env.step(actions)
            states.append((env.pos.clone(), env.vel.clone(), env.acc.clone()))
            if env.feedback is not None:
                series.append({key[5:]: v.clone() for key, v in env.last_step.items() if key.startswith("task/")})
            newly = dones & active & (done_step < 0)
            if bool(newly.any()):
                done_step[newly] = t + 1
                reasons = env.termination.tolist()
                for i in newly.nonzero().squeeze(1).tolist():
                    term[i] = TerminationReason(reasons[i]).label
                env.simulated = active & (done_step < 0)
            if bool((done_step[:k] >= 0).all()):
                break
    finally:
        env.simulated = None
    pos = torch.stack([s[0] for s in states], 1)  # (N, T+1, D)
    vel = torch.stack([s[1] for s in states], 1)
    acc = torch.stack([s[2] for s in states], 1)
    out = []
    for i in range(k):
        steps = int(done_step[i]) if int(done_step[i]) > 0 else pos.shape[1] - 1
        # the env kept stepping until the batch's last episode ended: an end reached after this one ended is not its
        finish = int(env.finish_step[i]) if int(env.finish_step[i]) <= steps else -1
        p, v, a = pos[i, : steps + 1], vel[i, : steps + 1], acc[i, : steps + 1]
        task_series = {key: torch.stack([s[key][i] for s in series[:steps]]).cpu()
                       for key in (series[0] if series else {})}
        sp, sv, sa = interpolate_step(p[:-1], v[:-1], a[:-1], a[1:], env.cfg.dt, c)  # (T, C, D)
        out.append(EpisodeRecord(
            episode=int(ids[i]),
            path=int(seg.path[i]),
            start_s=float(seg.start_s[i]),
            end_s=float(seg.end_s[i]),
            steps=steps,
            termination=term[i],
            reached_end=finish >= 0,
            finish_step=finish,
            pos=p.cpu(), vel=v.cpu(), acc=a.cpu(),
            setpoints=torch.cat([p[:1], sp.reshape(-1, p.shape[1])]).cpu(),
            setpoint_vel=torch.cat([v[:1], sv.reshape(-1, p.shape[1])]).cpu(),
            setpoint_acc=torch.cat([a[:1], sa.reshape(-1, p.shape[1])]).cpu(),
            # feedback after every step, and its values when the episode ended
            extra={"dt": env.cfg.dt, "control_dt": env.cfg.dt / c, "task_series": task_series,
                   "task": {key: float(v[-1]) for key, v in task_series.items()}},
        ))
    return out
