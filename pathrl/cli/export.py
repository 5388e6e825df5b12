"""``pathrl-export``: a shipped policy's actor (with its observation normaliser) to TorchScript and ONNX.

    pathrl-export run_dir=models/tracking/iiwa7_random [out=DIR] [dataset.path=DIR] [observations=1000]

Writes ``actor.pt``, ``actor.onnx`` and ``export.json`` to ``out`` (default ``<run_dir>/export``; checked before the
export runs) and checks both
exports against the PyTorch actor on `observations` states the policy visits on the test split (paper
segments); ``dataset.path`` defaults to the run's dataset, else the committed ``datasets/<robot>/<dataset>``. The
policy's length scale comes from the run's ``summary.json`` (an error without it).
The arguments are Hydra overrides of ``conf/export_app.yaml`` (schema :class:`pathrl.schema.ExportAppCfg`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pathrl.cli.common import UserError, compose, key_value_app, output_dir, run_cli

__all__ = ["main"]

USAGE = "usage: pathrl-export run_dir=RUN [out=DIR] [dataset.path=DIR] [observations=N]"

#: Keys whose value is taken as written (a path), as before Hydra: ``out=/tmp/a,b`` is not a list.
_LITERAL = ("run_dir", "out", "dataset.path")

#: Files an export writes into its output directory.
_OUTPUTS = ("actor.pt", "actor.onnx", "export.json")


def _print_help() -> None:
    """The usage and every key with its default (``conf/export_app.yaml``)."""
    from omegaconf import OmegaConf

    from pathrl.schema import ExportAppCfg

    print(__doc__.strip())
    print("\n== Config ==\nOverride anything in the config (foo.bar=value)\n")
    print(OmegaConf.to_yaml(compose("export_app", [], ExportAppCfg)).rstrip())


def _config(argv: list[str]) -> dict[str, Any]:
    """The composed ``export_app`` config of `argv`, checked (UserError: one line)."""
    from pathrl.schema import ExportAppCfg

    cfg = key_value_app("export_app", ExportAppCfg, argv, USAGE, _LITERAL)
    if cfg["observations"] < 1:
        raise UserError(f"observations must be >= 1, got {cfg['observations']}")
    return cfg


def _main(argv: list[str]) -> None:
    from pathrl.dataset.io import DatasetError
    from pathrl.deploy.export import export_policy
    from pathrl.envs.registry import EnvRequest, get_task, tracking_paths
    from pathrl.robot.model import load_robot
    from pathrl.runs import RunError, load_run, policy_scale

    if any(a in ("-h", "--help") for a in argv):
        _print_help()
        return
    args = _config(argv)
    run_dir = Path(args["run_dir"])
    count = args["observations"]
    out = output_dir(args["out"] or run_dir / "export", "out", _OUTPUTS)
    try:
        cfg, ckpt, summary = load_run(run_dir)
        if ckpt is None:
            raise UserError(f"{run_dir}: a model-based controller has no network to export")
        gap = policy_scale(run_dir, summary)
    except RunError as exc:
        raise UserError(str(exc)) from None
    try:
        feedback = get_task(cfg).feedback
    except ValueError as exc:
        raise UserError(f"{run_dir}: {exc}") from None
    if feedback is not None:
        raise UserError(f"{run_dir}: exporting policies of feedback tasks ({feedback}) is not "
                        "supported (their state needs the task's sensor)")
    robot = load_robot(cfg["robot"])
    ds = args["dataset"]["path"] or cfg["dataset"]["path"]
    if args["dataset"]["path"] is None and not Path(ds).is_dir():
        ds = str(Path("datasets") / robot.name / cfg["dataset"]["name"])
    try:
        paths = tracking_paths(cfg, "test", ds, robot)  # the env's paths, by the rule the run was trained with
    except (DatasetError, OSError) as exc:
        raise UserError(str(exc).splitlines()[0] if str(exc) else repr(exc)) from None
    request = EnvRequest("test", num_envs=min(8, paths.num_paths), seed=0, knot_gap_norm=gap, paths=paths, robot=robot)
    try:
        report = export_policy(cfg, ckpt, request, out, count)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    worst = max(report["max_abs_diff_torchscript"], report["max_abs_diff_onnx"])
    print(f"{out}/actor.pt, actor.onnx: max |export - PyTorch| {worst:.1e} "
          f"on {report['observations']} recorded observations (float32; the trained {report['hidden_dtype']} "
          f"policy differs by {report['max_abs_diff_trained_dtype']:.1e})")


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``pathrl-export key=value ...`` (argv: sys.argv[1:]); returns the exit code."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    raise SystemExit(main())
