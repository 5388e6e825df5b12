"""Dataset generators: ``random``, ``target_point`` and ``ball_balancing`` reference paths.

All generators are seedable and deterministic: a split is cut into chunks of ``chunk_size`` paths;
chunk ``c`` of split ``s`` (train = 0, test = 1) draws from ``SeedSequence(seed, spawn_key=(s, c))``
(a numpy Generator and a torch Generator), so train and test use disjoint streams and the result does
not depend on the number of worker processes. Chunks run in ``workers`` processes (joblib/loky).

Paths are stored as knots resampled every ``knot_spacing`` rad of arc length (0.1 for random /
target point, 0.3 for ball balancing); the paper's knot strategies (curvature 0.3 / distance) are
applied at load time (:func:`pathrl.dataset.io.load_pathset`).

``random`` (paper: "random actions at each decision step"; original_pathtracking.md 9):
    * start configuration uniform within the position limits, accepted if collision free (self +
      floor) and every TCP lies inside the robot's workspace box (``spec.workspace``), as the authors did;
    * every 0.1 s decision step a random action in [-1, 1]^D (optionally AR(1)-smoothed with
      ``action_smoothing`` rho: x_t = rho x_{t-1} + sqrt(1 - rho^2) u_t) is mapped into the valid
      acceleration range of :mod:`pathrl.limits` (position, velocity, acceleration, jerk limits incl.
      braking), the motion is integrated with linear acceleration interpolation and recorded at
      ``substeps`` points per step;
    * every recorded sample is collision checked; on a collision the candidate is rewound to its last
      checkpoint (every ``checkpoint_steps`` steps) and continues with new random actions (a
      stand-in for the authors' collision avoidance, Kiemel et al. 2021); after ``max_rewinds``
      rewinds it is dropped;
    * recording stops when the joint-space polyline length reaches a target length drawn per path
      from U(length_range) (the released sets look like fixed-length cuts: iiwa 19.6-26.1 rad,
      mean 22.9). Default ranges per robot are chosen to match the released sets' mean and maximum:
      iiwa7 U(19.5, 26.0), armar6 U(21.6, 25.5), armar4 U(18.0, 22.9);
    * the recorded positions (path joints) are cut at the target length, a natural cubic spline is
      put through them and resampled every 0.1 rad;
    * motions use the position limits shrunk by ``limit_margin`` (0.02 rad): where a joint turns at
      its limit, the spline through 0.1 rad knots overshoots by up to ~0.01 rad; the stored path is
      then checked (limits every 0.01 rad, collisions every ``check_spacing`` rad) and rejected if bad;
    * with uniform random actions (no smoothing) the curvature-resampled knot counts match the
      released sets without tuning (iiwa ~152 knots for ~22.7 rad vs 151 for 22.9).
``target_point`` (paper: a policy reaching random Cartesian target points):
    * same start as ``random``; then a sequence of goals: a Cartesian point per TCP drawn uniformly in
      the workspace box (restricted to 5 cm voxels the TCP reaches in 20 000 random configurations,
      which avoids hopeless IK problems), solved by damped-least-squares IK on the torch FK (seeded
      near the previous goal, within position limits, collision free, >= ``min_goal_distance`` rad
      away); goals are solved in batches and queued per candidate (``goal_batch``);
    * the robot moves toward the current goal with a limit-respecting motion (``approach``): by default
      (``saturated``) every joint on its own heads for its goal value at up to ``cruise`` x its velocity
      limit (desired velocity ``clamp(gain * e, +-cruise * v_max)``, acceleration ``gain * (v_des - v)``),
      plus uniform action noise (``action_noise``), mapped into the valid acceleration range; when the
      configuration is within ``goal_tolerance`` rad (path joints, Euclidean) of the goal, the next goal
      is drawn (a checkpoint); on a collision the candidate is rewound to the last goal switch and gets
      a new goal;
    * recorded, cut at a target length from U(length_range) (iiwa7 U(22.0, 28.9), armar4 U(23.7, 29.4),
      matching the released sets' mean and maximum), splined, resampled every 0.1 rad and checked as
      above.
    * why ``saturated`` (measured on 40 test paths each, ``segments=paper``, 200 TOPP-RA episodes): a
      joint-space straight line to each IK goal (``pd``: critically damped PD; ``pursuit``: constant
      speed) is dominated by the joints that differ most between goals (the base), so its
      velocity-limited speed is 2.5 rad/s against 3.9 for random paths and TOPP-RA needs 5.1 s per
      segment (iiwa7), 1.7x the random paths, where the paper's target-point paths take 1.13x (3.79 vs
      3.36 s, about their length ratio). Joints moving independently (as an acceleration policy that
      saturates its actions does) give 3.5 rad/s, TOPP-RA 3.55 s (iiwa7) / 3.55 s (armar4, paper 3.68),
      and with gain 6, cruise 0.8, noise 0.1, tolerance 0.4 the curvature knot density of the released
      sets (iiwa7 6.29 knots/rad vs 6.30; armar4 7.3 vs 7.9).
``ball_balancing`` (iiwa7 only; original_pathtracking.md 8.1):
    * paths in the plate-horizontal subspace q3 = q5 = 0, q6 = q4 - q2 (joint axes 2, 4, 6 are +y, -y,
      +y, so the flange z axis stays vertical and points up) and |q7| <= 0.009: a natural spline through
      random waypoints (start uniform; then steps in (q1, q2, q4) of norm U(waypoint_step) rad whose
      direction turns by N(0, waypoint_turn) noise, each waypoint valid; q7 in +-``q7_max``), added until
      the polyline is 15 % longer than the target length; the constraints are linear, so every point of
      every spline through such knots satisfies them exactly;
    * cut at a length L = lo + (hi - lo) * Beta(length_beta) with (lo, hi) = (3.2, 5.1) (released set:
      3.23 / 3.79 / 5.10 rad min / mean / max; Beta(1.5, 3.5) has mean 0.3 -> 3.77 rad);
    * stored knots resampled every 0.3 rad (the authors' distance knots for this set); the stored
      path must have a length within (lo, hi) (rare sharp turns get cut short by the knot spacing) and
      every point (sampled every ``check_spacing`` rad) within the position limits, collision free and
      with the TCP in the workspace box.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from pathrl.dataset.io import (
    Dataset,
    DatasetError,
    check_destination,
    path_lengths_and_gaps,
    save_dataset,
    write_cache,
)
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.spline import PathError, dedupe_knots, resample_by_distance, sample_uniform
from pathrl.robot.model import RobotSpec, load_robot

KINDS = ("random", "target_point", "ball_balancing")
APPROACHES = ("saturated", "pursuit", "pd")  # target_point motion toward each goal
SPLIT_IDS = {"train": 0, "test": 1}

_COMMON = {
    "chunk_size": 100,  # paths per chunk (unit of seeding and of parallel work)
    "batch_size": 256,  # at most this many candidate trajectories simulated together
    "dt": 0.1,  # decision step (s)
    "substeps": 4,  # recorded (and collision-checked) samples per decision step
    "max_duration": 60.0,  # longest simulated motion per candidate (s)
    "max_rewinds": 20,
    "knot_spacing": 0.1,  # stored knots: distance resampling (rad)
    "limit_margin": 0.02,  # motions stay this far inside the position limits (room for spline overshoot)
    "check_spacing": 0.05,  # final check of the stored path: collisions every 0.05 rad (limits every 0.01)
}

DEFAULT_PARAMS: dict[str, dict[str, Any]] = {
    "random": {
        **_COMMON,
        "length_range": {
            "iiwa7": [19.5, 26.0],
            "armar6": [21.6, 25.5],
            "armar4": [18.0, 22.9],
            "default": [19.5, 26.0],
        },
        "action_smoothing": 0.0,
        "checkpoint_steps": 5,
        "oversample": 1.4,  # candidates per missing path (~25 % are dropped after repeated collisions)
        "default_knots": {"strategy": "curvature", "spacing": 0.3, "base_spacing": 0.1},
    },
    "target_point": {
        **_COMMON,
        "length_range": {"iiwa7": [22.0, 28.9], "armar4": [23.7, 29.4], "default": [22.0, 28.9]},
        "oversample": 1.1,
        "approach": "saturated",  # saturated | pursuit | pd (module docstring)
        "cruise": 0.8,  # fraction of the velocity limits (saturated, pursuit)
        "gain": 6.0,
        "action_noise": 0.1,
        "goal_tolerance": 0.4,
        "goal_timeout": 6.0,  # s without reaching the goal -> new goal
        "min_goal_distance": 0.5,
        "ik_iterations": 150,
        "ik_tolerance": 0.005,  # m
        "ik_rounds": 8,
        "ik_candidates": 4,  # random targets solved at once per goal
        "goal_batch": 3,  # goals queued per candidate at each (batched) IK refill
        "default_knots": {"strategy": "curvature", "spacing": 0.3, "base_spacing": 0.1},
    },
    "ball_balancing": {
        "chunk_size": 10,
        "length_range": [3.2, 5.1],
        "length_beta": [1.5, 3.5],
        "waypoint_step": [0.8, 1.6],
        "waypoint_turn": 0.6,
        "q7_max": 0.006,
        "check_spacing": 0.05,
        "knot_spacing": 0.3,
        "max_tries": 200,
        "default_knots": {"strategy": "distance", "spacing": 0.3, "base_spacing": 0.1},
    },
}


class GenerationError(RuntimeError):
    """A generator could not produce the requested paths (e.g. no valid start configurations)."""


def resolve_params(kind: str, robot_name: str, params: Mapping[str, Any] | None) -> dict[str, Any]:
    """Defaults for `kind` updated by `params`; per-robot ``length_range`` mappings resolved."""
    if kind not in DEFAULT_PARAMS:
        raise DatasetError(f"dataset.kind: unknown generator {kind!r}; choose one of {list(KINDS)}")
    out = copy.deepcopy(DEFAULT_PARAMS[kind])
    unknown = sorted(set(params or {}) - set(out))
    if unknown:
        raise DatasetError(f"dataset.params: unknown keys {unknown} for {kind!r}; valid: {sorted(out)}")
    for key, value in (params or {}).items():
        out[key] = copy.deepcopy(dict(value) if isinstance(value, Mapping) else value)
    lr = out["length_range"]
    if isinstance(lr, Mapping):
        lr = lr.get(robot_name, lr.get("default"))
    try:
        lo, hi = (float(x) for x in lr)
    except (TypeError, ValueError):
        raise DatasetError(f"dataset.params.length_range: expected [min, max], got {lr!r}") from None
    if not 0 < lo <= hi:
        raise DatasetError(f"dataset.params.length_range: need 0 < min <= max, got [{lo}, {hi}]")
    out["length_range"] = [lo, hi]
    for key in ("chunk_size", "batch_size", "substeps"):
        if key in out and int(out[key]) < 1:
            raise DatasetError(f"dataset.params.{key} must be >= 1, got {out[key]}")
    if "approach" in out and out["approach"] not in APPROACHES:
        raise DatasetError(f"dataset.params.approach: expected one of {list(APPROACHES)}, got {out['approach']!r}")
    for key in ("cruise", "gain"):
        if key in out and not float(out[key]) > 0:
            raise DatasetError(f"dataset.params.{key} must be > 0, got {out[key]}")
    return out


# ----------------------------------------------------------------------------------------------------
# per-process context


class _Context:
    """FK, collision checker and limits of one robot, built once per process."""

    def __init__(self, robot_cfg: Mapping[str, Any]):
        from pathrl.robot.collision import CollisionChecker
        from pathrl.robot.kinematics import ForwardKinematics

        self.spec: RobotSpec = load_robot(robot_cfg)
        self.fk = ForwardKinematics(self.spec)
        self.checker = CollisionChecker(self.spec)
        self._limits = None
        self.set_margin(0.0)
        self.pidx = torch.as_tensor(self.spec.path_index)

    def set_margin(self, margin: float) -> None:
        """Generate motions within the position limits shrunk by `margin` (rad or m) on each side."""
        if getattr(self, "margin", None) == margin:
            return
        self.margin = float(margin)
        lim = self.spec.pos_limits + np.array([margin, -margin])
        if np.any(lim[:, 0] >= lim[:, 1]):
            raise GenerationError(f"limit_margin {margin} leaves an empty position range")
        self.gen_limits = lim
        self.lo = torch.as_tensor(lim[:, 0])
        self.hi = torch.as_tensor(lim[:, 1])
        self._limits = None

    def reachable_grid(self, n: int = 20_000, voxel: float = 0.05) -> tuple[np.ndarray, float]:
        """Occupancy (T, nx, ny, nz) of the workspace box by each TCP over n random configurations."""
        if getattr(self, "_grid", None) is None:
            rng = np.random.default_rng(12345)
            q = rng.uniform(self.spec.pos_limits[:, 0], self.spec.pos_limits[:, 1], size=(n, self.spec.dof))
            pos = self.fk.tcp_positions_np(q)  # (n, T, 3)
            ws = self.spec.workspace
            shape = np.maximum(np.ceil((ws[:, 1] - ws[:, 0]) / voxel).astype(int), 1)
            grid = np.zeros((pos.shape[1], *shape), dtype=bool)
            idx = np.floor((pos - ws[:, 0]) / voxel).astype(int)
            inside = np.all((idx >= 0) & (idx < shape), axis=-1)
            for t in range(pos.shape[1]):
                i = idx[inside[:, t], t]
                grid[t, i[:, 0], i[:, 1], i[:, 2]] = True
            self._grid = grid
        return self._grid, voxel

    def sample_targets(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n Cartesian targets per TCP (n, T, 3), uniform in the workspace box restricted to voxels
        that the TCP reached in random configurations (skips hopeless IK problems)."""
        grid, voxel = self.reachable_grid()
        ws = self.spec.workspace
        out = np.empty((n, grid.shape[0], 3))
        for t in range(grid.shape[0]):
            got = 0
            for _ in range(1000):
                x = rng.uniform(ws[:, 0], ws[:, 1], size=(4 * (n - got) + 8, 3))
                i = np.minimum(np.floor((x - ws[:, 0]) / voxel).astype(int), np.array(grid.shape[1:]) - 1)
                x = x[grid[t, i[:, 0], i[:, 1], i[:, 2]]][: n - got]
                out[got : got + len(x), t] = x
                got += len(x)
                if got == n:
                    break
            else:
                raise GenerationError(f"{self.spec.name}: TCP {t} never reaches its workspace box")
        return out

    @property
    def limits(self):
        if self._limits is None:
            from dataclasses import replace

            from pathrl.limits.feasible import JointLimits

            self._limits = JointLimits.from_robot(replace(self.spec, pos_limits=self.gen_limits))
        return self._limits

    def in_collision(self, q: np.ndarray | torch.Tensor) -> np.ndarray:
        q = q.detach().cpu().numpy() if isinstance(q, torch.Tensor) else np.asarray(q)
        if len(q) == 0:
            return np.zeros(0, dtype=bool)
        return np.asarray(self.checker.in_collision(np.ascontiguousarray(q, dtype=np.float64)), dtype=bool)

    def in_workspace(self, q: np.ndarray | torch.Tensor) -> np.ndarray:
        q = q.detach().cpu().numpy() if isinstance(q, torch.Tensor) else np.asarray(q)
        if len(q) == 0:
            return np.zeros(0, dtype=bool)
        pos = self.fk.tcp_positions_np(q)  # (N, T, 3)
        ws = self.spec.workspace
        return np.all((pos >= ws[:, 0]) & (pos <= ws[:, 1]), axis=(1, 2))


