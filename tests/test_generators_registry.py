"""The dataset generator registry: every kind resolves to a generator with one signature; unknown kinds fail early."""

from __future__ import annotations

import inspect

import pytest
from omegaconf import OmegaConf

from pathrl.config.paths import CONF_DIR
from pathrl.datagen.generate import generate_dataset
from pathrl.datagen.generators import GENERATORS, get_generator, path_kind
from pathrl.datagen.generators.defaults import DEFAULT_PARAMS, KINDS
from pathrl.dataset.io import DatasetError
from pathrl.robot.external import load_robot_by_name


def test_every_registered_generator_has_the_generate_dataset_signature():
    want = list(inspect.signature(generate_dataset).parameters)
    for kind in GENERATORS:
        got = list(inspect.signature(get_generator(kind)).parameters)
        assert got == want, kind


def test_path_kinds_are_registered_with_their_defaults():
    assert set(KINDS) == set(DEFAULT_PARAMS) and set(KINDS) < set(GENERATORS)
    for kind in KINDS:
        module = path_kind(kind)
        assert module.KIND == kind
        assert callable(module.check_robot) and callable(module.stored_paths)


def test_check_robot_of_the_path_kinds():
    armar6 = load_robot_by_name("armar6")
    path_kind("random").check_robot(armar6)  # no error: any robot
    path_kind("target_point").check_robot(armar6)
    with pytest.raises(DatasetError, match="iiwa7 only"):
        path_kind("ball_balancing").check_robot(armar6)
    path_kind("ball_balancing").check_robot(load_robot_by_name("iiwa7"))


def test_unknown_kind_names_every_registered_kind_and_writes_nothing(tmp_path):
    robot = OmegaConf.to_container(OmegaConf.load(CONF_DIR / "robot" / "iiwa7.yaml"), resolve=True)
    with pytest.raises(DatasetError) as err:
        generate_dataset(robot, {"kind": "spiral", "num_train": 1}, dest=tmp_path / "x", progress=False)
    msg = str(err.value)
    assert "\n" not in msg and "'spiral'" in msg
    assert all(repr(kind) in msg for kind in GENERATORS)
    assert not (tmp_path / "x").exists()
