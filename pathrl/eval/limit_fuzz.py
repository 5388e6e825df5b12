"""Adversarial limit fuzz: drive the tracking env with action streams built to break its limits, and count every
limit violation of the commanded trajectory at the control rate.

The env's guarantee is that *any* action keeps every joint inside its position, velocity, acceleration and jerk
limits (the valid acceleration range, :mod:`pathrl.limits.feasible`). The fuzz attacks it with, per env (env i
uses stream ``i % 5``):

- ``uniform``: independent uniform actions in [-1, 1];
- ``bang_bang``: independent signs, +-1;
- ``sticky``: an extreme held for a random number of steps (drives joints into their position limits);
- ``chatter``: +-1 alternating every step (the largest jerk demand);
- ``nan_inf``: uniform actions with 5 % of the entries NaN, +inf or -inf (the env substitutes a safe action).

On top, at every step each env is, with small probabilities, restarted at rest *on* its position limits (every
joint at its lower or upper bound), restarted at a fresh path segment, or switched to the end-of-path braking
law from wherever it is. Episodes never end by themselves (no deviation termination, no time-out, no
auto-reset), so streams run long and reach the corners of the state space. Every step's 24 control-rate
setpoints (and the jerk from the step's start) are checked with :func:`pathrl.limits.check.limit_violations`.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import torch
from torch import Tensor

from pathrl.dataset.io import load_pathset
from pathrl.envs.rewards import build_reward_terms
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.limits.check import KINDS, limit_violations
from pathrl.limits.integrate import interpolate_step
from pathrl.paths.knots import KnotStrategy
from pathrl.robot.external import load_robot_by_name

__all__ = ["DATASETS", "STREAMS", "FuzzResult", "Perturbations", "fuzz_env", "fuzz_report"]


STREAMS = ("uniform", "bang_bang", "sticky", "chatter", "nan_inf")
#: The path set each robot's fuzz env tracks (the committed test splits).
DATASETS = {"iiwa7": "datasets/iiwa7/random", "armar6": "datasets/armar6/random",
            "armar4": "datasets/armar4/random", "armar4_legs": "datasets/armar4/target_point"}


@dataclass
class FuzzResult:
    """Outcome of a limit fuzz: steps and setpoints checked, violations per kind (and ``total``), restarts, brakes,
    non-finite actions fed and wall time (s)."""

    robot: str
    decision_steps: int  # env steps taken (envs x steps)
    setpoints_checked: int  # (setpoint, joint) pairs checked
    violations: dict[str, int] = field(default_factory=dict)  # per kind and "total"
    restarts_at_limits: int = 0
    restarts_on_path: int = 0
    brakes: int = 0
    nonfinite_actions: int = 0  # NaN / inf action entries fed to the env
    seconds: float = 0.0


@dataclass(frozen=True)
class Perturbations:
    """Per env and step, the probabilities of a restart at rest on the position limits, of a restart on a fresh
    path segment and of a switch to the braking law (module docstring)."""

    limit_restart_p: float = 0.005
    path_restart_p: float = 0.005
    brake_p: float = 0.001


def fuzz_env(robot_name: str, steps: int, num_envs: int = 4096, seed: int = 0, root: Path | str = ".",
             perturb: Perturbations = Perturbations(), rtol: float = 1e-6) -> FuzzResult:
    """Run `steps` decision steps of `num_envs` fuzzed envs of `robot_name` on its dataset under `root`, perturbed
    as `perturb` says; a setpoint beyond a limit by more than `rtol` (relative) is a violation (see the module
    docstring)."""
    if steps < 1 or num_envs < 1:
        raise ValueError(f"steps and num_envs must be >= 1, got {steps} and {num_envs}")
    robot = load_robot_by_name(robot_name)
    paths = load_pathset(Path(root) / DATASETS[robot_name], "test", KnotStrategy.from_cfg({"strategy": "curvature"}),
                         robot=robot)
    cfg = TrackingEnvCfg(num_envs=num_envs, seed=seed, max_deviation=None, episode_budget_s=1e9, autoreset=False,
                         free_joint_actions="posture" if robot.dof > paths.dof else "linear")
    env = PathTrackingEnv(cfg, robot, paths, build_reward_terms({"path_length": {"weight": 1.0}}))
    g = torch.Generator().manual_seed(seed + 1)
    n, d = num_envs, robot.dof
    mode = (torch.arange(n) % len(STREAMS)).unsqueeze(1)
    held = torch.ones(n, d, dtype=torch.float64)
    hold_left = torch.zeros(n, 1, dtype=torch.long)
    lo, hi = env.limits.pos[:, 0], env.limits.pos[:, 1]
    dt_c = cfg.dt / env.control_steps
    out = FuzzResult(robot_name, steps * n, 0, {k: 0 for k in (*KINDS, "total")})
    t0 = time.perf_counter()
    for k in range(steps):
        r = 2.0 * torch.rand(n, d, generator=g, dtype=torch.float64) - 1.0
        renew = hold_left <= 0
        held = torch.where(renew, torch.sign(r), held)
        hold_left = torch.where(renew, torch.randint(1, 40, (n, 1), generator=g), hold_left - 1)
        chatter = torch.full((n, d), 1.0 if k % 2 else -1.0, dtype=torch.float64)
        noisy = r.clone()
        u = torch.rand(n, d, generator=g)
        noisy[u < 0.05] = float("nan")
        noisy[(u >= 0.05) & (u < 0.075)] = float("inf")
        noisy[(u >= 0.075) & (u < 0.1)] = float("-inf")
        actions = torch.where(mode == 0, r, torch.where(mode == 1, torch.sign(r), torch.where(
            mode == 2, held, torch.where(mode == 3, chatter, noisy))))
        out.nonfinite_actions += int((~torch.isfinite(actions)).sum())

        _restarts(env, g, lo, hi, perturb, out)
        p0, v0, a0 = env.pos.clone(), env.vel.clone(), env.acc.clone()
        env.step(actions)
        p, v, a = interpolate_step(p0, v0, a0, env.acc, cfg.dt, env.control_steps)
        p, v, a = (torch.cat([x0.unsqueeze(1), x], dim=1) for x0, x in ((p0, p), (v0, v), (a0, a)))
        counts = limit_violations(p, v, a, env.limits, dt_c, rtol=rtol)
        for key, c in counts.items():
            out.violations[key] += int(c.sum())
        out.setpoints_checked += n * env.control_steps * d
    out.seconds = time.perf_counter() - t0
    return out


def _restarts(env: PathTrackingEnv, g: torch.Generator, lo: Tensor, hi: Tensor, perturb: Perturbations,
              out: FuzzResult) -> None:
    """Random restarts on the position limits `lo`, `hi` (D,) (at rest), on fresh path segments, and switches to
    braking (probabilities `perturb`), counted in `out`."""
    limit_p, path_p, brake_p = perturb.limit_restart_p, perturb.path_restart_p, perturb.brake_p
    n, d = env.pos.shape
    u = torch.rand(n, generator=g)
    at_limit = (u < limit_p).nonzero().squeeze(1)
    on_path = ((u >= limit_p) & (u < limit_p + path_p)).nonzero().squeeze(1)
    brake = ((u >= limit_p + path_p) & (u < limit_p + path_p + brake_p)).nonzero().squeeze(1)
    if len(on_path):
        env._reset_envs(on_path, refresh=False)
        out.restarts_on_path += len(on_path)
    if len(at_limit):
        side = torch.rand(len(at_limit), d, generator=g) < 0.5
        env.pos[at_limit] = torch.where(side, lo, hi)
        env.vel[at_limit] = 0.0
        env.acc[at_limit] = 0.0
        env.braking[at_limit] = False
        out.restarts_at_limits += len(at_limit)
    if len(brake):
        env.braking[brake] = True
        out.brakes += len(brake)
    if len(at_limit) or len(on_path):
        env._update_window()


def fuzz_report(results: list[FuzzResult]) -> dict[str, dict]:
    """JSON-ready records keyed by robot (for ``bench/results.json``)."""
    return {r.robot: {**asdict(r), "decision_steps_per_s": r.decision_steps / max(r.seconds, 1e-9)} for r in results}