_CONTEXTS: dict[str, _Context] = {}


def _context(robot_cfg: Mapping[str, Any]) -> _Context:
    key = repr(sorted(robot_cfg.items()))
    if key not in _CONTEXTS:
        torch.set_num_threads(1)
        _CONTEXTS.clear()
        _CONTEXTS[key] = _Context(robot_cfg)
    return _CONTEXTS[key]


def _rngs(seed: int, split_id: int, chunk: int) -> tuple[np.random.Generator, torch.Generator]:
    ss = np.random.SeedSequence(int(seed), spawn_key=(split_id, chunk))
    rng = np.random.default_rng(ss)
    tgen = torch.Generator().manual_seed(int(ss.generate_state(1, np.uint64)[0] & 0x7FFF_FFFF_FFFF_FFFF))
    return rng, tgen


# ----------------------------------------------------------------------------------------------------
# start configurations and IK


def sample_starts(ctx: _Context, rng: np.random.Generator, n: int, max_draws: int = 200_000) -> np.ndarray:
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
    ctx: _Context,
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


# ----------------------------------------------------------------------------------------------------
# batched limit-respecting rollouts (random / target point)


class _RandomPolicy:
    def __init__(self, ctx: _Context, p: Mapping[str, Any], n: int, tgen: torch.Generator):
        self.rho = float(p["action_smoothing"])
        self.ck_steps = int(p["checkpoint_steps"])
        self.tgen = tgen
        self.prev = torch.zeros(n, ctx.spec.dof, dtype=torch.float64)

    def reset(self, q0: torch.Tensor) -> torch.Tensor:
        return torch.zeros(len(q0), dtype=torch.bool)

    def action(self, rows, p, v, a, a_min, a_max) -> torch.Tensor:
        u = torch.rand(a_min.shape, generator=self.tgen, dtype=torch.float64) * 2.0 - 1.0
        if self.rho > 0:
            u = (self.rho * self.prev[rows] + math.sqrt(1.0 - self.rho**2) * u).clamp(-1.0, 1.0)
            self.prev[rows] = u
        return u

    def after_step(self, rows, p, steps) -> tuple[torch.Tensor, torch.Tensor]:
        """-> (checkpoint mask, reject mask) for `rows`."""
        return steps[rows] % self.ck_steps == 0, torch.zeros(len(rows), dtype=torch.bool)

    def finished(self, rows: torch.Tensor) -> None:
        pass

    def on_rewind(self, rows, p) -> torch.Tensor:
        self.prev[rows] = 0.0
        return torch.zeros(len(rows), dtype=torch.bool)


