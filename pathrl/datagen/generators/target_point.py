"""``target_point`` generator: paths through random Cartesian target points reached by IK (docs/datasets.md)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from pathrl.datagen.generators.context import GeneratorContext
from pathrl.datagen.generators.ik import solve_ik
from pathrl.datagen.generators.rollout import stored_rollout_paths
from pathrl.robot.model import RobotSpec

__all__ = ["KIND", "check_robot", "stored_paths"]

KIND = "target_point"


class _TargetPolicy:
    """Head for a queue of IK goals (``approach``) plus action noise; a checkpoint at every goal switch."""

    def __init__(self, ctx: GeneratorContext, p: Mapping[str, Any], n: int, rng: np.random.Generator, tgen):
        self.ctx, self.p, self.rng, self.tgen = ctx, p, rng, tgen
        self.goal = torch.zeros(n, ctx.spec.dof, dtype=torch.float64)
        self.goal_steps = torch.zeros(n, dtype=torch.long)
        self.w = float(p["gain"])
        self.approach = str(p["approach"])
        self.cruise = float(p["cruise"]) * torch.as_tensor(ctx.spec.vel_limits, dtype=torch.float64)
        self.noise = float(p["action_noise"])
        self.tol = float(p["goal_tolerance"])
        self.timeout = int(round(float(p["goal_timeout"]) / float(p["dt"])))
        self.num_goals = torch.zeros(n, dtype=torch.long)

    def solve_goals(self, q_from: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """One IK goal per row of q_from (n, D): (goals (n, D), failed (n,)).

        Each round solves ``ik_candidates`` random targets per row in one batch and keeps the first
        valid solution (IK converged, >= min_goal_distance away from q_from, collision free).
        """
        ctx, p = self.ctx, self.p
        d = ctx.spec.dof
        k = int(p["ik_candidates"])
        goals = q_from.clone()
        todo = torch.arange(len(q_from))
        failed = torch.ones(len(q_from), dtype=torch.bool)
        for _ in range(int(p["ik_rounds"])):
            if len(todo) == 0:
                break
            n = len(todo)
            tgt = torch.as_tensor(ctx.sample_targets(self.rng, n * k))
            base = q_from[todo].repeat_interleave(k, dim=0)
            seed = base + torch.as_tensor(self.rng.normal(0.0, 0.3, size=(n * k, d)))
            seed = torch.minimum(torch.maximum(seed, ctx.lo), ctx.hi)
            q, ok = solve_ik(ctx, seed, tgt, int(p["ik_iterations"]), float(p["ik_tolerance"]))
            ok &= (q[:, ctx.pidx] - base[:, ctx.pidx]).norm(dim=1) >= float(p["min_goal_distance"])
            ok = ok.reshape(n, k)
            q = q.reshape(n, k, d)
            # collision-check candidates in order until each row has one valid goal
            chosen = torch.full((n,), -1, dtype=torch.long)
            for j in range(k):
                cand = ((chosen < 0) & ok[:, j]).nonzero().squeeze(1)
                if len(cand) == 0:
                    continue
                free = torch.as_tensor(~ctx.in_collision(q[cand, j]))
                chosen[cand[free]] = j
            got = (chosen >= 0).nonzero().squeeze(1)
            goals[todo[got]] = q[got, chosen[got]]
            failed[todo[got]] = False
            todo = todo[chosen < 0]
        return goals, failed

    def _refill(self, rows: torch.Tensor, q_from: torch.Tensor) -> None:
        """Append ``goal_batch`` chained goals (each from the previous one) to the queues of `rows`."""
        last = torch.stack([self.queue[r][-1] if self.queue[r] else q_from[i] for i, r in enumerate(rows.tolist())])
        for _ in range(int(self.p["goal_batch"])):
            last, failed = self.solve_goals(last)
            for i, r in enumerate(rows.tolist()):
                if not failed[i]:
                    self.queue[r].append(last[i])

    def new_goals(self, rows: torch.Tensor, q_from: torch.Tensor) -> torch.Tensor:
        """Next goal for each of `rows` (at q_from) from its queue; queues are refilled in batches.

        Queued goals closer than ``min_goal_distance`` to q_from are skipped. Returns the failure mask.
        """
        min_d = float(self.p["min_goal_distance"])
        failed = torch.ones(len(rows), dtype=torch.bool)
        for attempt in range(2):
            for i, r in enumerate(rows.tolist()):
                if not failed[i]:
                    continue
                while self.queue[r]:
                    g = self.queue[r].pop(0)
                    if (g[self.ctx.pidx] - q_from[i, self.ctx.pidx]).norm() >= min_d:
                        self.goal[r] = g
                        self.goal_steps[r] = 0
                        self.num_goals[r] += 1
                        failed[i] = False
                        break
            if attempt == 0:
                # refill every live row that ran dry (plus rows about to), in one batch
                low = [r for r in range(len(self.queue)) if len(self.queue[r]) <= 1 and self.live[r]]
                need = [int(r) for r in rows[failed].tolist()]
                refill = sorted(set(low) | set(need))
                if not need:
                    break
                q_from_all = self.goal.clone()
                q_from_all[rows] = q_from
                self._refill(torch.as_tensor(refill, dtype=torch.long), q_from_all[refill])
        return failed

    def reset(self, q0: torch.Tensor) -> torch.Tensor:
        self.queue: list[list[torch.Tensor]] = [[] for _ in range(len(q0))]
        self.live = torch.ones(len(q0), dtype=torch.bool)
        failed = self.new_goals(torch.arange(len(q0)), q0)
        self.live &= ~failed
        return failed

    def action(self, rows, p, v, a, a_min, a_max) -> torch.Tensor:
        e = self.goal[rows] - p
        if self.approach == "pd":
            a_des = self.w**2 * e - 2.0 * self.w * v
        elif self.approach == "pursuit":  # head for the goal at cruise speed (slowest joint at `cruise` x its limit)
            scale = (e.abs() / self.cruise).amax(dim=1, keepdim=True).clamp(min=1e-9)
            a_des = self.w * (e / scale - v)
        else:  # every joint on its own: toward its goal value at up to `cruise` x its velocity limit
            a_des = self.w * (torch.maximum(torch.minimum(self.w * e, self.cruise), -self.cruise) - v)
        rng_ = (a_max - a_min).clamp(min=1e-12)
        act = 2.0 * (a_des - a_min) / rng_ - 1.0
        if self.noise > 0:
            act = act + self.noise * (torch.rand(act.shape, generator=self.tgen, dtype=torch.float64) * 2 - 1)
        return act.clamp(-1.0, 1.0)

    def after_step(self, rows, p, steps) -> tuple[torch.Tensor, torch.Tensor]:
        self.goal_steps[rows] += 1
        e = (self.goal[rows] - p)[:, self.ctx.pidx].norm(dim=1)
        switch = (e < self.tol) | (self.goal_steps[rows] >= self.timeout)
        reject = torch.zeros(len(rows), dtype=torch.bool)
        if switch.any():
            sw = switch.nonzero().squeeze(1)
            reject[sw] = self.new_goals(rows[sw], p[sw])
        return switch & ~reject, reject

    def finished(self, rows: torch.Tensor) -> None:
        """Rows that no longer need goals (done or dropped): their queues are not refilled."""
        self.live[rows] = False
        for r in rows.tolist():
            self.queue[r] = []

    def on_rewind(self, rows, p) -> torch.Tensor:
        return self.new_goals(rows, p)

def check_robot(spec: RobotSpec) -> None:
    """Any robot whose joints are all path joints (checked by :func:`generate_paths`)."""


def stored_paths(
    ctx: GeneratorContext,
    params: Mapping[str, Any],
    n: int,
    rng: np.random.Generator,
    tgen: torch.Generator,
    stats: dict[str, int],
) -> list[np.ndarray]:
    """`n` stored paths of one chunk (:func:`pathrl.datagen.generators.rollout.stored_rollout_paths`)."""
    return stored_rollout_paths(ctx, lambda b: _TargetPolicy(ctx, params, b, rng, tgen), params, n, rng, stats)

