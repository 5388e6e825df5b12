"""Online path adjustment, measured: the path changes while the robot moves (paper Table V, "path adjustments").

Protocol (per episode, fixed seed): the robot follows a whole test path with the deployable follower
(:class:`pathrl.deploy.Follower`). After a random time (``switch_range`` seconds) the rest of the path is
replaced by a branch (:func:`branch`): from where the robot is, the path's remaining knots are shifted by a
random joint offset of ``offset_rad`` that ramps in smoothly over ``ramp_rad`` of arc length (an updated goal:
the new path starts at the robot, tangent to the old one, and ends elsewhere; its knots kept inside the position
range, and its spline, which can bulge past the range between them (up to 8.5 mrad on the iiwa7 test paths),
clipped into it: the follower runs with ``out_of_limits="clip"``, as a user's would to accept such a path, where
the default refuses it). The robot keeps its position,
velocity and acceleration; the policy sees the new path from its next decision on. Measured per episode:

- ``replan_ms``: wall time of the switch (building the new path) plus the first decision after it;
- the step deviation (weighted joint distance to the reference, the env's ``dev_max``) after the switch, and
  ``settle_in_band_s``: the time from the switch until it is, for the rest of the path, inside the policy's
  normal tracking band (:func:`peak_band`: the 95th percentile of the largest deviation per unchanged path, the
  same policy on the same test paths); two stricter readings kept beside it: ``settle_s``, back at the 95th
  percentile of the step deviation on unchanged paths (:func:`tracking_level`) after its largest excursion in
  the first 4 s, which the path's own turns also trip, and the settle time against the control
  (:func:`settle_vs_control`): the same change with offset 0 (the path replaced by itself) as the bound;
- ``duration_s``: from the switch to rest at B's end; every setpoint is checked against the position,
  velocity, acceleration and jerk limits.

The re-planned TOPP-RA baseline (:func:`toppra_replan`) solves the branch from the robot's position with the
robot's path velocity as toppra's start velocity (the branch is tangent to the old path there; the velocity's
part normal to the branch, ``normal_speed``, is what such a re-plan cannot honour) and no jerk limit; its
solve time is its re-plan latency.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch

from pathrl.deploy import Follower
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits
from pathrl.paths.branch import BranchShape, BranchStart
from pathrl.paths.spline import knot_arc_lengths

__all__ = ["OFFSET_RAD", "RAMP_RAD", "SWITCH_RANGE", "VARIANTS", "SwitchEpisode", "branch", "excess_vs_control", "main",
           "paired_settle", "path_change_episodes", "peak_band", "settle_vs_control", "summarize", "toppra_replan",
           "tracking_level", "unchanged_deviation"]

#: Defaults of the protocol: switch time (s), offset of the branch (rad, joint space), its ramp (rad of arc).
SWITCH_RANGE = (1.0, 4.0)
OFFSET_RAD = 0.3
RAMP_RAD = 1.0
#: The variants `main` measures: (offset_rad, ramp_rad) of the branch. ``none`` replaces the path by itself from the
#: robot's position (no offset): the control for what the settle window holds without a change.
VARIANTS = {"none": (0.0, RAMP_RAD), "gentle": (OFFSET_RAD, RAMP_RAD), "sharp": (0.6, 0.3)}


@dataclass
class SwitchEpisode:
    """One path change (module docstring)."""

    path: int
    switch_s: float
    replan_ms: float
    duration_s: float
    reached_end: bool
    dev_after: list[float] = field(default_factory=list)  # dev_max of each step after the switch (rad)
    violations: int = 0

    def settle_s(self, level: float, dt: float, window_s: float = 4.0) -> float:
        """Time from the switch until the deviation is back at or below `level` after its largest excursion in
        the first `window_s` seconds (0 if that excursion stays below `level`; inf if it never comes back)."""
        dev = np.asarray(self.dev_after)
        peak = int(np.argmax(dev[: max(1, int(round(window_s / dt)))]))
        if dev[peak] <= level:
            return 0.0
        back = np.nonzero(dev[peak:] <= level)[0]
        return float((peak + back[0]) * dt) if len(back) else float("inf")

    def settle_in_band_s(self, band: float, dt: float) -> float:
        """Time from the switch after which every step deviation up to the end of the path is at or below `band`
        (0 if it never exceeds it)."""
        above = np.nonzero(np.asarray(self.dev_after) > band)[0]
        return float((above[-1] + 1) * dt) if len(above) else 0.0


def _control_bound(dev: np.ndarray, control: np.ndarray, level: float, dt: float, window_s: float,
                   slack_s: float) -> tuple[np.ndarray, np.ndarray]:
    """`dev` over the first `window_s` seconds and, per step, the larger of `level` and the control's largest
    deviation within `slack_s` either side (the two runs drift apart by a step or two; past its end the control
    counts as 0)."""
    n = max(1, int(round(window_s / dt)))
    w = int(round(slack_s / dt))
    d = np.asarray(dev, dtype=float)[:n]
    c = np.zeros(n + 2 * w)
    c0 = np.asarray(control, dtype=float)[: n + w]
    c[w: w + len(c0)] = c0
    envelope = np.lib.stride_tricks.sliding_window_view(c, 2 * w + 1).max(axis=1)[: len(d)]
    return d, np.maximum(level, envelope)


def settle_vs_control(dev: np.ndarray, control: np.ndarray, level: float, dt: float, window_s: float = 4.0,
                      slack_s: float = 0.2) -> float:
    """Time (s) from the switch until the step deviation `dev` (T,) stays, for the rest of the first `window_s`
    seconds, at or below the larger of `level` and the deviation `control` (T0,) of the same episode with the path
    replaced by itself (variant ``none``: same path, same switch time, same policy), taken as the control's largest
    value within `slack_s` either side. 0 if `dev` never exceeds it: the change's own effect, with the path's turns
    (present in both runs) taken out."""
    d, bound = _control_bound(dev, control, level, dt, window_s, slack_s)
    above = np.nonzero(d > bound)[0]
    return float((above[-1] + 1) * dt) if len(above) else 0.0


def excess_vs_control(dev: np.ndarray, control: np.ndarray, level: float, dt: float, from_s: float = 2.0,
                      window_s: float = 4.0, slack_s: float = 0.2) -> float:
    """How far (rad) the step deviation exceeds the bound of :func:`settle_vs_control` at worst between `from_s` and
    `window_s` seconds after the switch (0 if it never does): the size of what is left of the change's effect."""
    d, bound = _control_bound(dev, control, level, dt, window_s, slack_s)
    k = int(round(from_s / dt))
    return float(max(0.0, np.max(d[k:] - bound[k:]))) if len(d) > k else 0.0


