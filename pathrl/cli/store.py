"""Register the schemas with Hydra's ConfigStore (imported by the CLI layer only)."""

from __future__ import annotations

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

from pathrl.config import schema


def _train_app_node() -> DictConfig:
    """The ``pathrl-train`` schema as a config node. Its ``env`` group is the env's frozen settings class
    (:class:`pathrl.envs.tracking_cfg.EnvSettings`), which OmegaConf makes read-only; composition writes into it."""
    node = OmegaConf.structured(schema.TrainAppCfg)
    OmegaConf.set_readonly(node.env, None)
    return node


def register() -> None:
    cs = ConfigStore.instance()
    cs.store(name="dataset_app_schema", node=schema.DatasetAppCfg)
    cs.store(name="toppra_app_schema", node=schema.ToppraAppCfg)
    cs.store(name="train_app_schema", node=_train_app_node())
    cs.store(group="robot", name="robot_schema", node=schema.RobotCfg)
    cs.store(group="dataset", name="dataset_schema", node=schema.DatasetCfg)
    cs.store(group="knots", name="knots_schema", node=schema.KnotsCfg)
