"""Register the schemas with Hydra's ConfigStore (imported by the CLI layer only)."""

from __future__ import annotations

import sys

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

from pathrl import schema

__all__ = ["SWEEP_SETTINGS", "register", "sweep_node"]

#: Every training sweep's settings besides its experiments: joblib, 2 jobs (conf/hydra/launcher/local.yaml) of one
#: torch thread each (n_jobs x threads = the 2 cores of the reference machine).
SWEEP_SETTINGS = {"defaults": [{"override /hydra/launcher": "local"}], "threads": 1}


def sweep_node(experiments: tuple[str, ...]) -> dict:
    """The ``sweep/<table>`` config of a Hydra multirun over `experiments` (``pathrl-train -m +sweep=<table>``)."""
    return {**SWEEP_SETTINGS, "hydra": {"sweeper": {"params": {"+experiment": ",".join(experiments)}}}}


def _train_app_node() -> DictConfig:
    """The ``pathrl-train`` schema as a config node. Its ``env`` group is the env's frozen settings class
    (:class:`pathrl.envs.tracking_cfg.EnvSettings`), which OmegaConf makes read-only; composition writes into it."""
    node = OmegaConf.structured(schema.TrainAppCfg)
    OmegaConf.set_readonly(node.env, None)
    return node


def _register_robot_files(cs: ConfigStore) -> None:
    """Every robot YAML on ``PATHRL_ROBOT_PATH`` as option ``robot=<its stem>`` (:mod:`pathrl.robot.external`); a
    broken one: its one-line error, exit 2."""
    from pathrl.robot.external import expand_robot_file, robot_files
    from pathrl.robot.model import RobotConfigError

    try:
        for name, path in robot_files().items():
            cs.store(group="robot", name=name, node=expand_robot_file(path))
    except RobotConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


def register() -> None:
    """The schemas, and a ``sweep/<table>`` config per sweeps/<table>.yaml that names experiments to train (a
    broken sweeps/ file: its one-line error, exit 1)."""
    from pathrl.repro.sweeps import SweepsError

    try:
        from pathrl.repro.tables import SWEEPS
    except SweepsError as exc:
        raise SystemExit(f"error: {exc}") from None
    cs = ConfigStore.instance()
    cs.store(name="dataset_app_schema", node=schema.DatasetAppCfg)
    cs.store(name="eval_app_schema", node=schema.EvalAppCfg)
    cs.store(name="export_app_schema", node=schema.ExportAppCfg)
    cs.store(name="toppra_app_schema", node=schema.ToppraAppCfg)
    cs.store(name="train_app_schema", node=_train_app_node())
    cs.store(group="robot", name="robot_schema", node=schema.RobotCfg)
    cs.store(group="dataset", name="dataset_schema", node=schema.DatasetCfg)
    cs.store(group="knots", name="knots_schema", node=schema.KnotsCfg)
    _register_robot_files(cs)
    for name, spec in SWEEPS.items():
        if spec.train:
            cs.store(group="sweep", name=name, node=sweep_node(spec.train), package="_global_")
