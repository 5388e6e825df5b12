"""What the paper's reward pays a ball policy for speed and for closeness (analytic ball).

Runs each policy deterministically on the 200 whole ball-balancing test paths, as ``pathrl-eval ... backend=analytic``
does, and sums the reward the env hands out at every decision step (the run's own reward terms: for the Table VII
runs the paper's weights, 0.9 + 0.9 on the deviation, 4 on the path length, 1 on the ball), per episode:

* ``terms``: the per-step reward summed over the episode, without the stop bonus;
* ``stop_bonus``: what the robot-stop step adds (its reward times the steps left in the 6 s budget);
* ``return``: both, undiscounted, and ``return_discounted`` with gamma = 0.99 (PPO's);
* with ``--closer K``: what the deviation terms would add if every step's joint deviations (max and mean) were K
  times what they were (K < 1: closer), the rest of the episode unchanged; undiscounted and discounted.

A policy the reward prefers has the larger return; comparing a fast row with a slower, closer one shows which way
the paper's reward pulls PPO. (Evaluation does not end an episode when the ball falls; training does, without a
bonus: the few lost balls count here with the ball term at zero for the rest of the episode.)

Usage:
    .venv/bin/python tools/lab/reward_price.py RUN_DIR[:model_K.pt] [...] [--closer 0.63]
"""

from __future__ import annotations

import argparse
from pathlib import Path
from types import SimpleNamespace

import torch

from pathrl.envs.tracking import PathTrackingEnv
from pathrl.eval.evaluate import EvalOptions, run_rollouts

DATASET = "datasets/iiwa7/ball_balancing"
GAMMA = 0.99


class _Ledger:
    """Per-env reward sums of the running batch, collected into per-episode rows when a batch ends."""

    def __init__(self, closer: float) -> None:
        self.closer = closer
        self.rows: list[tuple[float, ...]] = []  # (terms, stop_bonus, discounted return, what-if, its discounted)
        self._open: tuple[torch.Tensor, ...] | None = None

    def _closer_gain(self, env: PathTrackingEnv) -> torch.Tensor:
        """(N,) weighted deviation terms of the step at `closer` times its deviations, minus as they were."""
        q, k = env.last_step, self.closer
        now = SimpleNamespace(dev_max=q["dev_max"], dev_mean=q["dev_mean"])
        then = SimpleNamespace(dev_max=k * q["dev_max"], dev_mean=k * q["dev_mean"])
        gain = torch.zeros_like(q["dev_max"], dtype=torch.float64)
        for term in env.reward_terms:
            if term.name in ("deviation_max", "deviation_mean"):
                gain += term.weight * (term(then) - term(now)).to(torch.float64)  # type: ignore[arg-type]
        return gain.cpu()

    def step(self, env: PathTrackingEnv, reward: torch.Tensor) -> None:
        """Book one step's rewards (N,) of `env` (the step's `stopped` flag tells the bonus apart)."""
        if self._open is None or int(env.episode_length_buf.max()) == 1:
            self.flush()
            n = reward.shape[0]
            self._open = (*(torch.zeros(n, dtype=torch.float64) for _ in range(5)), torch.zeros(n, dtype=torch.bool))
        terms, bonus, disc, gain, gain_disc, ended = self._open
        r = reward.to(torch.float64).cpu()
        live = ~ended
        stopped = env.last_step["stopped"].cpu()
        remaining = (env.budget - env.episode_length_buf).clamp(min=0).cpu().to(torch.float64)
        base = torch.where(stopped, r / (1.0 + remaining), r)  # undo the bonus to split it off
        t = (env.episode_length_buf.cpu() - 1).to(torch.float64)
        terms += torch.where(live, base, 0.0)
        bonus += torch.where(live & stopped, r - base, 0.0)
        disc += torch.where(live, r * GAMMA**t, 0.0)
        g = self._closer_gain(env) * torch.where(stopped, 1.0 + remaining, 1.0)
        gain += torch.where(live, g, 0.0)
        gain_disc += torch.where(live, g * GAMMA**t, 0.0)
        ended |= stopped | env.last_step["time_outs"].cpu()

    def flush(self) -> None:
        if self._open is not None:
            self.rows += list(zip(*(x.tolist() for x in self._open[:5]), strict=True))
            self._open = None


def price(run: str, closer: float = 1.0) -> dict[str, float]:
    """Mean per-episode reward sums and the policy's end-of-path time (s) over the test paths."""
    run_dir, _, ckpt = run.partition(":")
    ledger, step = _Ledger(closer), PathTrackingEnv.step

    def booked(self: PathTrackingEnv, actions: torch.Tensor):  # noqa: ANN202
        out = step(self, actions)
        ledger.step(self, out[1])
        return out

    PathTrackingEnv.step = booked  # type: ignore[method-assign]
    try:
        opts = EvalOptions(dataset_path=DATASET, segments="full", backend="analytic", record=False,
                           progress=False, checkpoint=ckpt or None, out_of_limits="clip")
        records, _, _ = run_rollouts(Path(run_dir), opts)
    finally:
        PathTrackingEnv.step = step  # type: ignore[method-assign]
    ledger.flush()
    rows = torch.tensor(ledger.rows[: len(records)], dtype=torch.float64)
    ends = torch.tensor([r.finish_step * float(r.extra["dt"]) for r in records if r.finish_step >= 0])
    return {"end_of_path_s": float(ends.mean()), "terms": float(rows[:, 0].mean()),
            "stop_bonus": float(rows[:, 1].mean()), "return": float(rows[:, :2].sum(1).mean()),
            "return_discounted": float(rows[:, 2].mean()), "closer_gain": float(rows[:, 3].mean()),
            "closer_gain_discounted": float(rows[:, 4].mean())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="run directories, each optionally :model_K.pt")
    ap.add_argument("--closer", type=float, default=1.0, help="deviation factor of the what-if columns")
    args = ap.parse_args()
    torch.set_num_threads(1)
    print("| policy | end of path | reward terms | stop bonus | return | discounted return | "
          f"deviations x {args.closer}: gain | discounted |")
    print("|---|---|---|---|---|---|---|---|")
    for run in args.runs:
        p = price(run, args.closer)
        print(f"| {run} | {p['end_of_path_s']:.2f} s | {p['terms']:.1f} | {p['stop_bonus']:.1f} | {p['return']:.1f} | "
              f"{p['return_discounted']:.1f} | {p['closer_gain']:+.1f} | {p['closer_gain_discounted']:+.1f} |")


if __name__ == "__main__":
    main()
