"""sweeps/<table>.yaml: the loader's one-line errors, the derived tables, warm starts from init_from."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from pathrl.repro.sweeps import SWEEPS_DIR, SweepsError, load_table, load_tables, warm_starts
from pathrl.repro.tables import (
    CONTROLLER_MODELS,
    NO_SECOND_TEST_SET,
    ROWS,
    SWEEPS,
    TABLE_FILES,
    TABLE_GREEDY,
    TABLE_I,
    TABLE_I_TEST2,
    Evaluation,
    greedy_model,
    select,
)

ROOT = Path(__file__).resolve().parents[1]
GOOD_ROW = "  - {key: a, model: m, robot: iiwa7, dataset: random}\n"


def _error(tmp_path: Path, text: str) -> str:
    path = tmp_path / "table_X.yaml"
    path.write_text(text)
    with pytest.raises(SweepsError) as info:
        load_table(path, Evaluation)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith("table_X.yaml"), msg
    return msg


def test_bad_row_key_is_a_one_line_error(tmp_path):
    msg = _error(tmp_path, "rows:\n" + GOOD_ROW + "  - {key: b, modle: m, robot: iiwa7, dataset: random}\n")
    assert "row 2 (b): unknown key 'modle'" in msg and "model" in msg


@pytest.mark.parametrize(("text", "expected"), [
    ("rows:\n" + GOOD_ROW + "trian: [x]\n", "unknown key 'trian'"),
    ("rows:\n  - {key: a, model: m, robot: iiwa7}\n", "row 1 (a): missing dataset"),
    ("rows:\n  - {key: a, model: m, robot: iiwa7, dataset: random, episodes: many}\n", "episodes must be int | None"),
    ("rows:\n  - {key: a, model: m, robot: iiwa7, dataset: random, open_loop: 1}\n", "open_loop must be bool"),
    ("rows:\n" + GOOD_ROW + GOOD_ROW, "row key 'a' appears more than once"),
    ("rows:\n  - {model: m}\n", "a row must be a mapping with a string 'key'"),
    ("rows: []\n", "rows must be a non-empty list"),
    ("rows:\n" + GOOD_ROW + "train: iiwa7_random\n", "train must be a list of names"),
    ("rows: [\n", "while parsing"),
])
def test_bad_file_is_a_one_line_error(tmp_path, text, expected):
    assert expected in _error(tmp_path, text)


def test_defaults_and_flags(tmp_path):
    path = tmp_path / "t.yaml"
    path.write_text("defaults: {robot: iiwa7, dataset: random, episodes: 200}\ntrain: [e1, e2]\nrows:\n"
                    "  - {key: a, model: m}\n  - {key: b, model: c, episodes: null, controller: true, "
                    "not_in_paper: true}\n")
    spec = load_table(path, Evaluation)
    assert spec.train == ("e1", "e2") and [r.key for r in spec.rows] == ["a", "b"]
    assert spec.rows[0].evaluation == Evaluation("m", "iiwa7", "random", episodes=200)
    assert spec.rows[1].evaluation.episodes is None and spec.rows[1].controller and spec.rows[1].not_in_paper


def test_every_file_is_a_known_table(tmp_path):
    (tmp_path / "a.yaml").write_text("rows:\n" + GOOD_ROW)
    (tmp_path / "b.yaml").write_text("rows:\n" + GOOD_ROW)
    assert list(load_tables(tmp_path, ("b", "a"), Evaluation)) == ["b", "a"]
    with pytest.raises(SweepsError, match="b.yaml: not a known table"):
        load_tables(tmp_path, ("a",), Evaluation)
    with pytest.raises(SweepsError, match="no c.yaml"):
        load_tables(tmp_path, ("a", "b", "c"), Evaluation)


def test_sweeps_dir_is_the_package_data():
    assert (ROOT / "sweeps").resolve() == SWEEPS_DIR == ROOT / "pathrl" / "sweeps"
    assert sorted(p.stem for p in SWEEPS_DIR.glob("*.yaml")) == sorted(TABLE_FILES)


def test_derived_tables_follow_table_i():
    """The greedy follower and the second test split repeat Table I's rows (their files list them out)."""
    table_i = {r.key: r.evaluation for r in ROWS if r.table == TABLE_I}
    greedy = {r.key: r.evaluation for r in ROWS if r.table == TABLE_GREEDY}
    assert greedy == {k: replace(e, model=greedy_model(e)) for k, e in table_i.items()}
    test2 = {r.key: r.evaluation for r in ROWS if r.table == TABLE_I_TEST2}
    assert NO_SECOND_TEST_SET == set()
    assert test2 == {k: replace(e, second_test_set=True) for k, e in table_i.items() if k not in NO_SECOND_TEST_SET}


def test_controller_flag_is_per_model():
    """A model is a controller in every row or in none (the flag names the model, not the row)."""
    for spec in SWEEPS.values():
        for r in spec.rows:
            assert r.controller == (r.evaluation.model in CONTROLLER_MODELS), (spec.name, r.key)


def test_select_by_table_or_model():
    assert {r.table for r in select({"table_II"})} == {TABLE_FILES["table_II"]}
    assert len(select({"table_VII"})) == len(SWEEPS["table_VII"].rows)
    assert {r.evaluation.model for r in select({"armar4_random"})} == {"armar4_random"}
    assert select(None) == ROWS


def test_warm_starts_follow_defaults(tmp_path):
    files = {"base": "init_from: null\n", "src": "iterations: 3\n", "warm": "init_from: models/tracking/src\n",
             "child": "defaults:\n  - warm\n  - override /reward: x\n",  # inherits warm's init_from
             "reset": "defaults:\n  - warm\ninit_from: null\n", "over": "defaults:\n  - warm\ninit_from: "
                                                                        "models/tracking/base\n"}
    for name, text in files.items():
        (tmp_path / f"{name}.yaml").write_text(text)
    assert warm_starts(tmp_path) == {"child": "src", "over": "base", "warm": "src"}
    (tmp_path / "bad.yaml").write_text("init_from: runs/src/seed0\n")
    with pytest.raises(SweepsError, match="bad.yaml: init_from: expected models/<family>/<name>"):
        warm_starts(tmp_path)
