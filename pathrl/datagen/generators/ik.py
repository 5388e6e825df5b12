"""Start configurations and damped-least-squares inverse kinematics of the generators."""

from __future__ import annotations

import math

import numpy as np
import torch

from pathrl.datagen.generators.context import GenerationError, GeneratorContext

__all__ = ["sample_starts", "solve_ik"]


def sample_starts(ctx: GeneratorContext, rng: np.random.Generator, n: int, max_draws: int = 200_000) -> np.ndarray:
    """n configurations uniform in the position limits, collision free, every TCP in the workspace box."""
    lo, hi = ctx.gen_limits[:, 0], ctx.gen_limits[:, 1]
    out: list[np.ndarray] = []
    drawn = 0
    while len(out) < n:
        if drawn >= max_draws:
            raise GenerationError(
                f"{ctx.spec.name}: only {len(out)} of {n} valid start configurations in {drawn} draws "
                "(workspace box / collisions too restrictive?)"
            )
        q = rng.uniform(lo, hi, size=(max(8 * n, 64), ctx.spec.dof))
        drawn += len(q)
        q = q[ctx.in_workspace(q)]
        q = q[~ctx.in_collision(q)]
        out.extend(q)
    return np.asarray(out[:n])


def solve_ik(
    ctx: GeneratorContext,
    seed: torch.Tensor,
    targets: torch.Tensor,
    iterations: int = 150,
    tolerance: float = 0.005,
    damping: float = 0.05,
    max_step: float = 0.3,
    stall: int = 10,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Damped least squares IK for the TCP positions. seed (N, D), targets (N, T, 3) -> (q (N, D), ok (N,)).

    The Jacobian is taken by forward differences on the batched FK; q is clamped into the position
    limits after every step; a row stops when converged or when its error has not dropped by 2 % for
    `stall` iterations. ok = position error of every TCP < tolerance (collisions not checked).
    """
    q = seed.clone().to(torch.float64)
    n, d = q.shape
    eye = torch.eye(d, dtype=q.dtype)
    eps = 1e-6
    active = torch.ones(n, dtype=torch.bool)
    err_norm = torch.full((n,), math.inf, dtype=q.dtype)
    best = torch.full((n,), math.inf, dtype=q.dtype)
    since = torch.zeros(n, dtype=torch.long)
    for _ in range(iterations):
        idx = active.nonzero().squeeze(1)
        if len(idx) == 0:
            break
        qa = q[idx]
        qq = torch.cat([qa[:, None, :], qa[:, None, :] + eps * eye], dim=1)  # (n, D+1, D)
        pos = ctx.fk.tcp_positions(qq.reshape(-1, d)).reshape(len(idx), d + 1, -1)  # (n, D+1, 3T)
        x0 = pos[:, 0]
        jac = (pos[:, 1:] - x0[:, None]).transpose(1, 2) / eps  # (n, 3T, D)
        err = targets[idx].reshape(len(idx), -1) - x0
        per_tcp = err.reshape(len(idx), -1, 3).norm(dim=-1).max(dim=1).values
        err_norm[idx] = per_tcp
        conv = per_tcp < tolerance
        improved = per_tcp < 0.98 * best[idx]
        best[idx] = torch.minimum(best[idx], per_tcp)
        since[idx] = torch.where(improved, 0, since[idx] + 1)
        active[idx[conv | (since[idx] > stall)]] = False
        jjt = jac @ jac.transpose(1, 2) + damping**2 * torch.eye(jac.shape[1], dtype=q.dtype)
        dq = (jac.transpose(1, 2) @ torch.linalg.solve(jjt, err[:, :, None]))[:, :, 0]
        scale = torch.clamp(max_step / dq.norm(dim=1).clamp(min=1e-12), max=1.0)
        qn = torch.minimum(torch.maximum(qa + dq * scale[:, None], ctx.lo), ctx.hi)
        q[idx[~conv]] = qn[~conv]
    if active.any():
        idx = active.nonzero().squeeze(1)
        x0 = ctx.fk.tcp_positions(q[idx]).reshape(len(idx), -1)
        err_norm[idx] = (targets[idx].reshape(len(idx), -1) - x0).reshape(len(idx), -1, 3).norm(dim=-1).max(1).values
    return q, err_norm < tolerance