def paired_settle(episodes: list[SwitchEpisode], control: list[SwitchEpisode], level: float,
                  dt: float) -> tuple[list[float], list[float]]:
    """:func:`settle_vs_control` and :func:`excess_vs_control` of each change against the same change with offset 0
    (lists in the same order)."""
    pairs = [(np.asarray(e.dev_after), np.asarray(c.dev_after)) for e, c in zip(episodes, control, strict=True)]
    return ([settle_vs_control(d, c, level, dt) for d, c in pairs],
            [excess_vs_control(d, c, level, dt) for d, c in pairs])


def branch(knots: np.ndarray, start: BranchStart, shape: BranchShape) -> np.ndarray:
    """Knots (K', M) of a path from ``start.q`` (moving at ``start.v``: a second knot at q + lead_s v makes the path
    start in the direction of motion) along the knots of `knots` (K, M) past arc length s + lead_s |v|, shifted by
    w(s' - s) ``shape.offset`` (w: smoothstep from 0 to 1 over ``shape.ramp`` rad) and kept ``shape.margin`` inside
    ``shape.pos_limits`` (M, 2). `start` and `shape` of one path (numpy)."""
    s_now, q_now, v_now = start.s, start.q, start.v
    offset, ramp, pos_limits = shape.offset, shape.ramp, shape.pos_limits
    lead_s, margin = shape.lead_s, shape.margin
    s_k, _ = knot_arc_lengths(knots)
    lead = lead_s * float(np.linalg.norm(v_now))
    keep = s_k > s_now + lead + 1e-6
    x = np.clip((s_k[keep] - s_now) / ramp, 0.0, 1.0)
    w = x * x * (3.0 - 2.0 * x)
    moved = np.clip(knots[keep] + w[:, None] * offset, pos_limits[:, 0] + margin, pos_limits[:, 1] - margin)
    start = [q_now] + ([q_now + lead_s * v_now] if lead > 1e-6 else [])
    return np.vstack(start + [moved])


