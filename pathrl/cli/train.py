"""``pathrl-train``: compose robot, dataset, knots, reward, env and PPO settings with Hydra and train.

    pathrl-train robot=iiwa7 dataset=random knots=curvature_9 reward=balanced
    pathrl-train ... iterations=600 resume=true          # continue a killed run from its last checkpoint
    pathrl-train +experiment=armar4_random              # one table row (conf/experiment/)
    pathrl-train -m +sweep=table_II                      # a table's sweep (sweeps/table_II.yaml, Hydra multirun)
    pathrl-train -m reward=length_lt_deviation,balanced  # any ad-hoc sweep
"""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from pathrl.cli import sweep_report
from pathrl.cli.store import register
from pathrl.config.paths import CONF_DIR

__all__ = ["main"]

register()


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="train")
def _app(cfg: DictConfig) -> float | dict[str, str]:
    from pathrl.dataset.io import DatasetError
    from pathrl.train.runner import train

    typed = OmegaConf.to_object(cfg)  # the schema's TrainAppCfg, read by attribute from here on (pathrl.schema)
    try:
        summary = train(typed, Path(typed.run_dir), resume=typed.resume)
    except (DatasetError, FileExistsError, ValueError) as exc:
        if HydraConfig.get().mode == RunMode.MULTIRUN:
            return {"error": str(exc)}  # recorded as failed (pathrl.cli.sweep_report); the other jobs still run
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    print(f"done: {summary['iterations']} iterations, {summary['env_steps']:,} env steps, "
          f"{summary['wall_time_s']:.0f} s -> {typed.run_dir}")
    return float(summary["mean_reward"] or 0.0)


#: Flags after which Hydra does something other than one run (a sweep, help, printing the config).
_NOT_A_RUN = ("-m", "--multirun", "-h", "--help", "--hydra-help", "-c", "--cfg", "-i", "--info", "-p", "--package",
              "--shell-completion", "-sc", "--run", "-r", "--config-path", "-cp", "--config-name", "-cn",
              "--config-dir", "-cd")


def _precheck(argv: list[str]) -> dict | None:
    """Compose a single run's config before Hydra does, so that a bad override or key is one line (exit 2), not
    Hydra's multi-line report; the run directory is checked too. Returns the config (None for a sweep, help, ...:
    sweeps are checked per job, a failed job is recorded and the others run)."""
    if any(a.split("=", 1)[0] in _NOT_A_RUN for a in argv):
        return None
    from pathrl.cli.common import UserError, compose, output_dir, to_container
    from pathrl.envs.registry import check_task
    from pathrl.schema import TrainAppCfg
    from pathrl.train.runner import check_run_cfg

    try:
        cfg = to_container(compose("train", argv, TrainAppCfg))
        check_run_cfg(cfg)
        check_task(cfg)  # the task's env and reward values (pathrl.envs.registry); the dataset is checked by the run
        output_dir(cfg["run_dir"], "run_dir")
    except (UserError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    return cfg


def _first_missing(path: Path) -> Path | None:
    """The outermost directory of `path` (itself or an ancestor) that does not exist yet; None if `path` exists."""
    missing = None
    for p in (path, *path.parents):
        if p.exists():
            break
        missing = p
    return missing


def _remove_created(run_dir: Path, created: Path) -> None:
    """Remove the empty directories from `run_dir` up to `created` (what Hydra made for a start that failed)."""
    for p in (run_dir, *run_dir.parents):
        try:
            p.rmdir()
        except OSError:  # not empty (something else lives there) or gone
            return
        if p == created:
            return


def main() -> None:
    """Single run: exit 0, or 2 with a one-line error; a failed start leaves no directory behind. Multirun (``-m``):
    exit with the number of failed jobs, after the summary ``sweep: N/M jobs finished``."""
    from pathrl.cli.common import hydra_safe

    sys.argv[1:] = hydra_safe(sys.argv[1:])  # non-ASCII paths: quoted for Hydra's grammar
    created = None
    try:
        cfg = _precheck(sys.argv[1:])
        run_dir = Path(cfg["run_dir"]).absolute() if cfg is not None else None
        created = _first_missing(run_dir) if run_dir is not None else None
        _app()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    if code != 0 and created is not None:
        _remove_created(run_dir, created)
    raise SystemExit(sweep_report.sweep_exit_code(code))


if __name__ == "__main__":
    main()
