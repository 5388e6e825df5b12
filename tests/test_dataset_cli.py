"""``pathrl-dataset`` smoke runs: generate, import, info, bad input (exit 2, one line, nothing written)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_dataset_kiemel import write_set

from pathrl.cli.dataset import main
from pathrl.dataset.io import load_dataset


def test_generate_and_info(tmp_path, capsys):
    dest = tmp_path / "ball"
    args = [
        "generate",
        "robot=iiwa7",
        "dataset=ball_balancing",
        "dataset.num_train=2",
        "dataset.num_test=2",
        f"dataset.path={dest}",
        "workers=1",
    ]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert f"wrote {dest}" in out and "train 2, test 2" in out
    ds = load_dataset(dest)
    assert ds.meta["robot"] == "iiwa7" and ds.meta["kind"] == "ball_balancing"
    # existing dataset: refused without overwrite=true
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "already exists" in err and err.count("\n") == 1
    assert main([*args, "overwrite=true", "dataset.seed=9"]) == 0
    capsys.readouterr()
    assert load_dataset(dest).meta["seed"] == 9
    assert main(["info", str(dest)]) == 0
    out = capsys.readouterr().out
    assert ds.content_hash not in out and load_dataset(dest).content_hash in out
    assert "stored" in out and "distance_0.3" in out


def test_import_and_info(tmp_path, capsys):
    src = tmp_path / "src"
    write_set(src, np.random.default_rng(0), {"train": 2, "test": 1})
    (src / "spline_config.json").write_text(json.dumps({"max_dis_between_knots": 0.5}))
    dest = tmp_path / "imported"
    assert main(["import", "--format", "kiemel-json", "--robot", "iiwa7", str(src), str(dest)]) == 0
    assert "imported" in capsys.readouterr().out
    assert main(["info", str(dest)]) == 0
    out = capsys.readouterr().out
    assert "kiemel-json" in out and "reference max knot gap (spline_config) 0.5" in out


@pytest.mark.parametrize(
    "args, match",
    [
        ([], "missing command"),
        (["frobnicate"], "unknown command"),
        (["generate", "robot=nosuchrobot"], "config error"),
        (["generate", "dataset.num_tran=3"], "config error"),
        (["generate", "robot=armar6", "dataset=ball_balancing"], "iiwa7 only"),
        (["generate", "+dataset.params.bogus=1"], "unknown keys"),
        (["generate", "notanoverride"], "key=value"),
        (["import", "--format", "xlsx", "--robot", "iiwa7", "a", "b"], "invalid choice"),
        (["import", "--format", "csv", "--robot", "iiwa7", "a", "b"], "no such file or directory"),
        (["import", "--format", "kiemel-json", "--robot", "r2d2", "a", "b"], "unknown robot"),
        (["import", "--format", "kiemel-json", "--robot", "iiwa7", "/nonexistent/x", "DEST"], "not found"),
        (["info", "/nonexistent/dataset"], "not found"),
        (["import", "--format", "csv", "--reflections", "--robot", "iiwa7", "a", "b"], "--reflections is for"),
    ],
)
def test_bad_input(tmp_path, capsys, monkeypatch, args, match):
    monkeypatch.chdir(tmp_path)
    args = [a.replace("DEST", str(tmp_path / "dest")) for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert match in err and err.count("\n") == 1, err
    assert list(tmp_path.iterdir()) == []
