"""Output-bias search: a derivative-free fine-tune of a policy's per-joint action offsets on the training return.

Why: PPO explores with noise that is independent from step to step. A trained tracking policy feeds its error back,
so it cancels a one-step push within a few steps. A constant offset that the policy holds from the path is
therefore almost invisible to PPO's gradient, even when the reward pays for removing it. Under the KL-adaptive step
the mean also moves only about sigma * sqrt(2 KL) per iteration. ARMAR-4 random is the measured case
(docs/lab/lab_notebook.md): a constant +0.6 on two action outputs removes 0.06 rad offsets and 2 cm of hand deviation.

The search changes only the bias of the actor's output layer (one number per joint, D in all). Its objective is the
run's own training return:
- the training env: its reward, deviation cut-off and time budget;
- a fixed plan of training-split segments, the same at every evaluation;
- the deterministic policy, with the undiscounted return summed to each episode's end.
The objective is therefore a deterministic function of the D offsets, and scipy's Powell method searches it inside
[-bound, bound]. The test splits are never read.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.optimize import minimize
from torch import Tensor

from pathrl.paths.segments import Segments, evaluation_plan

__all__ = ["BiasSearchCfg", "env_generators", "episode_returns", "output_layer", "search_before_training",
           "search_bias", "search_output_bias"]


@dataclass(frozen=True)
class BiasSearchCfg:
    """The ``bias_search`` group of a run config (empty: no search)."""

    episodes: int = 1024  # training segments in the fixed plan (= parallel envs)
    max_evals: int = 400  # objective evaluations (each: one pass over the plan)
    bound: float = 1.0  # |offset| <= bound, in action units
    seed: int = 0  # the plan's segments

    def __post_init__(self) -> None:
        """Refuse values that would run but search nothing (one-line ValueError naming the key)."""
        for key in ("episodes", "max_evals"):
            if int(getattr(self, key)) < 1:
                raise ValueError(f"bias_search.{key} must be >= 1, got {getattr(self, key)}")
        if not float(self.bound) > 0.0:
            raise ValueError(f"bias_search.bound must be > 0, got {self.bound}")


def episode_returns(env: Any, policy: Callable[[Any], Tensor], plan: Segments) -> tuple[Tensor, int]:
    """Undiscounted returns (E,) of one deterministic pass: env i runs segment i of `plan` (E = env.num_envs) until
    its episode ends (stop, deviation cut-off or budget); later steps of an ended env are not counted. Also the env
    steps simulated (E per step of the pass)."""
    n = env.num_envs
    if len(plan) != n:
        raise ValueError(f"plan has {len(plan)} segments for {n} envs")
    dev = env.device
    env.start_segments(torch.arange(n, device=dev), plan.to(dev))
    total = torch.zeros(n, dtype=torch.float64, device=dev)
    active = torch.ones(n, dtype=torch.bool, device=dev)
    steps = 0
    for _ in range(int(env.max_episode_length) + 1):
        steps += n
        with torch.inference_mode():
            actions = policy(env.get_observations())
        _, reward, dones, _ = env.step(actions)
        total += torch.where(active, reward.to(torch.float64), torch.zeros_like(total))
        active &= ~dones
        if not bool(active.any()):
            break
    return total, steps


def output_layer(actor: torch.nn.Module) -> torch.nn.Linear:
    """The actor's last linear layer, whose bias holds the per-joint action offsets."""
    layers = [m for m in actor.modules() if isinstance(m, torch.nn.Linear)]
    if not layers:
        raise ValueError(f"{type(actor).__name__} has no linear layer")
    return layers[-1]


def search_bias(objective: Callable[[np.ndarray], float], dim: int, max_evals: int, bound: float,
                ) -> tuple[np.ndarray, float, float, int]:
    """Maximise `objective` over offsets in [-bound, bound]^dim from 0 (scipy Powell); (best offsets, best value,
    value at the start, evaluations). The start point is evaluated first, and the result is never worse than it."""
    f0 = objective(np.zeros(dim))
    res = minimize(lambda x: -objective(np.asarray(x)), np.zeros(dim), method="Powell",
                   bounds=[(-bound, bound)] * dim, options={"maxfev": max_evals, "xtol": 1e-2, "ftol": 1e-5})
    if -float(res.fun) <= f0:
        return np.zeros(dim), f0, f0, int(res.nfev) + 1
    return np.asarray(res.x, dtype=np.float64), -float(res.fun), f0, int(res.nfev) + 1


