"""``pathrl-eval``: evaluate a training run or a shipped model directory.

    pathrl-eval run_dir=models/tracking/iiwa7_random [dataset=NAME | dataset.path=DIR] [split=test]
                [episodes=N] [segments=paper|full] [seed=0] [out=DIR] [write_models=true|false]
                [record=true|false] [num_envs=1200]
                [task=ball_on_plate|standing] [backend=pybullet|analytic] [compile_limits=true|false]
                [open_loop=true|false] [checkpoint=model_K.pt] [dataset.out_of_limits=refuse|clip] [workers=N]
    pathrl-eval batch=FILE

The arguments are Hydra overrides of ``conf/eval_app.yaml`` (schema :class:`pathrl.schema.EvalAppCfg`).
``dataset=NAME`` is ``data/<the run's robot>/NAME`` (short for ``dataset.name=NAME``); neither ``dataset`` nor
``dataset.path``: the run's own dataset. ``task`` (group ``conf/task``; only its name is used) adds a feedback
task to a run trained without one (its sensor values stay unobserved); runs with a task are simulated with
``backend`` (default PyBullet). ``open_loop=true`` freezes the task's sensor at its first value of each episode.
``checkpoint`` evaluates that checkpoint of a training run instead of its latest. ``run_dir`` may also be a
model-based controller's directory (``models/tracking/iiwa7_ball_tray_controller``), or a run of another task family
(:mod:`pathrl.families`, found by :func:`~pathrl.families.family_of`): a TrueAdapt run or model is evaluated on
``episodes`` trajectories (default 1000) of its split with Table I's metrics (``backend``, ``open_loop``,
``checkpoint`` and ``workers``, its PyBullet worker processes, apply; no ``episodes.mcap``), an industrial policy
(``pathrl-industrial train``) by its learned IWA on the first ``episodes`` rows of Table II. ``metrics.json`` and
``episodes.mcap`` go to ``out``, by default the run directory; a shipped model's (``models/<family>/<name>``) go to
``runs/eval/<name>``: nothing is written inside ``models/`` unless ``write_models=true``. The output directory is
checked before the evaluation runs.

``batch=FILE`` runs many evaluations in one process: one per line of FILE, written as the arguments above (``#``
comments and blank lines skipped). Every line is checked first (a bad one stops the batch before any work, naming
its line); then they run in order, sharing the imports and the PyBullet ball scenes (:func:`pathrl.sim.vec.kept_pools`:
built once per size and seed, results as if built afresh). A line that fails is reported and the others still run;
the exit code is then 1.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pathrl.cli.common import UserError, compose, key_value_app, output_dir, run_cli, schema_keys
from pathrl.families.tracking import OFFSET_WARN_RAD
from pathrl.families.tracking import offset_line as _offset_line  # noqa: F401 (kept for its callers)

__all__ = ["OFFSET_WARN_RAD", "BatchFailed", "batch_lines", "main", "output_of"]

USAGE = "usage: " + " ".join(__doc__.split("\n\n")[1].split())


def _arguments(argv: Sequence[str]) -> list[str]:
    """`argv` with ``dataset=NAME`` as ``dataset.name=NAME`` (``dataset`` is a config group of the other CLIs); an
    unknown ``task`` is a UserError before Hydra (whose message would not list the tasks)."""
    out = []
    for a in argv:
        key, eq, value = a.partition("=")
        if eq and key == "task" and value not in (*_path_tasks(), "null"):
            raise UserError(f"task must be one of {', '.join(_path_tasks())}, got {value!r}")
        out.append(f"dataset.name={value}" if eq and key == "dataset" else a)
    return out


#: Keys whose value is taken as written (a path or a name), as before Hydra: ``out=/tmp/a,b`` is not a list.
_LITERAL = ("run_dir", "dataset.name", "dataset.path", "split", "out", "checkpoint")

#: Files an evaluation writes into its output directory.
_OUTPUTS = ("metrics.json", "episodes.mcap")


def _print_help() -> None:
    """The usage, the config group (``task``) and every key with its default (``conf/eval_app.yaml``)."""
    from omegaconf import OmegaConf

    from pathrl.schema import EvalAppCfg

    print(__doc__.strip())
    print("\n== Configuration groups ==\nCompose your configuration from those groups (group=option)\n")
    print(f"task: {', '.join(_path_tasks())}\n")
    print("== Config ==\nOverride anything in the config (foo.bar=value)\n")
    print(OmegaConf.to_yaml(compose("eval_app", [], EvalAppCfg)).rstrip())


def _path_tasks() -> list[str]:
    """The tasks an evaluation can add to a run (those without a TrueAdapt setting)."""
    from pathrl.envs.registry import TASKS

    return [name for name, t in TASKS.items() if not t.adapt]


def _config(argv: list[str]) -> dict[str, Any]:
    """The composed ``eval_app`` config of `argv`, checked (UserError: one line)."""
    from pathrl.schema import EvalAppCfg

    cfg = key_value_app("eval_app", EvalAppCfg, _arguments(argv), USAGE, _LITERAL, keys=schema_keys(EvalAppCfg))
    checks = [
        ("segments", cfg["segments"], ("paper", "full")),
        ("dataset.out_of_limits", cfg["dataset"]["out_of_limits"], ("refuse", "clip")),
        ("backend", cfg["backend"], ("pybullet", "analytic")),
    ]
    for key, value, allowed in checks:
        if value not in allowed:
            raise UserError(f"{key} must be {' or '.join(allowed)}, got {value!r}")
    if cfg["episodes"] is not None and cfg["episodes"] < 1:
        raise UserError(f"episodes must be >= 1, got {cfg['episodes']}")
    if cfg["num_envs"] < 1:
        raise UserError(f"num_envs must be >= 1, got {cfg['num_envs']}")
    if cfg["workers"] is not None and cfg["workers"] < 1:
        raise UserError(f"workers must be >= 1, got {cfg['workers']}")
    return {**cfg, "task": None if cfg["task"] is None else cfg["task"]["name"]}


def output_of(cfg: dict[str, Any]) -> Path:
    """Where the evaluation of `cfg` writes: ``out``, else the run directory, else (a shipped model in ``models/``)
    ``runs/eval/<name>`` (:func:`pathrl.eval.evaluate.output_dir_of`); checked before any work (UserError: inside
    ``models/`` without ``write_models=true``, a file, not writable)."""
    from pathrl.eval.evaluate import output_dir_of
    from pathrl.storage import inside_models

    out = output_dir_of(Path(cfg["run_dir"]), None if cfg["out"] is None else Path(cfg["out"]))
    if inside_models(out) and not cfg["write_models"]:
        raise UserError(f"out={out} is inside models/ (the shipped policies); give another out= or pass "
                        "write_models=true to write the evaluation there")
    return output_dir(out, "out", _OUTPUTS)


def _path_files_as_dataset(run_dir: Path, dataset_path: str | None) -> str | None:
    """`dataset_path`, or where it is a path file or a directory of them (CSV / NumPy waypoints, radians), the
    dataset they were imported into for the run's robot (:func:`pathrl.dataset.waypoints.as_dataset`)."""
    from pathrl.dataset.io import META_FILE
    from pathrl.dataset.waypoints import as_dataset
    from pathrl.robot.model import RobotConfigError, load_robot
    from pathrl.runs import load_run

    if dataset_path is None or (Path(dataset_path) / META_FILE).is_file() or not Path(dataset_path).exists():
        return dataset_path
    run_cfg, _, _ = load_run(run_dir)
    try:
        robot = load_robot(run_cfg["robot"])
    except (RobotConfigError, KeyError, ValueError) as exc:
        raise UserError(f"{run_dir}: robot: {exc}") from None
    return str(as_dataset(dataset_path, robot))