def _switch(direction: np.ndarray, follower: Follower, offset_rad: float, ramp_rad: float) -> np.ndarray:
    """The branch of the follower's current path (module docstring; its knots as the follower tracks them) from
    its state now."""
    env = follower.env
    idx = env.path_index.numpy()
    lim = JointLimits.from_robot(follower.robot).pos[env.path_index].numpy()
    current = env.paths.knots[0, : int(env.paths.num_knots[0])].numpy()
    start = BranchStart(float(follower.env.s[0]), follower.state[0][idx], follower.state[1][idx])
    return branch(current, start, BranchShape(offset_rad * direction / np.linalg.norm(direction), ramp_rad, lim))


def _run(follower: Follower, decisions: int, out: list, devs: list | None) -> None:
    for _ in range(decisions):
        sp = follower.decide()
        out.append(sp)
        if devs is not None:
            devs.append(float(follower.env.last_step["dev_max"][0]))
        if follower.done:
            return


def _violations(follower: Follower, start: tuple[np.ndarray, ...], setpoints: list) -> int:
    p = np.vstack([start[0][None]] + [s.position for s in setpoints])
    v = np.vstack([start[1][None]] + [s.velocity for s in setpoints])
    a = np.vstack([start[2][None]] + [s.acceleration for s in setpoints])
    t = lambda x: torch.as_tensor(x, dtype=torch.float64)  # noqa: E731
    lim = JointLimits.from_robot(follower.robot)
    return int(limit_violations(t(p), t(v), t(a), lim, 1.0 / follower.env_cfg.control_rate)["total"])


def unchanged_deviation(follower: Follower, knots: list[np.ndarray], episodes: int, max_s: float = 60.0
                        ) -> list[np.ndarray]:
    """Step deviation (dev_max, rad; one array per episode) of the policy on `episodes` whole paths without a
    change."""
    out = []
    for i in range(episodes):
        devs: list[float] = []
        follower.reset(knots[i % len(knots)])
        _run(follower, int(max_s / follower.env_cfg.dt), [], devs)
        out.append(np.asarray(devs))
    return out


def tracking_level(unchanged: list[np.ndarray], quantile: float = 0.95) -> float:
    """The `quantile` of the step deviation over all steps of `unchanged` (:func:`unchanged_deviation`)."""
    return float(np.quantile(np.concatenate(unchanged), quantile))


def peak_band(unchanged: list[np.ndarray], quantile: float = 0.95) -> float:
    """The `quantile` of the largest step deviation per path of `unchanged` (:func:`unchanged_deviation`): the
    band the policy keeps on that share of whole paths without a change."""
    return float(np.quantile([d.max() for d in unchanged], quantile))


def path_change_episodes(follower: Follower, knots: list[np.ndarray], episodes: int, seed: int = 0,
                         switch_range: tuple[float, float] = SWITCH_RANGE, offset_rad: float = OFFSET_RAD,
                         ramp_rad: float = RAMP_RAD, max_s: float = 60.0) -> list[SwitchEpisode]:
    """`episodes` path changes on the paths `knots` (module docstring)."""
    rng = np.random.default_rng(seed)
    dt = follower.env_cfg.dt
    out = []
    for i in range(episodes):
        a = i % len(knots)
        k = int(round(rng.uniform(*switch_range) / dt))
        follower.reset(knots[a])
        start = follower.state
        sps: list = []
        _run(follower, k, sps, None)
        new = _switch(rng.standard_normal(follower.robot.path_dof), follower, offset_rad, ramp_rad)
        t0 = time.perf_counter()
        follower.replace_path(new)
        first: list = []
        _run(follower, 1, first, None)
        replan_ms = 1e3 * (time.perf_counter() - t0)
        devs = [float(follower.env.last_step["dev_max"][0])]
        after: list = []
        _run(follower, int(max_s / dt), after, devs)
        sps += first + after
        out.append(SwitchEpisode(a, len(sps[:k]) * dt, replan_ms, (1 + len(after)) * dt, follower.done, devs,
                                 _violations(follower, start, sps)))
    return out


