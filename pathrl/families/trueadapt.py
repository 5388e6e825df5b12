"""The TrueAdapt family's lifecycle (:mod:`pathrl.families`): :func:`pathrl.envs.trueadapt.build_trueadapt_env`,
the Table I metrics (:mod:`pathrl.eval.trueadapt`, limit violations of :mod:`pathrl.eval.trueadapt_limits`),
``trueadapt.mcap`` (:mod:`pathrl.eval.trueadapt_record`, :mod:`pathrl.viz.trueadapt`), the time per decision
(:mod:`pathrl.eval.trueadapt_realtime`), the limit validation of Sec. VI-D (:mod:`pathrl.eval.trueadapt_validation`)
and Table I's cells (:mod:`pathrl.repro.trueadapt`).

A run is a run or model directory (its checkpoint, or the ``controller:`` of its config.yaml); ``tools/trueadapt_*.py``
call the same functions (:func:`load`, :func:`evaluate_loaded`) for their other sources (``--task``, ``--controller``).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pathrl.families import ViewOptions

if TYPE_CHECKING:
    from pathrl.eval.evaluate import EvalOptions

__all__ = ["EPISODES", "Source", "build", "controller_spec", "detect", "evaluate", "evaluate_loaded", "load", "record",
           "report", "table_rows", "timing", "validate", "view_trueadapt"]

#: Trajectories evaluated when ``episodes`` is not given (Table I's).
EPISODES = 1000


@dataclass(frozen=True)
class Source:
    """What to load besides the config: the checkpoint (None: the run's latest), a controller spec (None: the
    config's ``controller:``, else the checkpoint's policy; ``{"name": "reference"}`` replays the reference), the
    ball simulation, PyBullet workers (None: the config's) and the dataset (None: the config's, falling back to the
    committed split)."""

    checkpoint: Path | None = None
    controller: dict[str, Any] | None = None
    backend: str = "analytic"
    workers: int | None = None
    dataset: str | None = None
    split: str = "test"
    seed: int = 0


def controller_spec(text: str) -> dict[str, Any]:
    """``reference`` -> {"name": "reference"}; a YAML mapping ``{name: ..., <keys>}`` as it is (ValueError else)."""
    import yaml

    spec = yaml.safe_load(text)
    spec = {"name": spec} if isinstance(spec, str) else spec
    if not isinstance(spec, dict):
        raise ValueError(f"--controller: expected a name or a YAML mapping, got {text!r}")
    return spec


def load(cfg: dict[str, Any], ckpt: Path | None, src: Source, num_envs: int, **overrides: Any):
    """(env, actor, dataset) of a resolved config: the env on `num_envs` envs without autoreset on the evaluation
    device, `overrides` replacing env settings; the actor (obs -> actions) is the controller of `src` or of the
    config, else the policy of `ckpt`, None for the reference without adaptation (no checkpoint). ValueError /
    OSError on bad input."""
    from pathrl.envs.device import EVAL_DEVICE
    from pathrl.envs.trueadapt import build_trueadapt_env
    from pathrl.runs import committed_split, load_policy, make_controller

    spec = src.controller if src.controller is not None else cfg.get("controller")
    cfg["task"]["backend"] = src.backend
    if src.workers is not None:
        cfg["task"]["workers"] = src.workers
    dataset = src.dataset or committed_split(cfg["dataset"]["path"], src.split)
    # the evaluation device, not the one the run was trained on (a GPU-trained run evaluates on a CPU-only machine)
    env = build_trueadapt_env(cfg, src.split, num_envs, dataset, src.seed, autoreset=False,
                              **{"device": EVAL_DEVICE, **overrides})
    try:
        if spec is not None:
            return env, make_controller(spec, env), dataset
        return env, (load_policy(cfg, env, src.checkpoint or ckpt) if (src.checkpoint or ckpt) else None), dataset
    except BaseException:
        env.close()
        raise


def _source(opts: EvalOptions) -> Source:
    return Source(Path(opts.checkpoint) if opts.checkpoint else None, None, opts.backend, opts.workers,
                  opts.dataset_path, opts.split, opts.seed)


def _load_run(run_dir: Path, opts: EvalOptions, num_envs: int, **overrides: Any):
    from pathrl.runs import load_run

    cfg, ckpt, _ = load_run(run_dir)
    if opts.checkpoint and not Path(opts.checkpoint).is_absolute():
        opts = replace(opts, checkpoint=str(Path(run_dir) / opts.checkpoint))
    return load(cfg, ckpt, _source(opts), num_envs, **overrides)


def detect(run_dir: Path) -> bool:
    """A directory without config.yaml holding a TrueAdapt recording."""
    return (Path(run_dir) / "trueadapt.mcap").is_file()


def build(run_dir: Path, opts: EvalOptions):
    """The run's TrueAdapt env for evaluation (no autoreset) on ``opts.num_envs`` envs."""
    env, _, _ = _load_run(run_dir, opts, opts.num_envs)
    return env