def _prepare(argv: list[str]) -> tuple[dict[str, Any], Path]:
    """The checked config of `argv` and its output directory (UserError: one line)."""
    cfg = _config(argv)
    return cfg, output_of(cfg)


def _evaluate(cfg: dict[str, Any], out: Path) -> None:
    """Evaluate the run of a checked config (:func:`_prepare`) into `out` and print its report."""
    from pathrl.dataset.io import DatasetError
    from pathrl.eval.evaluate import EvalOptions
    from pathrl.families import family_of
    from pathrl.runs import RunError, load_run

    run_dir = Path(cfg["run_dir"])
    dataset_path = cfg["dataset"]["path"]
    if cfg["dataset"]["name"] is not None:
        try:
            run_cfg, _, _ = load_run(run_dir)
        except RunError as exc:
            raise UserError(str(exc)) from None
        dataset_path = str(Path("data") / run_cfg["robot"]["name"] / cfg["dataset"]["name"])
    try:
        dataset_path = _path_files_as_dataset(run_dir, dataset_path)
        opts = EvalOptions(dataset_path, cfg["split"], cfg["episodes"], cfg["segments"], cfg["seed"], out,
                           write_models=cfg["write_models"], num_envs=cfg["num_envs"], record=cfg["record"],
                           task=cfg["task"], backend=cfg["backend"], compile_limits=cfg["compile_limits"],
                           open_loop=cfg["open_loop"], checkpoint=cfg["checkpoint"],
                           out_of_limits=cfg["dataset"]["out_of_limits"], workers=cfg["workers"])
        family = family_of(run_dir)
        m = family.step("evaluate")(run_dir, opts)
    except (RunError, DatasetError) as exc:
        raise UserError(str(exc)) from None
    family.step("report")(m, out, opts)


