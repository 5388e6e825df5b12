"""Where the optimisation time t_opt goes, per IWA iteration: the execution (our controller simulator), the
measurement (errors of the executed path), MPGD's decision (one :func:`pathrl.industrial.mpgd.mpgd_update`) and
the policy's decision (its local features: matching, IK of the waypoints, eqs. 7-13; and the network's forward
pass). Each is timed on the programs the optimisation actually visits, on every evaluation row.

From these, a **cost model** t_opt = executions x (execution + measurement) + decisions x decision (+ executions x
features for the policy) gives the MPGD / policy t_opt ratio for any execution cost: with our simulator's
measured one, and with the paper's (about 12 s per RobotStudio execution, its Sec. III-B), keeping our measured
decision times or taking the paper's (60.86 s for MPGD, 0.004 s for the policy, its Sec. IV-C). The model ratios
are computed, not measured.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from pathrl.config.paper import load as load_paper
from pathrl.industrial import arm
from pathrl.industrial.controller import ControllerParams, Execution, execute
from pathrl.industrial.features import features, match
from pathrl.industrial.iwa_env import IWAEpisode, IWASettings
from pathrl.industrial.metrics import POS_SPEC_MM, evaluate
from pathrl.industrial.mpgd import MPGDParams, mpgd_update, run_mpgd
from pathrl.industrial.program import DEFAULT_SEED, Program
from pathrl.industrial.tables import PAPER_RL, PAPER_TABLE2
from pathrl.industrial.trajectories import Target, baseline_program, waypoint_indices

__all__ = [
    "PAPER_EXECUTION_S", "PAPER_MPGD_DECISION_S", "PAPER_POLICY_DECISION_S", "RowTiming", "model_ratio",
    "paper_per_iteration", "time_row", "time_rows", "timing_markdown",
]

#: The paper's costs (s): one RobotStudio execution (Sec. III-B, "about 12 seconds"), MPGD's and the policy's
#: choice of actions per iteration (Sec. IV-C); ``pathrl/config/paper/industrial.yaml``.
PAPER_EXECUTION_S = float(load_paper("industrial").value("execution_s"))
PAPER_MPGD_DECISION_S = float(load_paper("industrial").value("mpgd_decision_s"))
PAPER_POLICY_DECISION_S = float(load_paper("industrial").value("policy_decision_s"))


@dataclass
class RowTiming:
    """One row: executions and decisions of each method (None itr = 0.5 mm not reached) and the summed measured
    times (s) of their parts."""

    name: str
    mpgd_itr: int | None
    mpgd_exec: int
    rl_itr: int | None
    rl_exec: int
    t_execute: list[float]
    t_measure: list[float]
    t_mpgd: list[float]
    t_features: list[float]
    t_act: list[float]


def _timed(fn: Callable[[], object]) -> tuple[object, float]:
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def _execute_and_measure(prog: Program, target: Target, v: float, ctrl: ControllerParams, seed: int,
                         row: RowTiming) -> Execution:
    ex, t = _timed(lambda: execute(prog, v, ctrl, seed=seed))
    row.t_execute.append(t)
    _, t = _timed(lambda: evaluate(ex.p, ex.rot, 1.0 / ctrl.rate, target.p, target.z_axis))
    row.t_measure.append(t)
    return ex  # type: ignore[return-value]


def time_row(target: Target, ctrl: ControllerParams, mpgd: MPGDParams, policy: Callable[[np.ndarray], np.ndarray],
             waypoints: int = 100, zone: float = 10.0, k_max: int = 10, seed: int = 0) -> RowTiming:
    """Run MPGD and the policy's IWA on `target` as Table II does, then time each part on the visited programs."""
    visited: list[Program] = []
    res = run_mpgd(target, baseline_program(target, waypoints, zone), target.speed, mpgd, ctrl, seed,
                   on_execution=lambda k, prog, ex: visited.append(prog))
    env = IWAEpisode(target, target.speed, ctrl, IWASettings(waypoints, zone, k_max))
    observations = [env.reset()]
    rl_programs = [env.program]
    rl_itr = 0 if env.errors.max_pos_mm <= POS_SPEC_MM else None
    while rl_itr is None and env.k < env.k_max:
        step = env.step(policy(observations[-1]))
        if step.errors is None:
            break
        observations.append(step.obs)
        rl_programs.append(env.program)
        rl_itr = env.k if step.errors.max_pos_mm <= POS_SPEC_MM else None
        if step.terminal:
            break
    row = RowTiming(target.name, res.iterations_to_spec, res.executions, rl_itr, len(rl_programs), [], [], [], [],
                    [])
    psi = waypoint_indices(len(target.p), waypoints)
    for k, prog in enumerate(visited):
        ex = _execute_and_measure(prog, target, target.speed, ctrl, seed + k, row)
        if k + 1 < len(visited):
            row.t_mpgd.append(_timed(lambda prog=prog, ex=ex: mpgd_update(prog, ex, target, psi, mpgd))[1])
    for k, prog in enumerate(rl_programs):
        ex = execute(prog, target.speed, ctrl)

        def observe(prog: Program = prog, ex: Execution = ex) -> np.ndarray:
            m = match(target.p, target.z_axis, ex.p, ex.rot[:, :, 2])
            return features(target.p, psi, m, arm.ik_path(prog.positions, prog.rotations, DEFAULT_SEED))

        row.t_features.append(_timed(observe)[1])
        if k + 1 < len(rl_programs):
            row.t_act.append(_timed(lambda k=k: policy(observations[k]))[1])
    return row


