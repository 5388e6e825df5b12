"""How much of a TrueAdapt policy's action comes from the ball feedback: closed loop, every decision is taken twice,
once on the real state and once with the ball parts of the state (the last two measurements and, in place, the offset
from the start) frozen at the episode's first values, as the open-loop rows freeze them; the policy acts on the real
state. Reports the mean action difference relative to the mean action (both normalised actions, 2-norm over joints)
over the decisions of the episodes still running, and the closed-loop metrics of the same rollouts.

    .venv/bin/python tools/lab/trueadapt_feedback_share.py models/trueadapt/iiwa7_trueadapt_on_plate_ppo_scratch \\
        models/trueadapt/iiwa7_trueadapt_on_plate_distill_full --episodes 1000 \\
        --out results/trueadapt_from_scratch/feedback_share.json

Analytic ball, the committed test split, deterministic actions, seed 0.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

from pathrl.envs.terminations import TerminationReason
from pathrl.families.trueadapt import Source, load
from pathrl.runs import load_run

BALL_PARTS = ("prev_ball", "ball", "ball_offset")


class TwoWayPolicy:
    """Acts on the real state; on every call also evaluates the actor on the state with the ball parts frozen at
    the batch's first observation, and accumulates sum |a - a_frozen| and sum |a| (2-norms over joints)."""

    def __init__(self, actor, columns: list[slice]):
        self.actor, self.columns = actor, columns
        self.first: torch.Tensor | None = None
        self.diff = self.norm = 0.0
        self.count = 0

    def reset(self) -> None:
        """A new batch of episodes starts: the next observation is their first."""
        self.first = None

    def __call__(self, env) -> torch.Tensor:
        obs = env.get_observations()
        policy = obs["policy"]
        if self.first is None:
            self.first = policy.clone()
        frozen = policy.clone()
        for c in self.columns:
            frozen[:, c] = self.first[:, c]
        a = self.actor(obs)
        obs_frozen = obs.clone()
        obs_frozen["policy"] = frozen
        a_frozen = self.actor(obs_frozen)
        live = env.termination == TerminationReason.NONE
        self.diff += float((a - a_frozen).norm(dim=1)[live].sum())
        self.norm += float(a.norm(dim=1)[live].sum())
        self.count += int(live.sum())
        return a


def measure(run: Path, episodes: int) -> dict:
    """Feedback share of `run`'s policy on `episodes` test trajectories (analytic ball)."""
    cfg, ckpt, _ = load_run(run)
    env, actor, dataset = load(cfg, ckpt, Source(), min(episodes, 250))
    try:
        cols = [slice(a, b) for name, a, b in env.observation_layout() if name in BALL_PARTS]
        policy = TwoWayPolicy(actor, cols)
        from pathrl.eval.trueadapt import evaluate, summary

        t0 = time.perf_counter()
        res = summary(evaluate(env, policy, torch.arange(episodes) % env.bank.num))
        return {"run": str(run), "dataset": str(dataset), "episodes": episodes, "decisions": policy.count,
                "mean_action_norm": policy.norm / policy.count,
                "mean_feedback_difference": policy.diff / policy.count,
                "feedback_share": policy.diff / policy.norm, "closed_loop_analytic": res,
                "wall_time_s": round(time.perf_counter() - t0, 1)}
    finally:
        env.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--episodes", type=int, default=250)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    torch.set_num_threads(1)
    rows = []
    for run in args.runs:
        r = measure(run, args.episodes)
        rows.append(r)
        print(f"{run}: feedback share {r['feedback_share']:.3f} (|a - a_frozen| {r['mean_feedback_difference']:.4f}"
              f" / |a| {r['mean_action_norm']:.4f}), closed-loop success (analytic) "
              f"{r['closed_loop_analytic']['success']:.3f}", flush=True)
    if args.out is not None:
        tmp = args.out.with_suffix(".tmp")
        tmp.write_text(json.dumps({"command": "tools/lab/trueadapt_feedback_share.py", "rows": rows}, indent=1))
        tmp.replace(args.out)


if __name__ == "__main__":
    main()