def toppra_replan(follower: Follower, knots: list[np.ndarray], episodes: int, seed: int = 0,
                  switch_range: tuple[float, float] = SWITCH_RANGE, offset_rad: float = OFFSET_RAD,
                  ramp_rad: float = RAMP_RAD) -> list[dict]:
    """The same changes (same seed: same paths, times and offsets) re-planned with TOPP-RA (module docstring).

    ``from_motion``: toppra from the robot's speed along the branch's start (``feasible`` or not; the
    robot's speed normal to the branch, ``normal_speed`` in rad/s, is dropped). ``brake_replan``: the robot
    brakes to rest with the env's braking law (``braking_s``), then toppra solves the branch from there, from
    rest: ``duration_s`` from the change to rest at the end, ``solve_ms``, ``violations`` (TOPP-RA's own; it
    has no jerk limit).
    """
    from pathrl.baselines.toppra import PathLimits, ToppraSettings, solve_segment
    from pathrl.paths.spline import fit_spline

    rng = np.random.default_rng(seed)
    dt = follower.env_cfg.dt
    lim = JointLimits.from_robot(follower.robot)
    rows = []
    for i in range(episodes):
        a = i % len(knots)
        k = int(round(rng.uniform(*switch_range) / dt))
        follower.reset(knots[a])
        _run(follower, k, [], None)
        direction = rng.standard_normal(follower.robot.path_dof)
        idx = follower.env.path_index.numpy()
        limits = PathLimits(lim.vel[idx].numpy(), lim.acc[idx].numpy(), lim.pos[idx].numpy())
        settings = ToppraSettings(control_rate=follower.env_cfg.control_rate, keep_trajectory=False)
        new = _switch(direction, follower, offset_rad, ramp_rad)
        spline = fit_spline(new)
        tangent = spline(0.0, 1)
        tangent = tangent / max(np.linalg.norm(tangent), 1e-12)
        v = follower.state[1][idx]
        along = float(v @ tangent)
        _, length = knot_arc_lengths(new)
        moving = solve_segment(new, 0.0, length, limits, settings, start_rate=max(along, 0.0))
        follower.stop()
        braking: list = []
        _run(follower, 100, braking, None)
        rest = _switch(direction, follower, offset_rad, ramp_rad)
        _, length = knot_arc_lengths(rest)
        res = solve_segment(rest, 0.0, length, limits, settings)
        rows.append({"path": a, "switch_s": k * dt, "from_motion_feasible": moving.status != "infeasible",
                     "normal_speed": float(np.linalg.norm(v - along * tangent)), "braking_s": len(braking) * dt,
                     "solve_ms": 1e3 * res.solve_time_s, "duration_s": len(braking) * dt + res.duration_s,
                     "status": res.status, "violations": res.num_violations})
    return rows


def _finite(x: float) -> float | None:
    """JSON-safe: None for inf / nan."""
    return float(x) if np.isfinite(x) else None


