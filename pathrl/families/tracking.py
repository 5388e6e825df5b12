"""The path-tracking family's lifecycle (:mod:`pathrl.families`): envs of the task registry
(:func:`pathrl.envs.registry.make_env`), :func:`pathrl.eval.evaluate.evaluate`, ``episodes.mcap`` / ``run.mcap``
(:mod:`pathrl.viz.episodes`, :mod:`pathrl.viz.runs`), :mod:`pathrl.eval.realtime`, :mod:`pathrl.eval.limit_fuzz`
and the short columns of the paper's Tables II-IV (:data:`pathrl.repro.tables.SHORT_COLUMNS`)."""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pathrl.families import ViewOptions

if TYPE_CHECKING:
    from pathrl.eval.evaluate import EvalOptions

__all__ = ["OFFSET_WARN_RAD", "TABLE_KEYS", "build", "detect", "evaluate", "offset_line", "print_table", "record",
           "report", "table_rows", "timing", "validate", "view_episodes", "view_run"]

#: Metrics ``pathrl-eval`` prints, in this order (those an evaluation has).
TABLE_KEYS = ("duration_s", "joint_dev_mean_rad", "joint_dev_max_rad", "joint_dev_final_rad",
              "cart_pos_dev_mean_cm", "cart_pos_dev_max_cm", "cart_pos_dev_final_cm",
              "cart_rot_dev_mean_deg", "cart_rot_dev_max_deg", "cart_rot_dev_final_deg",
              "duration_end_of_path_s", "terminated_early_pct", "task_failed_pct", "limit_violations")

#: A path joint whose mean signed error (commanded minus reference) exceeds this is listed under the table (rad).
OFFSET_WARN_RAD = 0.02


def detect(run_dir: Path) -> bool:
    """A directory without config.yaml holding an evaluation's or a training's recording."""
    return any((Path(run_dir) / n).is_file() for n in ("episodes.mcap", "run.mcap"))


def build(run_dir: Path, opts: EvalOptions):
    """The run's env for evaluation (:data:`pathrl.envs.registry.EVAL_ENV`) on `opts`' dataset (default: the run's,
    or its committed split), split and envs."""
    from pathrl.envs.registry import EVAL_ENV, EnvRequest, make_env
    from pathrl.runs import committed_split, load_run

    cfg, _, _ = load_run(run_dir)
    dataset = opts.dataset_path or committed_split(cfg["dataset"]["path"], opts.split)
    req = EnvRequest(split=opts.split, num_envs=opts.num_envs, seed=opts.seed, dataset_path=dataset,
                     backend=opts.backend)
    return make_env(cfg, req, **EVAL_ENV)


def evaluate(run_dir: Path, opts: EvalOptions) -> dict[str, Any]:
    """:func:`pathrl.eval.evaluate.evaluate` (``metrics.json``, with ``opts.record`` also ``episodes.mcap``)."""
    from pathrl.eval.evaluate import evaluate as run

    return run(run_dir, opts)


def record(run_dir: Path, out: Path, opts: EvalOptions) -> Path:
    """An evaluation into `out` that records its episodes: ``out/episodes.mcap``."""
    evaluate(run_dir, replace(opts, out_dir=Path(out), record=True))
    return Path(out) / "episodes.mcap"


def report(metrics: dict[str, Any], out: Path, opts: EvalOptions) -> None:
    """The metrics table and the files written (``pathrl-eval``'s output)."""
    print_table(metrics)
    print(f"wrote {out / 'metrics.json'}" + (f" and {out / 'episodes.mcap'}" if opts.record else ""))


def print_table(m: dict[str, Any]) -> None:
    """:data:`TABLE_KEYS` of an evaluation as a table, then the joint offsets (:func:`offset_line`)."""
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"{m['robot']} on {m['dataset']} ({m['split']}, {m['segments']}, {m['episodes']} episodes)")
    t.add_column("metric")
    t.add_column("value", justify="right")
    for k in TABLE_KEYS:
        if k not in m:
            continue
        v = m[k]
        t.add_row(k, f"{v:.3f}" if isinstance(v, float) else str(v))
    Console().print(t)
    if "per_joint" in m:
        print(offset_line(m["per_joint"]))


def offset_line(per_joint: dict[str, dict[str, float]]) -> str:
    """One line naming the joints held off the path by more than :data:`OFFSET_WARN_RAD` on average (or none)."""
    from pathrl.eval.metrics import offset_joints

    big = offset_joints(per_joint, OFFSET_WARN_RAD)
    listed = ", ".join(f"{n} {per_joint[n]['offset_rad']:+.3f} ({100 * per_joint[n]['share']:.0f} %)" for n in big)
    return f"joint offsets > {OFFSET_WARN_RAD} rad (mean signed error, share of squared deviation): {listed or 'none'}"


def timing(run_dir: Path, opts: EvalOptions) -> dict[str, Any]:
    """Compute per decision and per episode (:func:`pathrl.eval.realtime.realtime_ratios`) of the run's robot on
    `opts`' dataset (default: the run's), ``opts.episodes`` episodes (default 50), no simulator."""
    from pathrl.eval.realtime import realtime_ratios
    from pathrl.robot.model import load_robot
    from pathrl.runs import committed_split, load_run

    cfg, _, _ = load_run(run_dir)
    dataset = opts.dataset_path or committed_split(cfg["dataset"]["path"], "test")
    return realtime_ratios(load_robot(cfg["robot"]), dataset, opts.episodes or 50, simulate=False, seed=opts.seed,
                           compile_limits=opts.compile_limits)


def validate(run_dir: Path, opts: EvalOptions) -> dict[str, Any]:
    """The limit fuzz of the run's robot (:func:`pathrl.eval.limit_fuzz.fuzz_env`): ``opts.episodes`` decision steps
    (default 100) of ``opts.num_envs`` fuzzed envs on its committed dataset."""
    from pathrl.eval.limit_fuzz import fuzz_env
    from pathrl.runs import load_run

    cfg, _, _ = load_run(run_dir)
    return asdict(fuzz_env(cfg["robot"]["name"], opts.episodes or 100, opts.num_envs, opts.seed))


def table_rows(metrics: dict[str, Any]) -> list[str]:
    """A markdown table (header, rule, one row) of the short columns of Tables II-IV."""
    from pathrl.repro.tables import SHORT_COLUMNS

    cells = ["–" if metrics.get(c) is None else f"{float(metrics[c]):.2f}" for c in SHORT_COLUMNS]
    return [f"| {' | '.join(SHORT_COLUMNS)} |", "|" + "---|" * len(SHORT_COLUMNS), f"| {' | '.join(cells)} |"]


def view_episodes(src: Path, out: Path, opts: ViewOptions):
    """``episodes.mcap`` -> ``.rrd`` (:func:`pathrl.viz.episodes.episodes_to_rrd`, the selection of `opts`)."""
    from pathrl.viz.episodes import episodes_to_rrd

    return episodes_to_rrd(src, out, ids=opts.ids, worst=opts.worst, timeline=opts.timeline)


def view_run(src: Path, out: Path, opts: ViewOptions):
    """``run.mcap`` (training curves) -> ``.rrd`` (:func:`pathrl.viz.runs.run_to_rrd`)."""
    from pathrl.viz.runs import run_to_rrd

    return run_to_rrd(src, out)
