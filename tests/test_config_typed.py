"""The typed ``pathrl-train`` config (:class:`pathrl.schema.TrainAppCfg`) the CLI hands to the runner: converted
once from the composed config, it goes back to exactly the dict a run saves as ``config.yaml`` (key order, values),
for every shipped experiment."""

import pytest
import yaml
from omegaconf import OmegaConf

from pathrl.cli.common import compose, to_container
from pathrl.config.paths import CONF_DIR
from pathrl.schema import CriticWarmupCfg, LrDecayCfg, StdAnnealCfg, TrainAppCfg, config_dict, train_app_cfg
from pathrl.train.runner import check_run_cfg

EXPERIMENTS = [None] + sorted(p.stem for p in (CONF_DIR / "experiment").glob("*.yaml"))


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_the_typed_config_saves_as_the_composed_one(name):
    cfg = compose("train", [] if name is None else [f"+experiment={name}"], TrainAppCfg)
    typed = OmegaConf.to_object(cfg)
    saved = yaml.safe_dump(to_container(cfg), sort_keys=False)  # what config.yaml held before the typed config
    assert isinstance(typed, TrainAppCfg) and yaml.safe_dump(config_dict(typed), sort_keys=False) == saved
    assert train_app_cfg(to_container(cfg)) == typed  # a resolved mapping converts to the same object


def test_groups_are_typed_and_bad_values_are_one_line():
    typed = check_run_cfg(to_container(compose("train", ["+experiment=iiwa7_trueadapt_in_place_distill_decay"],
                                                       TrainAppCfg)))
    assert isinstance(typed.lr_decay, LrDecayCfg) and typed.lr_decay.final is not None
    assert isinstance(typed.critic_warmup, CriticWarmupCfg) and typed.std_anneal is None  # the recipe's: no cap
    assert typed.teacher["name"] == "trueadapt_tray"
    raw = to_container(compose("train", [], TrainAppCfg))
    assert isinstance(check_run_cfg(raw).std_anneal, StdAnnealCfg)
    with pytest.raises(ValueError, match=r"^[^\n]*iterations[^\n]*$"):
        check_run_cfg({**raw, "iterations": "many"})
    with pytest.raises(ValueError, match="unknown config key iteration; did you mean iterations"):
        check_run_cfg({**raw, "iteration": 3})


def test_every_shipped_policy_config_converts():
    """The migrated config of every shipped policy (controller directories have no training config) becomes the
    typed config, e.g. the early ``critic_warmup: 0`` of models/tracking/iiwa7_ball_balancing_distill."""
    from pathrl.config.migrate import migrate
    from pathrl.config.paths import CONF_DIR

    models = sorted((CONF_DIR.parent.parent / "models").glob("*/*/config.yaml"))
    policies = [cfg for cfg in (migrate(yaml.safe_load(p.read_text())) for p in models) if "controller" not in cfg]
    assert len(policies) > 50 and all(isinstance(train_app_cfg(cfg), TrainAppCfg) for cfg in policies)