class _TargetPolicy:
    def __init__(self, ctx: _Context, p: Mapping[str, Any], n: int, rng: np.random.Generator, tgen):
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


def _cut(rec: np.ndarray, s: np.ndarray, length: float) -> np.ndarray:
    """Recorded polyline (S, M) with cumulative lengths s, cut at arc length `length`."""
    j = int(np.searchsorted(s, length))
    if j >= len(s):
        return rec
    seg = s[j] - s[j - 1]
    w = (length - s[j - 1]) / seg if seg > 0 else 1.0
    out = rec[: j + 1].copy()
    out[j] = rec[j - 1] + w * (rec[j] - rec[j - 1])
    return out


def rollout_paths(
    ctx: _Context,
    kind: str,
    p: Mapping[str, Any],
    n_paths: int,
    rng: np.random.Generator,
    tgen: torch.Generator,
    stats: dict[str, int] | None = None,
) -> list[np.ndarray]:
    """Recorded polylines (path joints) of `n_paths` accepted limit-respecting motions."""
    from pathrl.limits.feasible import action_to_acceleration, valid_acceleration_range
    from pathrl.limits.integrate import interpolate_step

    stats = stats if stats is not None else {}
    dt, n_sub = float(p["dt"]), int(p["substeps"])
    lo_len, hi_len = p["length_range"]
    max_steps = int(math.ceil(float(p["max_duration"]) / dt))
    d, m = ctx.spec.dof, len(ctx.pidx)
    cap = max_steps * n_sub + 1
    out: list[np.ndarray] = []
    while len(out) < n_paths:
        # enough candidates for the missing paths (some get dropped), at most batch_size
        b = min(int(p["batch_size"]), math.ceil(float(p["oversample"]) * (n_paths - len(out))) + 1)
        q0 = torch.as_tensor(sample_starts(ctx, rng, b))
        target = torch.as_tensor(rng.uniform(lo_len, hi_len, size=b))
        if kind == "random":
            pol: Any = _RandomPolicy(ctx, p, b, tgen)
        else:
            pol = _TargetPolicy(ctx, p, b, rng, tgen)
        pos, vel, acc = (
            q0.clone(),
            torch.zeros(b, d, dtype=torch.float64),
            torch.zeros(b, d, dtype=torch.float64),
        )
        rec = torch.zeros(b, cap, m, dtype=torch.float64)
        s = torch.zeros(b, cap, dtype=torch.float64)
        rec[:, 0] = q0[:, ctx.pidx]
        n_rec = torch.ones(b, dtype=torch.long)
        steps = torch.zeros(b, dtype=torch.long)
        rewinds = torch.zeros(b, dtype=torch.long)
        ck = {
            "pos": pos.clone(),
            "vel": vel.clone(),
            "acc": acc.clone(),
            "n": n_rec.clone(),
            "steps": steps.clone(),
        }
        active = ~pol.reset(q0)
        done = torch.zeros(b, dtype=torch.bool)
        stats["candidates"] = stats.get("candidates", 0) + b
        was_active = active.clone()
        for _ in range(max_steps * 4):
            ended = (was_active & ~active).nonzero().squeeze(1)
            if len(ended):
                pol.finished(ended)
            was_active = active.clone()
            rows = active.nonzero().squeeze(1)
            if len(rows) == 0:
                break
            p0, v0, a0 = pos[rows], vel[rows], acc[rows]
            a_min, a_max = valid_acceleration_range(p0, v0, a0, ctx.limits, dt)
            act = pol.action(rows, p0, v0, a0, a_min, a_max)
            a1 = action_to_acceleration(act, a_min, a_max)
            ps, vs, _ = interpolate_step(p0, v0, a0, a1, dt, n_sub)  # (n, n_sub, D)
            coll = torch.as_tensor(ctx.in_collision(ps.reshape(-1, d)).reshape(len(rows), n_sub).any(axis=1))
            stats["checks"] = stats.get("checks", 0) + len(rows) * n_sub
            ok = ~coll
            if ok.any():
                r = rows[ok]
                new = ps[ok][:, :, ctx.pidx]  # (k, n_sub, M)
                cols = n_rec[r][:, None] + torch.arange(n_sub)
                prev = rec[r, n_rec[r] - 1]
                seg = torch.diff(torch.cat([prev[:, None], new], dim=1), dim=1).norm(dim=-1)
                rec[r[:, None], cols] = new
                s[r[:, None], cols] = s[r, n_rec[r] - 1][:, None] + torch.cumsum(seg, dim=1)
                n_rec[r] += n_sub
                pos[r], vel[r], acc[r] = ps[ok][:, -1], vs[ok][:, -1], a1[ok]
                steps[r] += 1
                fin = s[r, n_rec[r] - 1] >= target[r]
                done[r[fin]] = True
                active[r[fin]] = False
                rest = ~fin
                r2 = r[rest]
                if len(r2):
                    ckm, rej = pol.after_step(r2, pos[r2], steps)
                    timeout = n_rec[r2] + n_sub > cap
                    stats["dropped_timeout"] = stats.get("dropped_timeout", 0) + int(timeout.sum())
                    stats["dropped_goal"] = stats.get("dropped_goal", 0) + int((rej & ~timeout).sum())
                    rej = rej | timeout
                    active[r2[rej]] = False
                    c = r2[ckm & ~rej]
                    for key, val in (
                        ("pos", pos),
                        ("vel", vel),
                        ("acc", acc),
                        ("n", n_rec),
                        ("steps", steps),
                    ):
                        ck[key][c] = val[c]
                    rewinds[c] = 0
            if coll.any():
                r = rows[coll]
                rewinds[r] += 1
                stats["rewinds"] = stats.get("rewinds", 0) + len(r)
                give_up = rewinds[r] > int(p["max_rewinds"])
                stats["dropped_collision"] = stats.get("dropped_collision", 0) + int(give_up.sum())
                active[r[give_up]] = False
                r = r[~give_up]
                if len(r):
                    pos[r], vel[r], acc[r] = ck["pos"][r], ck["vel"][r], ck["acc"][r]
                    n_rec[r], steps[r] = ck["n"][r], ck["steps"][r]
                    fail = pol.on_rewind(r, pos[r])
                    active[r[fail]] = False
        for i in done.nonzero().squeeze(1).tolist():
            n_i = int(n_rec[i])
            out.append(_cut(rec[i, :n_i].numpy(), s[i, :n_i].numpy(), float(target[i])))
            if len(out) == n_paths:
                break
    stats["accepted"] = stats.get("accepted", 0) + len(out)
    return out


