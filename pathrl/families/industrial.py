"""The industrial family's lifecycle (:mod:`pathrl.families`): a learned iterative waypoint adjustment (IWA) of the
simulated industrial controller (:mod:`pathrl.industrial`). A run is a policy directory of ``pathrl-industrial
train`` (``model.pt`` or ``model_<K>.pt``, no config.yaml); its env is one :class:`~pathrl.industrial.iwa_env.
IWAEpisode` per evaluation row (Table II's rows, :func:`pathrl.industrial.trajectories.evaluation_targets`), with the
default controller and IWA settings (``pathrl-industrial`` composes others from ``conf/industrial/app.yaml``).
Recording: :mod:`pathrl.industrial.record`, viewer :mod:`pathrl.viz.industrial`, timing
:mod:`pathrl.industrial.timing`; the family has no limit validation (its programs are Cartesian waypoints executed
by the controller, not joint setpoints of ours).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pathrl.families import ViewOptions

if TYPE_CHECKING:
    from pathrl.eval.evaluate import EvalOptions

__all__ = ["COLUMNS", "build", "detect", "evaluate", "policy_of", "record", "report", "table_rows", "targets",
           "timing", "validate", "view_industrial"]

#: Columns of :func:`table_rows` (the learned IWA's columns of Table II).
COLUMNS = ("row", "max error (mm)", "iterations to 0.5 mm", "t_opt (s)")


def detect(run_dir: Path) -> bool:
    """A directory without config.yaml holding ``industrial.mcap`` or an industrial policy (``model.pt`` /
    ``model_<K>.pt``)."""
    d = Path(run_dir)
    return d.is_dir() and not (d / "config.yaml").exists() and (
        (d / "industrial.mcap").is_file() or (d / "model.pt").is_file() or any(d.glob("model_*.pt")))


def policy_of(run_dir: Path) -> Callable[[np.ndarray], np.ndarray]:
    """The deterministic policy (features (m, 313) -> actions (m, 3)) of the run's shipped or newest checkpoint,
    scaled by its action clip as ``pathrl-industrial`` does."""
    from pathrl.industrial.rl_train import load_agent

    agent, _ = load_agent(Path(run_dir))
    clip = agent.params.action_clip
    return agent.act if clip == 1.0 else (lambda obs: clip * agent.act(obs))


def targets(opts: EvalOptions) -> list:
    """The first ``opts.episodes`` evaluation rows (all without)."""
    from pathrl.industrial.trajectories import evaluation_targets

    rows = evaluation_targets()
    return rows[: opts.episodes] if opts.episodes else rows


def build(run_dir: Path, opts: EvalOptions):
    """The IWA episode of the first evaluation row (default controller and IWA settings)."""
    from pathrl.industrial.controller import ControllerParams
    from pathrl.industrial.iwa_env import IWAEpisode, IWASettings

    t = targets(opts)[0]
    return IWAEpisode(t, t.speed, ControllerParams(), IWASettings())


def evaluate(run_dir: Path, opts: EvalOptions) -> dict[str, Any]:
    """The learned IWA on each of :func:`targets` (Table II's RL columns); written to ``opts.out_dir/metrics.json``
    (default: :func:`pathrl.eval.evaluate.output_dir_of`)."""
    from pathrl.eval.evaluate import output_dir_of
    from pathrl.industrial.controller import ControllerParams
    from pathrl.industrial.iwa_env import IWAEpisode, IWASettings
    from pathrl.industrial.rl import run_policy_iwa
    from pathrl.storage import write_json_atomic

    policy, rows = policy_of(run_dir), []
    for t in targets(opts):
        res = run_policy_iwa(IWAEpisode(t, t.speed, ControllerParams(), IWASettings()), policy)
        rows.append({"row": t.name, "speed": t.speed, "baseline_mm": res.history[0], "err_mm": res.errors.max_pos_mm,
                     "itr": res.iterations_to_spec, "t_opt": res.t_opt, "executions": res.executions})
    m = {"run_dir": str(run_dir), "episodes": len(rows), "rows": rows,
         "err_mm_mean": float(np.mean([r["err_mm"] for r in rows]))}
    out = output_dir_of(Path(run_dir), opts.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "metrics.json", m)
    return m


def report(metrics: dict[str, Any], out: Path, opts: EvalOptions) -> None:
    """The rows as a markdown table and the file written."""
    print("\n".join(table_rows(metrics)))
    print(f"wrote {out / 'metrics.json'}")


def record(run_dir: Path, out: Path, opts: EvalOptions) -> Path:
    """``out/industrial.mcap``: the learned IWA of the first of :func:`targets` with every execution
    (:func:`pathrl.industrial.record.record_optimisation`)."""
    from pathrl.industrial.controller import ControllerParams
    from pathrl.industrial.record import Optimiser, record_optimisation

    path, _, _ = record_optimisation(targets(opts)[0], Optimiser("rl", policy=policy_of(run_dir)), ControllerParams(),
                                     Path(out), seed=opts.seed, meta={"policy": str(run_dir), "method_name": "RL"})
    return path


def timing(run_dir: Path, opts: EvalOptions) -> dict[str, Any]:
    """Per-iteration execution, measurement, MPGD and policy decision times on :func:`targets`
    (:func:`pathrl.industrial.timing.time_rows`)."""
    from pathrl.industrial.controller import ControllerParams
    from pathrl.industrial.mpgd import MPGDParams
    from pathrl.industrial.timing import time_rows

    rows = time_rows(targets(opts), ControllerParams(), MPGDParams(), policy_of(run_dir), seed=opts.seed)
    return {"rows": [asdict(r) for r in rows]}


def validate(run_dir: Path, opts: EvalOptions) -> None:
    """None: the family has no limit validation (module doc)."""
    return None


def table_rows(metrics: dict[str, Any]) -> list[str]:
    """A markdown table of :data:`COLUMNS`, one row per evaluated row."""
    def cells(r: dict[str, Any]) -> list[str]:
        return [r["row"], f"{r['err_mm']:.3f}", "–" if r["itr"] is None else str(r["itr"]), f"{r['t_opt']:.2f}"]

    return [f"| {' | '.join(COLUMNS)} |", "|" + "---|" * len(COLUMNS),
            *(f"| {' | '.join(cells(r))} |" for r in metrics["rows"])]


def view_industrial(src: Path, out: Path, opts: ViewOptions):
    """``industrial.mcap`` -> ``.rrd`` (:func:`pathrl.viz.industrial.industrial_to_rrd`)."""
    from pathrl.viz.industrial import industrial_to_rrd

    return industrial_to_rrd(src, out)
