"""Register the schemas with Hydra's ConfigStore (imported by the CLI layer only)."""

from __future__ import annotations

from hydra.core.config_store import ConfigStore

from pathrl.config import schema


def register() -> None:
    cs = ConfigStore.instance()
    cs.store(name="dataset_app_schema", node=schema.DatasetAppCfg)
    cs.store(name="toppra_app_schema", node=schema.ToppraAppCfg)
    cs.store(name="train_app_schema", node=schema.TrainAppCfg)
    cs.store(group="robot", name="robot_schema", node=schema.RobotCfg)
    cs.store(group="dataset", name="dataset_schema", node=schema.DatasetCfg)
    cs.store(group="knots", name="knots_schema", node=schema.KnotsCfg)