# ----------------------------------------------------------------------------------------------------
# ball balancing


def _ball_full(red: np.ndarray) -> np.ndarray:
    """Reduced (q1, q2, q4, q7) (..., 4) -> iiwa joints (..., 7) with q3 = q5 = 0, q6 = q4 - q2."""
    q = np.zeros(red.shape[:-1] + (7,))
    q[..., 0], q[..., 1], q[..., 3], q[..., 6] = red[..., 0], red[..., 1], red[..., 2], red[..., 3]
    q[..., 5] = red[..., 2] - red[..., 1]
    return q


def ball_constraint_violation(q: np.ndarray) -> np.ndarray:
    """Per sample (..., 7): max(|q3|, |q5|, |q6 - (q4 - q2)|, max(|q7| - 0.009, 0))."""
    q = np.asarray(q)
    return np.max(
        np.stack(
            [
                np.abs(q[..., 2]),
                np.abs(q[..., 4]),
                np.abs(q[..., 5] - (q[..., 3] - q[..., 1])),
                np.maximum(np.abs(q[..., 6]) - 0.009, 0.0),
            ],
            axis=-1,
        ),
        axis=-1,
    )


def check_ball_robot(spec: RobotSpec) -> None:
    if spec.dof != 7 or spec.path_dof != 7 or not spec.name.startswith("iiwa"):
        raise DatasetError(
            f"dataset ball_balancing is defined for the iiwa7 only (plate-horizontal joint constraints), "
            f"not for robot {spec.name!r}"
        )


