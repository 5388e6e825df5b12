"""Adversarial fuzz of the deployed follower: paths outside the position range, paths hugging a limit (their spline
overshoots between knots on it), path changes to such paths mid-motion, stops, and bad measured states. Every
setpoint the follower sends is checked against every limit at the control rate.

Each trial draws a path of 2-6 knots in the position range (probability 0.4) or anywhere in it widened by a
quarter on each side (0.6, so that most of those leave it); with probability 0.3 every inner knot of one joint
sits on its upper limit, with 0.2 one knot leaves the range by at most 4 mrad (as released third-party path sets
do). A refusing follower must accept it or raise a :class:`~pathrl.deploy.follower.FollowerError`; a clipping
follower must follow it, with a path change to another such path at a random decision (half of the trials) and a
stop (a quarter), and must refuse a bad measured state (NaN, wrong length) without changing anything. Any other
exception is counted as a crash.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from pathrl.deploy.follower import Follower, FollowerError
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits

__all__ = ["FollowerFuzz", "adversarial_knots", "fuzz_follower"]


@dataclass
class FollowerFuzz:
    """Counts of a follower fuzz (module docstring): trials, paths refused / accepted by the refusing follower,
    path changes, stops, bad states refused, (setpoint, joint) pairs checked, limit violations, crashes, seconds."""

    model: str
    trials: int = 0
    refused: int = 0
    accepted_unclipped: int = 0
    path_changes: int = 0
    stops: int = 0
    bad_states_refused: int = 0
    setpoints_checked: int = 0
    violations: int = 0
    crashes: int = 0
    seconds: float = 0.0


def adversarial_knots(lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One adversarial path (K, M) for the position range [lo, hi] (M,) (module docstring)."""
    width = hi - lo
    low, high = (-0.25, 1.25) if rng.random() < 0.6 else (0.0, 1.0)
    k = lo + rng.uniform(low, high, size=(int(rng.integers(2, 7)), len(lo))) * width
    if rng.random() < 0.3 and len(k) > 2:
        j = int(rng.integers(len(lo)))
        k[1:-1, j] = hi[j]
    if rng.random() < 0.2:
        k = np.clip(k, lo, hi)
        i, j = int(rng.integers(len(k))), int(rng.integers(len(lo)))
        k[i, j] = hi[j] + rng.uniform(0.0, 4e-3)
    return k


def _run(follower: Follower, decisions: int, change_at: int | None, stop_at: int | None,
         rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray) -> tuple[list[torch.Tensor], ...]:
    """Setpoints (T, D) of one run of `follower` (start state first), with an optional path change and stop."""
    p, v, a = (torch.as_tensor(x).unsqueeze(0) for x in follower.state)
    out = ([p], [v], [a])
    for t in range(decisions):
        if t == change_at:
            follower.replace_path(np.vstack([follower.state[0][follower.robot.path_index],
                                             adversarial_knots(lo, hi, rng)]))
        if t == stop_at:
            follower.stop()
        sp = follower.decide()
        for acc, x in zip(out, (sp.position, sp.velocity, sp.acceleration), strict=True):
            acc.append(torch.as_tensor(x))
        if follower.done:
            break
    return out


def _bad_state_refused(follower: Follower, knots: np.ndarray, rng: np.random.Generator) -> bool:
    """A NaN or wrong-length measured state is a FollowerError and leaves the follower's state as it was."""
    before = [x.copy() for x in follower.state]
    q = before[0].copy()
    if rng.random() < 0.5:
        q[int(rng.integers(len(q)))] = np.nan
    else:
        q = q[:-1]
    try:
        follower.reset(knots, q=q)
    except FollowerError:
        return all(np.array_equal(x, y) for x, y in zip(before, follower.state, strict=True))
    return False


def fuzz_follower(model: str | Path, trials: int, seed: int = 0, decisions: int = 150) -> FollowerFuzz:
    """Run `trials` adversarial trials (module docstring) against the policy in `model`, one thread."""
    refuse, clip = Follower.load(model), Follower.load(model, out_of_limits="clip")
    lim = clip.robot.pos_limits[clip.robot.path_index]
    lo, hi = lim[:, 0], lim[:, 1]
    limits, dt = JointLimits.from_robot(clip.robot), 1.0 / clip.env_cfg.control_rate
    rng, res, t0 = np.random.default_rng(seed), FollowerFuzz(str(model)), time.perf_counter()
    for _ in range(trials):
        res.trials += 1
        knots = adversarial_knots(lo, hi, rng)
        try:
            runs = []
            try:
                refuse.reset(knots)
                res.accepted_unclipped += 1
                runs.append(_run(refuse, decisions, None, None, rng, lo, hi))
            except FollowerError:
                res.refused += 1
            clip.reset(knots)
            change = int(rng.integers(1, 40)) if rng.random() < 0.5 else None
            stop = int(rng.integers(1, 60)) if rng.random() < 0.25 else None
            res.path_changes += change is not None
            res.stops += stop is not None
            runs.append(_run(clip, decisions, change, stop, rng, lo, hi))
            res.bad_states_refused += _bad_state_refused(clip, knots, rng)
        except Exception:  # noqa: BLE001 - anything but a FollowerError is what the fuzz looks for
            res.crashes += 1
            continue
        for p, v, a in runs:
            p, v, a = torch.cat(p), torch.cat(v), torch.cat(a)
            res.setpoints_checked += p.numel()
            res.violations += int(limit_violations(p, v, a, limits, dt)["total"])
    res.seconds = time.perf_counter() - t0
    return res