def summarize(episodes: list[SwitchEpisode], replans: list[dict], level: float, band: float, dt: float,
              control: list[SwitchEpisode] | None = None) -> dict:
    """Aggregate of :func:`path_change_episodes` and :func:`toppra_replan` on the same changes; with `control` (the
    same changes with offset 0) also the settle time against it (:func:`settle_vs_control`)."""
    settle = np.array([e.settle_s(level, dt) for e in episodes])
    in_band = np.array([e.settle_in_band_s(band, dt) for e in episodes])
    paired = {}
    if control is not None:
        vs, excess = (np.array(x) for x in paired_settle(episodes, control, level, dt))
        paired = {"settled_vs_control_within_2s_pct": float(100 * np.mean(vs <= 2.0)),
                  "settle_vs_control_s_median": float(np.median(vs)),
                  "settle_vs_control_s_p95": float(np.quantile(vs, 0.95)),
                  "settle_vs_control_s_hist": {f"<={b:g}": int(np.sum(vs <= b)) for b in (0.0, 0.5, 1.0, 2.0, 4.0)},
                  "excess_after_2s_rad_median": float(np.median(excess)),
                  "excess_after_2s_rad_p95": float(np.quantile(excess, 0.95))}
    peak = np.array([max(e.dev_after) for e in episodes])
    learned = np.array([e.duration_s for e in episodes])
    ok = [r for r in replans if r["status"] != "infeasible"]
    topp = np.array([r["duration_s"] for r in ok])
    return {
        "episodes": len(episodes), "settle_level_rad": level,
        "replan_ms_mean": float(np.mean([e.replan_ms for e in episodes])),
        "replan_ms_max": float(np.max([e.replan_ms for e in episodes])),
        "dev_peak_rad_median": float(np.median(peak)), "dev_peak_rad_p95": float(np.quantile(peak, 0.95)),
        "settle_s_median": _finite(np.median(settle)), "settle_s_p95": _finite(np.quantile(settle, 0.95)),
        "settled_within_2s_pct": float(100 * np.mean(settle <= 2.0)),
        "settle_band_rad": band, "settled_in_band_within_2s_pct": float(100 * np.mean(in_band <= 2.0)),
        "left_band_pct": float(100 * np.mean(in_band > 0.0)),
        "settle_in_band_s_median": float(np.median(in_band)), "settle_in_band_s_p95": float(np.quantile(in_band, 0.95)),
        "settle_in_band_s_hist": {f"<={b:g}": int(np.sum(in_band <= b)) for b in (0.0, 0.5, 1.0, 2.0, 4.0)},
        "duration_after_switch_s": float(learned.mean()), "reached_end_pct": float(100 * np.mean(
            [e.reached_end for e in episodes])),
        "limit_violations": int(sum(e.violations for e in episodes)),
        "toppra_duration_after_switch_s": _finite(topp.mean()) if len(topp) else None,
        "toppra_solve_ms_mean": _finite(np.mean([r["solve_ms"] for r in ok])) if ok else None,
        "toppra_violations": int(sum(r["violations"] for r in ok)),
        "toppra_from_motion_feasible_pct": float(100 * np.mean([r["from_motion_feasible"] for r in replans])),
        "toppra_normal_speed_median": float(np.median([r["normal_speed"] for r in replans])),
        "learned_over_toppra": _finite(learned.mean() / topp.mean()) if len(topp) else None, **paired,
    }


def main(argv: list[str] | None = None) -> None:
    """``python -m pathrl.eval.path_change MODEL_DIR TEST_DATASET OUT.json [--episodes N] [--seed S]``."""
    import argparse

    from pathrl.dataset.io import load_dataset
    from pathrl.storage import write_json_atomic

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model")
    ap.add_argument("dataset")
    ap.add_argument("out")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    follower = Follower.load(args.model, out_of_limits="clip")  # a branch's spline may bulge past the range: module doc
    knots = load_dataset(args.dataset, follower.robot).splits["test"].knots
    unchanged = unchanged_deviation(follower, knots, args.episodes)
    level, band = tracking_level(unchanged), peak_band(unchanged)
    dt = follower.env_cfg.dt
    res: dict = {"model": args.model, "dataset": args.dataset, "seed": args.seed, "switch_range_s": SWITCH_RANGE,
                 "variants": {}}
    control = None
    for name, (offset, ramp) in VARIANTS.items():  # "none" first: the control of the others
        episodes = path_change_episodes(follower, knots, args.episodes, args.seed, offset_rad=offset, ramp_rad=ramp)
        replans = toppra_replan(follower, knots, args.episodes, args.seed, offset_rad=offset, ramp_rad=ramp)
        res["variants"][name] = {"offset_rad": offset, "ramp_rad": ramp,
                                 **summarize(episodes, replans, level, band, dt, control),
                                 "settle_s": [_finite(e.settle_s(level, dt)) for e in episodes],
                                 "settle_in_band_s": [e.settle_in_band_s(band, dt) for e in episodes]}
        if control is not None:
            vs, excess = paired_settle(episodes, control, level, dt)
            res["variants"][name].update(settle_vs_control_s=vs, excess_after_2s_rad=excess)
        control = episodes if offset == 0.0 else control
    write_json_atomic(args.out, res)


if __name__ == "__main__":
    main()
