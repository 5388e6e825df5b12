"""Adversarial fuzz of the deployed follower: paths outside the position range, paths hugging a limit (their spline
overshoots between knots on it), path changes to such paths mid-motion, stops, and bad measured states. Every
setpoint the follower sends is checked against every limit at the control rate.

Each trial draws a path of 2-6 knots in the position range (probability 0.4) or anywhere in it widened by a
quarter on each side (0.6, so that most of those leave it); with probability 0.3 every inner knot of one joint
sits on its upper limit, with 0.2 one knot leaves the range by at most 4 mrad (as released third-party path sets
do). A refusing follower must accept it or raise a :class:`~pathrl.deploy.follower.FollowerError`; a clipping
follower must follow it, with a path change to another such path (half of the trials) and a stop (a quarter), each
at a random decision or, in a third of them, in the first three decisions of the final approach onto the path's last
knot (a time-optimal jerk-limited move: a stop or change there once left the range), and must refuse a bad measured
state (NaN, wrong length) in ``reset`` without changing anything.

Adversarial measured states: at each decision, with probability 0.2, ``decide(q_measured=...)`` gets a position
with a NaN, an inf, the wrong length, one joint beyond the measured tolerance (up to 100x it), or every joint within
it. The clipping follower refuses measurements beyond the tolerance (``on_measured="refuse"``), the refusing one
warns and goes on (``"warn"``): a non-finite or wrong-length state must be refused by both without changing
anything, one beyond the tolerance by the first; a state within it (or beyond it, for the warning one) must be
taken, and the commanded setpoints that follow are checked like all others. Any other outcome counts as mishandled,
any other exception as a crash.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from pathrl.deploy.follower import Follower, FollowerError
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits

__all__ = ["FollowerFuzz", "adversarial_knots", "adversarial_measurement", "fuzz_follower"]


@dataclass
class FollowerFuzz:
    """Counts of a follower fuzz (module docstring): trials, paths refused / accepted by the refusing follower,
    path changes (and of them refused, without a change), stops, bad states refused by ``reset``, adversarial
    measured states given to ``decide`` / refused without a change / mishandled, (setpoint, joint) pairs checked,
    limit violations, crashes, seconds."""

    model: str
    trials: int = 0
    refused: int = 0
    accepted_unclipped: int = 0
    path_changes: int = 0
    path_changes_refused: int = 0
    stops: int = 0
    bad_states_refused: int = 0
    measured_states: int = 0
    measured_refused: int = 0
    measured_mishandled: int = 0
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


def adversarial_measurement(q: np.ndarray, tolerance: float, rng: np.random.Generator) -> tuple[np.ndarray, str]:
    """A measured position for the commanded one `q` (D,) and its kind: "bad" (a NaN, an inf or the wrong length),
    "far" (one joint 1.5-100x the `tolerance` (rad) away) or "near" (every joint within half of it)."""
    kind, j = int(rng.integers(5)), int(rng.integers(len(q)))
    m = q.copy()
    if kind == 0:
        m[j] = np.nan
    elif kind == 1:
        m[j] = np.inf if rng.random() < 0.5 else -np.inf
    elif kind == 2:
        m = m[:-1] if rng.random() < 0.5 else np.r_[m, 0.0]
    elif kind == 3:
        m[j] += rng.choice([-1.0, 1.0]) * tolerance * rng.uniform(1.5, 100.0)
        return m, "far"
    else:
        return m + rng.uniform(-0.5, 0.5, size=len(q)) * tolerance, "near"
    return m, "bad"


def _measured_decide(follower: Follower, rng: np.random.Generator, res: FollowerFuzz):
    """One decision given an adversarial measured position (:func:`adversarial_measurement`): its setpoints if it was
    taken, else None (refused: counted, and checked to have changed nothing)."""
    before = [x.copy() for x in follower.state]
    q, kind = adversarial_measurement(before[0], follower.measured_tolerance, rng)
    refuse = kind == "bad" or (kind == "far" and follower.on_measured == "refuse")
    res.measured_states += 1
    try:
        sp = follower.decide(q_measured=q)
    except FollowerError:
        unchanged = _unchanged(follower, before)
        res.measured_refused += refuse and unchanged
        res.measured_mishandled += not (refuse and unchanged)
        return None
    res.measured_mishandled += refuse
    return sp


def _change_path(follower: Follower, knots: np.ndarray, res: FollowerFuzz) -> None:
    """Replace the path by one from the robot through `knots` (K, M); a refusal (the clipping follower refuses only
    during the final approach) must change nothing, else it is re-raised (a crash)."""
    before = [x.copy() for x in follower.state]
    try:
        follower.replace_path(np.vstack([before[0][follower.robot.path_index], knots]))
    except FollowerError:
        if not _unchanged(follower, before):
            raise
        res.path_changes_refused += 1


#: When an event of a trial happens: ("decision", k) at decision k, ("approach", k) k decisions into the final
#: approach, None never.
When = tuple[str, int] | None


def _when(rng: np.random.Generator, p: float, last: int) -> When:
    """With probability `p` an event: at a decision in 1..`last` (2/3) or in the approach's first three (1/3)."""
    if rng.random() >= p:
        return None
    return ("approach", int(rng.integers(0, 3))) if rng.random() < 1 / 3 else ("decision", int(rng.integers(1, last)))


