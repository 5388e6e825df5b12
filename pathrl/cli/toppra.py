"""``pathrl-toppra``: the TOPP-RA baseline on a dataset split, with the evaluation's episode protocol.

    pathrl-toppra robot=iiwa7 [dataset=NAME | dataset.path=DIR] [split=test] [segments=full|paper]
                  [episodes=N] [seed=S] [workers=2] [knots=curvature_9] [out=FILE]

``segments=full``: whole paths, one episode per path unless ``episodes`` is given (cycling over the
paths). ``segments=paper``: the paper's random segments, 1200 episodes by default, drawn with ``seed``
(the same plan :func:`pathrl.paths.segments.evaluation_plan` gives the policy evaluation). Writes a
JSON summary (default ``<dataset.path>/toppra_<split>_<segments>.json``; checked before the solver runs) and prints a
short table.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pathrl.cli.common import UserError, compose, output_file, run_cli, to_container
from pathrl.config.paper import load as load_paper
from pathrl.storage import write_json_atomic

__all__ = ["PAPER_EPISODES", "main", "main_", "print_summary", "summarize"]

#: Default number of episodes of ``segments=paper`` (cycling over the paths): the paper's evaluation protocol.
PAPER_EPISODES = int(load_paper("tracking").value("episodes"))


def _num(x: float) -> float | None:
    """JSON-safe float (NaN / inf -> null)."""
    x = float(x)
    return x if math.isfinite(x) else None


def _mean(xs: Sequence[float]) -> float:
    xs = [float(x) for x in xs if math.isfinite(float(x))]
    return sum(xs) / len(xs) if xs else math.nan


def summarize(results, plan, paths, meta: dict[str, Any]) -> dict[str, Any]:
    """The JSON report of a solved plan (see module doc)."""
    import numpy as np

    from pathrl.baselines.toppra import VIOLATION_KEYS

    solved = [r for r in results if r.status.solved]
    by_kind = {k: int(sum(r.violations.get(k, 0) for r in results)) for k in VIOLATION_KEYS}
    jerk_max = [r.max_jerk for r in solved]
    jerk_ratio = [r.max_jerk_ratio for r in solved]
    idx = plan.path.cpu().numpy()
    s0 = plan.start_s.detach().cpu().double().numpy()
    s1 = plan.end_s.detach().cpu().double().numpy()
    per_path = []
    for i, r in enumerate(results):
        per_path.append(
            {
                "name": paths.names[int(idx[i])],
                "episode": i,
                "start_s": float(s0[i]),
                "end_s": float(s1[i]),
                "duration_s": _num(r.duration_s),
                "max_joint_dev_rad": _num(r.max_joint_dev_rad),
                "solve_time_s": float(r.solve_time_s),
                "violations": r.num_violations,
                "status": r.status.value,
                "vel_scale": r.vel_scale,
                "acc_scale": r.acc_scale,
                "max_vel_ratio": _num(r.max_vel_ratio),
                "max_acc_ratio": _num(r.max_acc_ratio),
                "max_jerk": _num(r.max_jerk),
                "iterations": r.iterations,
                "num_gridpoints": r.num_gridpoints,
                **({"ruckig": r.tracked} if r.tracked is not None else {}),
            }
        )
    tracked = [r.tracked for r in solved if r.tracked is not None]
    ruckig = {} if not tracked else {"ruckig": {
        "note": "the TOPP-RA plan tracked by Ruckig every control cycle under the velocity, acceleration and "
                "jerk limits (pathrl.baselines.ruckig_track)",
        "duration_s": _num(_mean([t["duration_s"] for t in tracked])),
        "max_dev_rad": _num(_mean([t["max_dev_rad"] for t in tracked])),
        "mean_dev_rad": _num(_mean([t["mean_dev_rad"] for t in tracked])),
        "limit_violations_by_kind": {k: int(sum(t["violations"].get(k, 0) for t in tracked))
                                     for k in (*VIOLATION_KEYS, "jerk")},
        "episodes_with_violations": int(sum(sum(t["violations"].values()) > 0 for t in tracked)),
    }}
    return {
        **meta,
        "episodes": len(results),
        "solved": len(solved),
        "failed": len(results) - len(solved),
        "toppra_duration_s": _num(_mean([r.duration_s for r in solved])),
        "toppra_max_joint_dev_rad": _num(_mean([r.max_joint_dev_rad for r in solved])),
        "toppra_max_joint_dev_rad_max": _num(max([r.max_joint_dev_rad for r in solved], default=math.nan)),
        "solve_time_s": _num(_mean([r.solve_time_s for r in results])),
        "solve_time_total_s": float(sum(r.solve_time_s for r in results)),
        "segment_length_rad": _num(float(np.mean(s1 - s0))) if len(results) else None,
        "limit_violations": int(sum(by_kind.values())),
        "limit_violations_by_kind": by_kind,
        "episodes_with_violations": int(sum(r.num_violations > 0 for r in results)),
        "max_vel_ratio": _num(max([r.max_vel_ratio for r in solved], default=math.nan)),
        "max_acc_ratio": _num(max([r.max_acc_ratio for r in solved], default=math.nan)),
        "max_jerk": {
            "note": "TOPP-RA has no jerk limits; jerk is reported, not counted as a violation",
            "max": _num(max(jerk_max, default=math.nan)),
            "mean_of_episode_max": _num(_mean(jerk_max)),
            "max_ratio_to_limit": _num(max(jerk_ratio, default=math.nan)),
            "mean_ratio_to_limit": _num(_mean(jerk_ratio)),
            "episodes_over_jerk_limit": int(sum(r.jerk_violations > 0 for r in solved)),
        },
        **ruckig,
        "per_path": per_path,
    }


def print_summary(report: dict[str, Any], out: Path) -> None:
    """Print a baseline report as a table (episodes, durations, deviations, limit ratios, solve time; the Ruckig
    tracking if run), then where it was written (`out`)."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    def f(x: Any, fmt: str) -> str:
        return "n/a" if x is None else format(x, fmt)

    table = Table(
        title=f"TOPP-RA  {report['robot']} / {report['dataset']} / {report['split']} / {report['segments']}",
        show_header=True,
    )
    table.add_column("metric")
    table.add_column("value", justify="right")

    def row(name: str, value: str) -> None:
        table.add_row(escape(name), escape(value))

    row("episodes (solved)", f"{report['episodes']} ({report['solved']})")
    row("mean duration [s]", f(report["toppra_duration_s"], ".3f"))
    row("mean segment length [rad]", f(report["segment_length_rad"], ".2f"))
    row("mean max joint deviation [rad]", f(report["toppra_max_joint_dev_rad"], ".2e"))
    row("limit violations (pos+vel+acc)", str(report["limit_violations"]))
    row(
        "max |qd|/vel, |qdd|/acc", f"{f(report['max_vel_ratio'], '.4f')}, {f(report['max_acc_ratio'], '.4f')}"
    )
    row("max jerk / limit (not enforced)", f(report["max_jerk"]["max_ratio_to_limit"], ".1f"))
    solve = report["solve_time_s"]
    row("mean solve time [ms]", f(None if solve is None else solve * 1e3, ".1f"))
    if "ruckig" in report:
        rk = report["ruckig"]
        row("tracked by Ruckig: mean duration [s]", f(rk["duration_s"], ".3f"))
        row("tracked by Ruckig: mean max joint deviation [rad]", f(rk["max_dev_rad"], ".3f"))
        row("tracked by Ruckig: violations (pos, vel, acc, jerk)",
            ", ".join(str(v) for v in rk["limit_violations_by_kind"].values()))
    Console().print(table)
    print(f"wrote {out}")