def env_generators(env: Any) -> list[torch.Generator]:
    """The random generators of `env`: its own and its feedback model's (the ball's radius, friction and start are
    drawn at each episode start), if it has one."""
    owners = (env, getattr(env, "feedback", None))
    return [g for g in (getattr(o, "generator", None) for o in owners) if isinstance(g, torch.Generator)]


def search_output_bias(env: Any, actor: torch.nn.Module, cfg: BiasSearchCfg) -> dict[str, Any]:
    """Search the output-layer bias of `actor` on `env` (the training env, ``num_envs`` = ``cfg.episodes``) and
    add the best offsets to it in place; returns the record (offsets, mean returns before and after, evaluations,
    wall time)."""
    plan = evaluation_plan(env.paths, cfg.episodes, env.cfg.segments, cfg.seed)
    layer = output_layer(actor)
    base = layer.bias.detach().clone()
    was_training = actor.training
    actor.eval()

    steps = [0]  # env steps simulated (every env of every pass, as long as the pass runs)
    generators = env_generators(env)
    states = [g.get_state() for g in generators]  # every pass draws the same balls: a deterministic objective

    def mean_return(offsets: np.ndarray) -> float:
        for g, state in zip(generators, states, strict=True):
            g.set_state(state)
        with torch.no_grad():
            layer.bias.copy_(base + torch.as_tensor(offsets, dtype=base.dtype, device=base.device))
        returns, n = episode_returns(env, actor, plan)
        steps[0] += n
        return float(returns.mean())

    t0 = time.perf_counter()
    try:
        best, value, before, evals = search_bias(mean_return, base.numel(), cfg.max_evals, cfg.bound)
    finally:
        with torch.no_grad():
            layer.bias.copy_(base)
    with torch.no_grad():
        layer.bias.add_(torch.as_tensor(best, dtype=base.dtype, device=base.device))
    actor.train(was_training)
    return {"offsets": [round(float(x), 6) for x in best], "mean_return_before": before, "mean_return_after": value,
            "evaluations": evals, "env_steps": steps[0], "episodes": cfg.episodes, "seed": cfg.seed, "bound": cfg.bound,
            "wall_time_s": round(time.perf_counter() - t0, 1)}


def search_before_training(cfg: dict[str, Any], actor: torch.nn.Module, knot_gap: float, summary: Path
                           ) -> dict[str, Any]:
    """Search the actor's output offsets on the training return before PPO (this module's search), on an
    env of its own (``bias_search.episodes`` envs, the run's training settings); records the search in the run's
    `summary` (its wall time counted as training time) and returns the updated summary."""
    from pathrl.envs.registry import EnvRequest, make_env
    from pathrl.storage import write_json_atomic

    if cfg["agent"]["algorithm"]["class_name"] != "PPO" or cfg.get("residual"):
        raise ValueError("bias_search: only for a PPO run without residual (a trained actor's output offsets)")
    bs = BiasSearchCfg(**cfg["bias_search"])
    search_env = make_env(cfg, EnvRequest(num_envs=bs.episodes, seed=bs.seed, knot_gap_norm=knot_gap))
    record = search_output_bias(search_env, actor, bs)
    print(f"bias_search: mean training return {record['mean_return_before']:.3f} -> {record['mean_return_after']:.3f} "
          f"in {record['evaluations']} evaluations ({record['wall_time_s']} s)", file=sys.stderr)
    out = {**json.loads(summary.read_text()), "bias_search": record}
    out["wall_time_s"] = float(out.get("wall_time_s", 0.0)) + record["wall_time_s"]
    write_json_atomic(summary, out)
    return out