def time_rows(targets: Sequence[Target], ctrl: ControllerParams, mpgd: MPGDParams,
              policy: Callable[[np.ndarray], np.ndarray], waypoints: int = 100, zone: float = 10.0,
              k_max: int = 10, seed: int = 0) -> list[RowTiming]:
    """:func:`time_row` on every target."""
    return [time_row(t, ctrl, mpgd, policy, waypoints, zone, k_max, seed) for t in targets]


def model_ratio(rows: Sequence[RowTiming], t_exec: float, t_measure: float, t_mpgd: float, t_policy: float,
                baseline: bool = True) -> float:
    """Cost-model MPGD / policy t_opt summed over the rows both methods bring to 0.5 mm (nan if none). Both pay
    t_exec + t_measure (s) per execution; MPGD pays t_mpgd per update (executions - 1), the policy t_policy per
    execution (its features of every executed profile, plus the forward pass: all executions are counted, which
    slightly overcounts the forward passes). ``baseline=False`` leaves out the shared first execution of the
    baseline profile (then executions = iterations)."""
    both = [r for r in rows if r.mpgd_itr is not None and r.rl_itr is not None]
    if not both:
        return float("nan")
    skip = 0 if baseline else 1
    mpgd = sum((r.mpgd_exec - skip) * (t_exec + t_measure) + (r.mpgd_exec - 1) * t_mpgd for r in both)
    rl = sum((r.rl_exec - skip) * (t_exec + t_measure + t_policy) for r in both)
    return mpgd / rl


def paper_per_iteration() -> tuple[float, float]:
    """The paper's Table II t_opt per iteration (s), MPGD and RL, over the rows both reach (its own numbers)."""
    both = [n for n, p in PAPER_TABLE2.items() if p[4] is not None and PAPER_RL[n][1] is not None]
    mpgd = sum(PAPER_TABLE2[n][5] for n in both) / sum(PAPER_TABLE2[n][4] for n in both)
    rl = sum(PAPER_RL[n][2] for n in both) / sum(PAPER_RL[n][1] for n in both)
    return mpgd, rl


def timing_markdown(rows: Sequence[RowTiming], command: str) -> str:
    """Per-row measured times per iteration (ms, medians) and the cost-model ratios."""
    med = {k: float(np.median([x for r in rows for x in getattr(r, k)]))
           for k in ("t_execute", "t_measure", "t_mpgd", "t_features", "t_act")}
    lines = ["| Traj. | MPGD itr. / executions | policy itr. / executions | execution (ms) | measurement (ms) | "
             "MPGD decision (ms) | policy features (ms) | policy forward (ms) |", "|" + "---|" * 8]
    for r in rows:
        cells = [r.name, f"{r.mpgd_itr if r.mpgd_itr is not None else 'N/A'} / {r.mpgd_exec}",
                 f"{r.rl_itr if r.rl_itr is not None else 'N/A'} / {r.rl_exec}"]
        cells += [f"{1e3 * np.median(getattr(r, k)):.2f}" if getattr(r, k) else "-" for k in med]
        lines.append("| " + " | ".join(cells) + " |")
    medians = " | ".join(f"**{1e3 * v:.2f}**" for v in med.values())
    lines.append(f"| **median of all iterations** | | | {medians} |")
    policy_ours = med["t_features"] + med["t_act"]
    ours = (med["t_execute"], med["t_measure"], med["t_mpgd"], policy_ours)
    paper_exec = (PAPER_EXECUTION_S, med["t_measure"], med["t_mpgd"], policy_ours)
    paper_all = (PAPER_EXECUTION_S, 0.0, PAPER_MPGD_DECISION_S, PAPER_POLICY_DECISION_S)
    ratio = {(k, b): model_ratio(rows, *c, baseline=b) for k, c in (("ours", ours), ("exec", paper_exec),
                                                                      ("all", paper_all)) for b in (True, False)}
    p_mpgd, p_rl = paper_per_iteration()
    return "\n".join([
        "# Industrial motion-profile optimisation: where t_opt goes (per IWA iteration)", "",
        f"Measured with `{command}` (one core; wall times of each part on the programs the optimisation visits).", "",
        *lines, "",
        "Cost model (computed from the medians above and the executions counted here, on the rows both methods "
        "bring to 0.5 mm; **a model, not a measurement**): t_opt = executions x (execution + measurement) + "
        "decisions x decision time (MPGD: executions - 1 updates; policy: features of every execution + forward "
        "passes).", "",
        "| execution cost | decision times | MPGD / policy t_opt (model) | same, baseline execution not counted |",
        "|---|---|---|---|",
        f"| ours, measured ({1e3 * med['t_execute']:.1f} ms) | ours (MPGD {1e3 * med['t_mpgd']:.1f} ms, policy "
        f"{1e3 * policy_ours:.1f} ms) | {ratio['ours', True]:.1f}x | {ratio['ours', False]:.1f}x |",
        f"| paper's RobotStudio, {PAPER_EXECUTION_S:g} s | ours | {ratio['exec', True]:.1f}x | "
        f"{ratio['exec', False]:.1f}x |",
        f"| paper's RobotStudio, {PAPER_EXECUTION_S:g} s | paper's (MPGD {PAPER_MPGD_DECISION_S} s, policy "
        f"{PAPER_POLICY_DECISION_S} s) | {ratio['all', True]:.1f}x | {ratio['all', False]:.1f}x |", "",
        f"The paper's own Table II gives {p_mpgd:.1f} s per MPGD iteration and {p_rl:.1f} s per RL iteration (t_opt / "
        "Itr. summed over the rows both reach; its 17.7x).", ""])