def evaluate_loaded(env, actor, episodes: int) -> dict[str, Any]:
    """Table I's metrics (:func:`pathrl.eval.trueadapt.summary`) of trajectories 0 .. episodes-1 (cycled) under
    `actor` (None: the reference), with the limit violations of the commanded setpoints and the wall time."""
    import torch

    from pathrl.eval.trueadapt import ObservingPolicy, evaluate, reference_policy, summary
    from pathrl.eval.trueadapt_limits import LimitCounter

    policy = reference_policy if actor is None else ObservingPolicy(actor)
    traj = torch.arange(episodes) % env.bank.num
    limits = LimitCounter(env)
    t0 = time.perf_counter()
    res = summary(evaluate(env, policy, traj, limits))
    return res | {"limit_violations": limits.counts["total"], "limit_violations_by_kind": limits.counts,
                  "setpoints_checked": limits.checked, "trajectories_in_split": env.bank.num,
                  "seconds": round(time.perf_counter() - t0, 1)}


def evaluate(run_dir: Path, opts: EvalOptions) -> dict[str, Any]:
    """Table I's metrics of the run on ``opts.episodes`` trajectories (default :data:`EPISODES`) of its split,
    ``opts.num_envs`` at a time, ``opts.backend`` ball, ``opts.open_loop``: the ball measurement frozen; written to
    ``opts.out_dir/metrics.json`` (default: the run directory; :func:`pathrl.eval.evaluate.output_dir_of`)."""
    from pathrl.eval.evaluate import output_dir_of
    from pathrl.storage import write_json_atomic

    episodes = opts.episodes or EPISODES
    env, actor, dataset = _load_run(run_dir, opts, min(opts.num_envs, episodes),
                                    **({"obs_ball": False} if opts.open_loop else {}))
    try:
        res = evaluate_loaded(env, actor, episodes)
    finally:
        env.close()
    res = {**res, "backend": opts.backend, "dataset": dataset, "split": opts.split, "run_dir": str(run_dir),
           "open_loop": opts.open_loop}
    out = output_dir_of(Path(run_dir), opts.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "metrics.json", res)
    return res


def report(metrics: dict[str, Any], out: Path, opts: EvalOptions) -> None:
    """The metrics as JSON and the file written (a TrueAdapt evaluation records no episodes: :func:`record`)."""
    import json

    print(json.dumps(metrics, indent=1))
    print(f"wrote {out / 'metrics.json'}")


def record(run_dir: Path, out: Path, opts: EvalOptions) -> Path:
    """``out/trueadapt.mcap`` of ``opts.episodes`` episodes (default 3) of the run
    (:func:`pathrl.eval.trueadapt_record.record_trueadapt`)."""
    from pathrl.eval.trueadapt_record import FILE_NAME, record_trueadapt

    episodes = opts.episodes or 3
    env, actor, _ = _load_run(run_dir, opts, episodes)
    try:
        if actor is None:
            from pathrl.runs import make_controller

            actor = make_controller({"name": "reference"}, env)
        record_trueadapt(env, actor, episodes, Path(out) / FILE_NAME)
    finally:
        env.close()
    return Path(out) / FILE_NAME


def timing(run_dir: Path, opts: EvalOptions) -> dict[str, Any]:
    """Time per adaptation decision (:func:`pathrl.eval.trueadapt_realtime.measure`) of the run's policy,
    ``opts.episodes`` decisions (default 1000)."""
    from pathrl.eval.trueadapt_realtime import measure

    return measure(Path(run_dir), opts.dataset_path, opts.episodes or 1000)


def validate(run_dir: Path, opts: EvalOptions) -> list[dict[str, Any]]:
    """Sec. VI-D's limit validation of the run's robot: ``opts.num_envs`` trajectories of ``opts.episodes`` decision
    steps (default 100) per mode (:func:`pathrl.eval.trueadapt_validation.validate`)."""
    from pathrl.eval.trueadapt_validation import MODES
    from pathrl.eval.trueadapt_validation import validate as run
    from pathrl.limits.feasible import JointLimits
    from pathrl.robot.model import load_robot
    from pathrl.runs import load_run

    cfg, _, _ = load_run(run_dir)
    limits = JointLimits.from_robot(load_robot(cfg["robot"]))
    return [asdict(run(limits, opts.num_envs, opts.episodes or 100, mode=m, seed=opts.seed)) for m in MODES]


def table_rows(metrics: dict[str, Any]) -> list[str]:
    """A markdown table (header, rule, one row) of Table I's columns (:func:`pathrl.repro.trueadapt.ours`)."""
    from pathrl.repro.trueadapt import COLUMNS, ours

    cells = ["–" if (v := ours(metrics, c)) is None else f"{v:.1f}" for c in COLUMNS]
    return [f"| {' | '.join(COLUMNS)} |", "|" + "---|" * len(COLUMNS), f"| {' | '.join(cells)} |"]


def view_trueadapt(src: Path, out: Path, opts: ViewOptions):
    """``trueadapt.mcap`` -> ``.rrd`` (:func:`pathrl.viz.trueadapt.trueadapt_to_rrd`)."""
    from pathrl.viz.trueadapt import trueadapt_to_rrd

    return trueadapt_to_rrd(src, out)