def _ball_point_ok(ctx: _Context, red: np.ndarray) -> bool:
    lim = ctx.spec.pos_limits
    q = _ball_full(red)
    if np.any(q < lim[:, 0]) or np.any(q > lim[:, 1]):
        return False
    return bool(ctx.in_workspace(q[None])[0]) and not bool(ctx.in_collision(q[None])[0])


def ball_paths(
    ctx: _Context,
    p: Mapping[str, Any],
    n_paths: int,
    rng: np.random.Generator,
    stats: dict[str, int] | None = None,
) -> list[np.ndarray]:
    """Plate-horizontal iiwa paths: spline through valid random (q1, q2, q4, q7) waypoints, cut, checked."""
    check_ball_robot(ctx.spec)
    stats = stats if stats is not None else {}
    lim = ctx.spec.pos_limits
    lo, hi = p["length_range"]
    a_beta, b_beta = (float(x) for x in p["length_beta"])
    step_lo, step_hi = (float(x) for x in p["waypoint_step"])
    q7_max = float(p["q7_max"])
    turn = float(p["waypoint_turn"])
    out: list[np.ndarray] = []
    tries = 0
    while len(out) < n_paths:
        tries += 1
        if tries > int(p["max_tries"]) * max(n_paths, 1):
            raise GenerationError(f"ball_balancing: only {len(out)} of {n_paths} valid paths in {tries} tries")
        stats["candidates"] = stats.get("candidates", 0) + 1
        length = lo + (hi - lo) * rng.beta(a_beta, b_beta)
        # start: uniform in (q1, q2, q4) with q6 = q4 - q2 in limits, plate in the workspace, collision free
        for _ in range(10_000):
            red = np.array(
                [
                    rng.uniform(*lim[0]),
                    rng.uniform(*lim[1]),
                    rng.uniform(*lim[3]),
                    rng.uniform(-q7_max, q7_max),
                ]
            )
            if _ball_point_ok(ctx, red):
                break
        else:
            raise GenerationError("ball_balancing: no valid start configuration found")
        pts, poly = [red], 0.0
        heading = rng.normal(size=3)
        while poly < 1.15 * length:
            for _ in range(50):
                direction = heading / np.linalg.norm(heading) + turn * rng.normal(size=3)
                direction /= np.linalg.norm(direction)
                nxt = pts[-1].copy()
                nxt[:3] += direction * rng.uniform(step_lo, step_hi)
                nxt[3] = rng.uniform(-q7_max, q7_max)
                if _ball_point_ok(ctx, nxt):
                    break
            else:
                break
            heading = direction
            poly += float(np.linalg.norm(_ball_full(nxt) - _ball_full(pts[-1])))
            pts.append(nxt)
        if poly < 1.15 * length:
            continue
        knots = _ball_full(np.asarray(pts))
        try:
            dense, total = sample_uniform(knots, float(p["check_spacing"]) / 4)
        except PathError:
            continue
        if total < length:
            continue
        cum = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))]
        path = _cut(dense, cum, length)
        try:
            stored = resample_by_distance(path, float(p["knot_spacing"]))
            check, stored_length = sample_uniform(stored, float(p["check_spacing"]))
        except PathError:
            continue
        if not lo <= stored_length <= hi:  # sharp turns cut short by the knot spacing
            stats["rejected_length"] = stats.get("rejected_length", 0) + 1
            continue
        stats["checks"] = stats.get("checks", 0) + len(check)
        if not _ball_valid(ctx, check):
            stats["rejected"] = stats.get("rejected", 0) + 1
            continue
        out.append(stored)
    stats["accepted"] = stats.get("accepted", 0) + len(out)
    return out