def _run(follower: Follower, decisions: int, change: When, stop: When, rng: np.random.Generator, lo: np.ndarray,
         hi: np.ndarray, res: FollowerFuzz) -> tuple[list[torch.Tensor], ...]:
    """Setpoints (T, D) of one run of `follower` (start state first), with an optional path change and stop, and
    adversarial measured states (module docstring)."""
    p, v, a = (torch.as_tensor(x).unsqueeze(0) for x in follower.state)
    out = ([p], [v], [a])
    approach_at = None  # the decision at which the final approach started
    for t in range(decisions):
        if approach_at is None and follower.final_approach_s > 0:
            approach_at = t
        now = {("decision", t)} | (set() if approach_at is None else {("approach", t - approach_at)})
        if change in now:
            _change_path(follower, adversarial_knots(lo, hi, rng), res)
        if stop in now:
            follower.stop()
        sp = _measured_decide(follower, rng, res) if rng.random() < 0.2 else None
        if sp is None:
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
        return _unchanged(follower, before)
    return False


def _unchanged(follower: Follower, before: list[np.ndarray]) -> bool:
    """Whether the follower's commanded state (position, velocity, acceleration) equals `before` exactly."""
    return all(np.array_equal(x, y) for x, y in zip(before, follower.state, strict=True))


def fuzz_follower(model: str | Path, trials: int, seed: int = 0, decisions: int = 150) -> FollowerFuzz:
    """Run `trials` adversarial trials (module docstring) against the policy in `model`, one thread."""
    refuse, clip = Follower.load(model, on_measured="warn"), Follower.load(model, out_of_limits="clip")
    rng, res, t0 = np.random.default_rng(seed), FollowerFuzz(str(model)), time.perf_counter()
    with warnings.catch_warnings():  # the warning follower's measurements beyond the tolerance
        warnings.filterwarnings("ignore", message="the measured position", category=RuntimeWarning)
        _trials(refuse, clip, trials, decisions, rng, res)
    res.seconds = time.perf_counter() - t0
    return res


def _trials(refuse: Follower, clip: Follower, trials: int, decisions: int, rng: np.random.Generator,
            res: FollowerFuzz) -> None:
    """Run `trials` trials (module docstring) of the two followers, counting into `res`."""
    lim = clip.robot.pos_limits[clip.robot.path_index]
    lo, hi = lim[:, 0], lim[:, 1]
    limits, dt = JointLimits.from_robot(clip.robot), 1.0 / clip.env_cfg.control_rate
    for _ in range(trials):
        res.trials += 1
        knots = adversarial_knots(lo, hi, rng)
        try:
            runs = []
            try:
                refuse.reset(knots)
            except FollowerError:
                res.refused += 1
            else:  # a FollowerError while following an accepted path is a crash
                res.accepted_unclipped += 1
                runs.append(_run(refuse, decisions, None, None, rng, lo, hi, res))
            clip.reset(knots)
            change, stop = _when(rng, 0.5, 40), _when(rng, 0.25, 60)
            res.path_changes += change is not None
            res.stops += stop is not None
            runs.append(_run(clip, decisions, change, stop, rng, lo, hi, res))
            res.bad_states_refused += _bad_state_refused(clip, knots, rng)
        except Exception:  # noqa: BLE001 - anything but a FollowerError is what the fuzz looks for
            res.crashes += 1
            continue
        for p, v, a in runs:
            p, v, a = torch.cat(p), torch.cat(v), torch.cat(a)
            res.setpoints_checked += p.numel()
            res.violations += int(limit_violations(p, v, a, limits, dt)["total"])