def batch_lines(text: str) -> list[tuple[int, list[str]]]:
    """The evaluations of a batch file's `text`: (line number, its arguments) of every line that is not blank or a
    ``#`` comment; UserError (one line) on a line shlex cannot split or one that is itself a batch."""
    import shlex

    out = []
    for no, line in enumerate(text.splitlines(), 1):
        try:
            words = shlex.split(line, comments=True)
        except ValueError as exc:
            raise UserError(f"batch line {no}: {exc}") from None
        if any(w.startswith("batch=") for w in words):
            raise UserError(f"batch line {no}: a batch cannot name another batch")
        if words:
            out.append((no, words))
    return out


class BatchFailed(Exception):
    """Some evaluations of a batch failed (the others ran): exit code 1."""


def _batch(path: str) -> None:
    """Check every evaluation of batch file `path`, then run them in one process sharing the PyBullet ball scenes;
    a failed evaluation is reported on stderr and the others run (then exit code 1)."""
    import sys

    from pathrl.sim.vec import kept_pools

    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise UserError(f"batch={path}: {exc.strerror or exc}") from None
    jobs = []
    for no, words in batch_lines(text):
        try:
            jobs.append((no, *_prepare(words)))
        except UserError as exc:
            raise UserError(f"batch line {no}: {exc}") from None
    outs = [out.resolve() for _, _, out in jobs]
    if len(set(outs)) < len(outs):
        raise UserError(f"batch={path}: two lines write the same output directory")
    failed = []
    with kept_pools():
        for no, cfg, out in jobs:
            print(f"== batch line {no}: {cfg['run_dir']} -> {out}", flush=True)
            try:
                _evaluate(cfg, out)
            except Exception as exc:  # noqa: BLE001 - one line per failed evaluation; the others still run
                what = "" if isinstance(exc, UserError) else f"{type(exc).__name__}: "
                print(f"error: batch line {no}: {what}{exc}", file=sys.stderr, flush=True)
                failed.append(no)
    if failed:
        raise BatchFailed(f"{len(failed)} of {len(jobs)} evaluations failed (lines {', '.join(map(str, failed))})")


def _main(argv: list[str]) -> None:
    if any(a in ("-h", "--help") for a in argv):
        _print_help()
        return
    if any(a.startswith("batch=") for a in argv):
        if len(argv) != 1:
            raise UserError(f"batch=FILE takes no other arguments (they go on its lines); {USAGE}")
        _batch(argv[0].partition("=")[2])
        return
    _evaluate(*_prepare(argv))


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``pathrl-eval key=value ...`` (argv: sys.argv[1:]); returns the exit code."""
    import sys

    try:
        return run_cli(_main, argv)
    except BatchFailed as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    raise SystemExit(main())