def _checked_segments(cfg: Any, protocols: Sequence[str]) -> str:
    """The segment protocol of `cfg` after checking it, the episode and worker counts and the control rate
    (UserError: one line)."""
    segments = str(cfg.segments)
    if segments not in protocols:
        raise UserError(f"segments must be one of {list(protocols)}, got {segments!r}")
    if cfg.episodes is not None and int(cfg.episodes) < 1:
        raise UserError(f"episodes must be >= 1, got {cfg.episodes}")
    if int(cfg.workers) < 1:
        raise UserError(f"workers must be >= 1, got {cfg.workers}")
    if not float(cfg.control_rate) > 0:
        raise UserError(f"control_rate must be > 0, got {cfg.control_rate}")
    return segments


def main_(argv: list[str]) -> dict[str, Any]:
    """Run the baseline; returns the report (also written to ``out``); ``-h`` / ``--help`` prints the usage."""
    if any(a in ("-h", "--help") for a in argv):
        print(__doc__.strip())
        return {}
    from pathrl.schema import ToppraAppCfg

    cfg = compose("toppra_app", argv, ToppraAppCfg)
    from pathrl.dataset.io import DatasetError, load_dataset, load_pathset
    from pathrl.dataset.waypoints import as_dataset
    from pathrl.paths.knots import KnotStrategy
    from pathrl.paths.segments import PROTOCOLS, evaluation_plan
    from pathrl.robot.model import RobotConfigError, load_robot

    segments = _checked_segments(cfg, PROTOCOLS)
    try:
        robot = load_robot(to_container(cfg.robot))
        knots = KnotStrategy.from_cfg(to_container(cfg.knots))
    except (RobotConfigError, ValueError) as exc:
        raise UserError(str(exc)) from None
    try:  # a path file (or a directory of them) is imported into a dataset first
        data_dir = as_dataset(Path(str(cfg.dataset.path)), robot)
    except DatasetError as exc:
        raise UserError(str(exc)) from None
    out = output_file(str(cfg.out) if cfg.out else data_dir / f"toppra_{cfg.split}_{segments}.json", "out")
    try:
        dataset = load_dataset(data_dir, robot)
        paths = load_pathset(dataset, str(cfg.split), knots, robot, out_of_limits=str(cfg.dataset.out_of_limits))
    except DatasetError as exc:
        raise UserError(str(exc)) from None
    if cfg.episodes is not None:
        episodes = int(cfg.episodes)
    else:
        episodes = paths.num_paths if segments == "full" else PAPER_EPISODES
    plan = evaluation_plan(paths, episodes, segments, int(cfg.seed))

    from pathrl.baselines.toppra import GRID_STEP, MARGIN, ToppraSettings, solve_plan

    settings = ToppraSettings(control_rate=float(cfg.control_rate), keep_trajectory=False)
    results = solve_plan(paths, plan, robot, settings, workers=int(cfg.workers), progress=True,
                         track=bool(cfg.ruckig))
    meta = {
        "robot": robot.name,
        "dataset": data_dir.name,
        "dataset_kind": dataset.meta.get("kind"),
        "dataset_path": str(data_dir),
        "content_hash": dataset.meta.get("content_hash"),
        "split": str(cfg.split),
        "segments": segments,
        "seed": int(cfg.seed),
        "knots": str(cfg.knots.name),
        "control_rate": float(cfg.control_rate),
        "method": {
            "library": "toppra 0.6.10 (seidel)",
            "output": "constant path acceleration between gridpoints (ParametrizeConstAccel law)",
            "gridpoints": f"spline knots + uniform arc-length grid of {GRID_STEP} rad, refined at "
            "overshooting control-rate samples",
            "limit_margin": MARGIN,
            "boundary": "rest to rest",
        },
    }
    report = summarize(results, plan, paths, meta)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out, report, allow_nan=False)
    print_summary(report, out)
    return report


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``pathrl-toppra key=value ...`` (argv: sys.argv[1:]); returns the exit code."""
    return run_cli(main_, argv)


if __name__ == "__main__":
    raise SystemExit(main())
