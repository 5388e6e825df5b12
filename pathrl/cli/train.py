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

    resolved = OmegaConf.to_container(cfg, resolve=True)
    try:
        summary = train(resolved, Path(cfg.run_dir), resume=bool(cfg.resume))
    except (DatasetError, FileExistsError, ValueError) as exc:
        if HydraConfig.get().mode == RunMode.MULTIRUN:
            return {"error": str(exc)}  # recorded as failed (pathrl.cli.sweep_report); the other jobs still run
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    print(f"done: {summary['iterations']} iterations, {summary['env_steps']:,} env steps, "
          f"{summary['wall_time_s']:.0f} s -> {cfg.run_dir}")
    return float(summary["mean_reward"] or 0.0)


#: Flags after which Hydra does something other than one run (a sweep, help, printing the config).
_NOT_A_RUN = ("-m", "--multirun", "-h", "--help", "--hydra-help", "-c", "--cfg", "-i", "--info", "-p", "--package",
              "--shell-completion", "-sc", "--run", "-r", "--config-path", "-cp", "--config-name", "-cn",
              "--config-dir", "-cd")


def _precheck(argv: list[str]) -> None:
    """Compose a single run's config before Hydra does, so that a bad override or key is one line (exit 2), not
    Hydra's multi-line report. Sweeps are checked per job (a failed job is recorded, the others run)."""
    if any(a.split("=", 1)[0] in _NOT_A_RUN for a in argv):
        return
    from pathrl.cli.common import UserError, compose, to_container
    from pathrl.config.schema import TrainAppCfg
    from pathrl.envs.registry import check_task
    from pathrl.train.runner import check_run_cfg

    try:
        cfg = to_container(compose("train", argv, TrainAppCfg))
        check_run_cfg(cfg)
        check_task(cfg)  # the task's env and reward values (pathrl.envs.registry); the dataset is checked by the run
    except (UserError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


def main() -> None:
    """Single run: exit 0, or 2 with a one-line error. Multirun (``-m``): exit with the number of failed jobs,
    after the summary ``sweep: N/M jobs finished``."""
    try:
        _precheck(sys.argv[1:])
        _app()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    raise SystemExit(sweep_report.sweep_exit_code(code))


if __name__ == "__main__":
    main()