def _ball_valid(ctx: _Context, q: np.ndarray) -> bool:
    lim = ctx.spec.pos_limits
    if np.any(q < lim[:, 0] - 1e-9) or np.any(q > lim[:, 1] + 1e-9):
        return False
    if np.any(ball_constraint_violation(q) > 1e-9):
        return False
    if not np.all(ctx.in_workspace(q)):
        return False
    return not np.any(ctx.in_collision(q))


# ----------------------------------------------------------------------------------------------------
# chunks and datasets


def path_valid(ctx: _Context, knots: np.ndarray, spacing: float) -> bool:
    """The stored path (spline through `knots`) within the position limits (dense samples, 0.01 rad)
    and collision free (samples every `spacing` rad)."""
    lim = ctx.spec.pos_limits
    q, _ = sample_uniform(knots, 0.01)
    if np.any(q < lim[:, 0]) or np.any(q > lim[:, 1]):
        return False
    qc, _ = sample_uniform(knots, spacing)
    return not np.any(ctx.in_collision(qc))


def _path_metrics(knots_list: Sequence[np.ndarray]) -> np.ndarray:
    counts, lengths, gaps = path_lengths_and_gaps(knots_list)
    return np.stack([counts, lengths, gaps], axis=1) if len(counts) else np.zeros((0, 3))


