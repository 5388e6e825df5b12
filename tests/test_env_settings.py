"""One config source for the env settings (issue 23): ``EnvSettings`` is the ``env`` group's Hydra schema and its only
defaults, ``conf/env/*.yaml`` sets only what differs, saved runs read through ``pathrl.config.migrate``."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import pytest
import yaml

from pathrl.cli.common import UserError, compose, to_container
from pathrl.config.migrate import ADDED_IN_V2, ADDED_KEYS, CONFIG_VERSION, NO_TASK, config_version, migrate
from pathrl.envs.tracking_cfg import EnvSettings, TrackingEnvCfg
from pathrl.schema import TrainAppCfg

ROOT = Path(__file__).resolve().parents[1]
ENV_YAMLS = sorted((ROOT / "pathrl" / "conf" / "env").glob("*.yaml"))
SAVED = sorted((ROOT / "models").glob("*/*/config.yaml"))
DEFAULTS = {f.name: f.default for f in dataclasses.fields(EnvSettings)}


def _plain(value):
    """Tuples as lists (how YAML and OmegaConf hold them)."""
    return list(value) if isinstance(value, tuple) else value


@pytest.mark.parametrize("path", ENV_YAMLS, ids=lambda p: p.name)
def test_env_yaml_sets_only_what_differs_from_the_dataclass(path):
    values = yaml.safe_load(path.read_text()) or {}
    assert set(values) <= set(DEFAULTS), f"{path.name}: keys the schema lacks"
    same = [k for k, v in values.items() if EnvSettings.from_mapping({k: v}) == EnvSettings()]
    assert same == [], f"{path.name} repeats the dataclass default of {same}; remove them"


def test_composed_env_group_is_the_dataclass_defaults_with_the_yaml_on_top():
    cfg = to_container(compose("train", [], TrainAppCfg))
    tracking = yaml.safe_load((ROOT / "pathrl" / "conf" / "env" / "tracking.yaml").read_text())
    assert cfg["env"] == {k: _plain(v) for k, v in {**DEFAULTS, **tracking}.items()}
    assert cfg["config_version"] == CONFIG_VERSION
    assert EnvSettings.from_mapping(cfg["env"]) == dataclasses.replace(EnvSettings(), max_deviation=0.25,
                                                                       end_tolerance=0.05, end_obs=True)


def test_env_group_takes_overrides_and_refuses_unknown_keys():
    """The frozen settings class is the schema; composition still writes into it (pathrl.cli.store)."""
    cfg = to_container(compose("train", ["env.num_envs=7", "env.max_deviation=null", "env.start_range=[0.1,0.5]"],
                               TrainAppCfg))
    env = TrackingEnvCfg.from_run(cfg)
    assert (env.num_envs, env.max_deviation, env.start_range) == (7, None, (0.1, 0.5))
    with pytest.raises(UserError, match="end_obs"):
        compose("train", ["+env.end_ob=true"], TrainAppCfg)


def test_from_mapping_converts_types_and_refuses_bad_values():
    s = EnvSettings.from_mapping({"num_envs": 8.0, "dt": 1, "start_range": [0, 0.5], "max_deviation": None})
    assert (s.num_envs, s.dt, s.start_range, s.max_deviation) == (8, 1.0, (0.0, 0.5), None)
    assert type(s.num_envs) is int and type(s.dt) is float
    with pytest.raises(ValueError, match="unknown keys \\['dtt'\\]"):
        EnvSettings.from_mapping({"dtt": 0.1})
    with pytest.raises(ValueError, match="env.dt: expected float"):
        EnvSettings.from_mapping({"dt": "fast"})
    with pytest.raises(ValueError, match="env.end_obs: expected bool"):
        EnvSettings.from_mapping({"end_obs": "yes"})
    with pytest.raises(ValueError, match="env.dt: null"):
        EnvSettings.from_mapping({"dt": None})
    with pytest.raises(ValueError, match="env.segments must be one of"):
        EnvSettings.from_mapping({"segments": "half"})


def test_migrate_fills_a_version_0_config_with_the_old_behaviour():
    old = {"env": {"num_envs": 8, "tcp_obs_error": 0.2}, "knots": {"n_state": 5}, "seed": 3}
    new = migrate(old)
    assert old == {"env": {"num_envs": 8, "tcp_obs_error": 0.2}, "knots": {"n_state": 5}, "seed": 3}  # a copy
    assert new["config_version"] == CONFIG_VERSION == 4
    assert new["task"] == {**NO_TASK, "adapt": {}}
    assert new["env"] == {"num_envs": 8, "tcp_obs_error": 0.2, "knot_obs": "relative", "end_obs": False,
                          "end_tolerance": None, "free_joint_actions": "linear", "posture_omega": 3.0,
                          "tcp_obs": False, "tcp_obs_box": [-1.0, 1.0, -1.0, 1.0, -0.7, 1.3],
                          "error_obs": False, "error_obs_scale": 0.1}
    assert "dataset" not in new  # groups the config lacks are not invented
    assert (new["init_from"], new["teacher"], new["residual"]) == (None, {}, {})
    assert new["critic_warmup"] == {"iterations": 0, "learning_rate": None, "freeze_normalizer": False}  # v4 too
    assert new["lr_decay"] == {"final": None, "start": 0.0}  # version 3: a constant (or adaptive) learning rate
    assert migrate(new) == new
    env = TrackingEnvCfg.from_run(old, seed=None)
    assert (env.free_joint_actions, env.end_obs, env.tcp_obs_error, env.n_state, env.seed) == ("linear", False, 0.2,
                                                                                                5, 3)


def test_migrate_fills_a_version_3_config_with_a_normaliser_that_keeps_learning():
    v3 = {"config_version": 3, "critic_warmup": {"iterations": 10, "learning_rate": 1e-5}}
    new = migrate(v3)
    assert new["critic_warmup"] == {"iterations": 10, "learning_rate": 1e-5, "freeze_normalizer": False}
    assert new["config_version"] == 4 and "lr_decay" not in new  # the version 2 -> 3 key is not filled again


def test_migrate_fills_a_version_1_config_without_the_error_observation():
    v1 = {"config_version": 1, "env": {"num_envs": 8, "tcp_obs": True}, "task": dict(NO_TASK), "knots": {"n_state": 5}}
    new = migrate(v1)
    assert new["env"] == {"num_envs": 8, "tcp_obs": True, "error_obs": False, "error_obs_scale": 0.1}
    assert new["task"] == NO_TASK and "init_from" not in new  # the version 0 keys are not filled again
    assert new["lr_decay"] == {"final": None, "start": 0.0} and new["config_version"] == 4
    assert TrackingEnvCfg.from_run(new, seed=0).error_obs is False


def test_migrate_leaves_a_current_config_alone_and_refuses_newer_ones():
    cfg = to_container(compose("train", ["+experiment=iiwa7_ball_balancing_residual"], TrainAppCfg))
    assert migrate(cfg) == cfg
    for bad in (CONFIG_VERSION + 1, -1, True, "1"):
        with pytest.raises(ValueError, match="config_version"):
            config_version({"config_version": bad})


@pytest.mark.parametrize("path", SAVED, ids=lambda p: p.parent.name)
def test_every_shipped_model_reads_its_saved_env_values_and_back_fills_the_rest(path):
    saved = yaml.safe_load(path.read_text())
    env = TrackingEnvCfg.from_run(saved)
    for key, value in saved["env"].items():
        assert _plain(getattr(env, key)) == value, key
    for key in set(DEFAULTS) - set(saved["env"]):
        assert _plain(getattr(env, key)) == {**ADDED_KEYS, **ADDED_IN_V2}[f"env.{key}"], key
    assert env.n_state == saved["knots"]["n_state"]


def test_env_package_and_migration_do_not_import_hydra():
    files = [*sorted((ROOT / "pathrl" / "envs").glob("*.py")), ROOT / "pathrl" / "config" / "migrate.py"]
    for path in files:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import | ast.ImportFrom):
                mods = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
                assert not any(m.split(".")[0] in ("hydra", "omegaconf") for m in mods), f"{path.name}: {mods}"


def test_a_run_saved_before_config_version_resumes_under_the_current_config():
    from pathrl.train.runner import config_change

    now = to_container(compose("train", ["+experiment=iiwa7_random", "iterations=9", "resume=true"], TrainAppCfg))
    saved = {k: v for k, v in now.items() if k not in ("config_version", "critic_warmup", "teacher", "residual")}
    saved["iterations"] = 5
    assert config_change(saved, now) == ""
    saved["env"] = {k: v for k, v in now["env"].items() if k != "free_joint_actions"}  # saved when it was linear
    assert config_change(saved, now) == "env.free_joint_actions: 'linear' != 'centred'"
