"""``pathrl-train``: compose robot, dataset, knots, reward, env and PPO settings with Hydra and train.

    pathrl-train robot=iiwa7 dataset=random knots=curvature_9 reward=balanced
    pathrl-train ... iterations=600 resume=true          # continue a killed run from its last checkpoint
    pathrl-train +experiment=armar4_random              # one table row (conf/experiment/)
    pathrl-train -m +sweep=table_II                      # a table's sweep (conf/sweep/, Hydra multirun)
    pathrl-train -m reward=length_lt_deviation,balanced  # any ad-hoc sweep
"""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from pathrl.cli.common import CONF_DIR
from pathrl.config.store import register

register()


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="train")
def _app(cfg: DictConfig) -> float:
    from pathrl.dataset.io import DatasetError
    from pathrl.train.runner import train

    resolved = OmegaConf.to_container(cfg, resolve=True)
    try:
        summary = train(resolved, Path(cfg.run_dir), resume=bool(cfg.resume))
    except (DatasetError, FileExistsError, ValueError) as exc:
        if HydraConfig.get().mode == RunMode.MULTIRUN:
            raise RuntimeError(str(exc)) from None  # Hydra records the failed job; the other jobs still run
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    print(f"done: {summary['iterations']} iterations, {summary['env_steps']:,} env steps, "
          f"{summary['wall_time_s']:.0f} s -> {cfg.run_dir}")
    return float(summary["mean_reward"] or 0.0)


def main() -> None:
    _app()


if __name__ == "__main__":
    main()