def generate_chunk(
    robot_cfg: Mapping[str, Any],
    kind: str,
    params: Mapping[str, Any],
    seed: int,
    split_id: int,
    chunk: int,
    n: int,
) -> dict[str, Any]:
    """Generate one chunk: stored knots, knots under the default strategy and per-path metrics of both."""
    ctx = _context(robot_cfg)
    rng, tgen = _rngs(seed, split_id, chunk)
    stats: dict[str, int] = {}
    t0 = time.perf_counter()
    if kind == "ball_balancing":
        stored = ball_paths(ctx, params, n, rng, stats)
    else:
        ctx.set_margin(float(params["limit_margin"]))
        stored = []
        while len(stored) < n:
            polys = rollout_paths(ctx, kind, params, n - len(stored), rng, tgen, stats)
            for pl in polys:
                k = resample_by_distance(dedupe_knots(pl), float(params["knot_spacing"]))
                if path_valid(ctx, k, float(params["check_spacing"])):
                    stored.append(k)
                else:
                    stats["rejected_final"] = stats.get("rejected_final", 0) + 1
    strategy = KnotStrategy.from_cfg(params["default_knots"])
    resampled = [strategy.apply(k) for k in stored]
    return {
        "stored": stored,
        "resampled": resampled,
        "metrics_stored": _path_metrics(stored),
        "metrics_resampled": _path_metrics(resampled),
        "stats": stats,
        "seconds": time.perf_counter() - t0,
    }


def _metrics_stats(metrics: np.ndarray) -> dict[str, Any]:
    if len(metrics) == 0:
        return {"count": 0}
    c, length, g = metrics[:, 0], metrics[:, 1], metrics[:, 2]
    return {
        "count": len(metrics),
        "knots": {"min": int(c.min()), "mean": float(c.mean()), "max": int(c.max())},
        "length": {"min": float(length.min()), "mean": float(length.mean()), "max": float(length.max())},
        "max_knot_gap": float(g.max()),
    }


@dataclass
class _Job:
    split: str
    chunk: int
    n: int


def _run_jobs(
    jobs: list[_Job],
    fn: Callable[[_Job], dict[str, Any]],
    workers: int,
    progress: bool,
    label: str,
    total: int,
) -> list[dict[str, Any]]:
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    results: list[dict[str, Any] | None] = [None] * len(jobs)
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        disable=not progress,
        transient=False,
    ) as bar:
        task = bar.add_task(label, total=total)
        if workers <= 1 or len(jobs) <= 1:
            for i, job in enumerate(jobs):
                results[i] = fn(job)
                bar.advance(task, job.n)
        else:
            from joblib import Parallel, delayed

            par = Parallel(n_jobs=workers, return_as="generator_unordered", backend="loky")
            for i, res in par(delayed(_indexed)(fn, i, job) for i, job in enumerate(jobs)):
                results[i] = res
                bar.advance(task, jobs[i].n)
    return results  # type: ignore[return-value]


def _indexed(fn: Callable[[_Job], dict[str, Any]], i: int, job: _Job) -> tuple[int, dict[str, Any]]:
    return i, fn(job)


@dataclass
class _ChunkFn:
    robot_cfg: dict[str, Any]
    kind: str
    params: dict[str, Any]
    seed: int

    def __call__(self, job: _Job) -> dict[str, Any]:
        return generate_chunk(self.robot_cfg, self.kind, self.params, self.seed, SPLIT_IDS[job.split], job.chunk, job.n)


def generate_dataset(
    robot_cfg: Mapping[str, Any],
    dataset_cfg: Mapping[str, Any],
    dest: str | None = None,
    workers: int = 1,
    overwrite: bool = False,
    progress: bool = True,
) -> Dataset:
    """Generate and save a dataset (train + test) as configured by a resolved robot and dataset config.

    The destination is checked before any work; the result is written atomically. The default knot
    strategy's resampled knots are written to the dataset's cache, and meta["stats"] holds the stored
    and the resampled statistics per split.
    """
    robot_cfg = dict(robot_cfg)
    spec = load_robot(robot_cfg)
    kind = str(dataset_cfg["kind"])
    if kind not in KINDS:
        raise DatasetError(f"dataset.kind: unknown generator {kind!r}; choose one of {list(KINDS)}")
    if kind == "ball_balancing":
        check_ball_robot(spec)
    if spec.dof != spec.path_dof:
        raise DatasetError(
            f"robot {spec.name!r} controls joints outside the path; generate with a robot whose joints are "
            f"all path joints (e.g. armar4 for armar4_legs: the datasets share path_joints)"
        )
    params = resolve_params(kind, spec.name, dataset_cfg.get("params"))
    seed = int(dataset_cfg.get("seed", 0))
    counts = {"train": int(dataset_cfg.get("num_train", 0)), "test": int(dataset_cfg.get("num_test", 0))}
    if any(c < 0 for c in counts.values()) or sum(counts.values()) == 0:
        raise DatasetError(f"dataset.num_train / num_test must be >= 0 and not both 0, got {counts}")
    dest = str(dest if dest is not None else dataset_cfg["path"])
    check_destination(dest, overwrite)
    if workers < 1:
        raise DatasetError(f"workers must be >= 1, got {workers}")

    t0 = time.perf_counter()
    chunk = int(params["chunk_size"])
    jobs = [
        _Job(split, c, min(chunk, counts[split] - c * chunk))
        for split in ("train", "test")
        for c in range(math.ceil(counts[split] / chunk))
    ]
    fn = _ChunkFn(robot_cfg, kind, params, seed)
    results = _run_jobs(jobs, fn, workers, progress, f"{spec.name}/{kind}", sum(counts.values()))
    splits: dict[str, list[tuple[str, np.ndarray]]] = {"train": [], "test": []}
    resampled: dict[str, list[np.ndarray]] = {"train": [], "test": []}
    metrics: dict[str, list[np.ndarray]] = {"train": [], "test": []}
    metrics_r: dict[str, list[np.ndarray]] = {"train": [], "test": []}
    gen_stats: dict[str, int] = {}
    cpu = 0.0
    for job, res in zip(jobs, results, strict=True):
        for k in res["stored"]:
            splits[job.split].append((f"{job.split}_{len(splits[job.split]):05d}", k))
        resampled[job.split].extend(res["resampled"])
        metrics[job.split].append(res["metrics_stored"])
        metrics_r[job.split].append(res["metrics_resampled"])
        for key, val in res["stats"].items():
            gen_stats[key] = gen_stats.get(key, 0) + int(val)
        cpu += res["seconds"]
    strategy = KnotStrategy.from_cfg(params["default_knots"])
    from pathrl.dataset.io import strategy_key

    skey = strategy_key(strategy)
    stats = {}
    for split in splits:
        ms = np.concatenate(metrics[split]) if metrics[split] else np.zeros((0, 3))
        mr = np.concatenate(metrics_r[split]) if metrics_r[split] else np.zeros((0, 3))
        stats[split] = {"stored": _metrics_stats(ms), skey: _metrics_stats(mr)}
    elapsed = time.perf_counter() - t0
    meta = {
        "robot": spec.name,
        "kind": kind,
        "path_joints": list(spec.path_joints),
        "seed": seed,
        "generator": {
            "name": str(dataset_cfg.get("name", kind)),
            "kind": kind,
            "params": params,
            "num_train": counts["train"],
            "num_test": counts["test"],
            "robot_config": robot_cfg,
        },
        "source": "generated",
        "default_knots": dict(params["default_knots"]),
        "generation": {
            "seconds": round(elapsed, 2),
            "worker_seconds": round(cpu, 2),
            "workers": workers,
            **gen_stats,
        },
    }
    ds = save_dataset(dest, splits, meta, overwrite=overwrite, stats=stats)
    for split in splits:
        if resampled[split]:
            write_cache(ds, split, strategy, resampled[split])
    return ds
