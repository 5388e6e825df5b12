"""The family registry's contract: every registered family is built, evaluated (tiny), recorded, viewed (.rrd read
back) and tabled through the shared entry points (pathrl-eval, pathrl-view, pathrl.families)."""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path

import pytest

from pathrl.cli.evaluate import main as eval_main
from pathrl.cli.view import main as view_main
from pathrl.eval.evaluate import EvalOptions
from pathrl.families import ADAPTERS, FAMILIES, Family, family_of, resolve

ROOT = Path(__file__).resolve().parents[1]

#: Per family: the smallest shipped run and the pathrl-eval keys of a tiny evaluation.
CASES = {
    "tracking": ("models/tracking/iiwa7_random", ["episodes=2", "num_envs=2", "record=false"]),
    "trueadapt": ("models/trueadapt/iiwa7_trueadapt_on_plate_tray_controller", ["episodes=2", "num_envs=2",
                                                                      "backend=analytic"]),
    "industrial": ("models/industrial/industrial_td3", ["episodes=1"]),
}
STEPS = [f.name for f in fields(Family) if f.name not in ("name", "summary", "tasks", "recordings")]


def test_every_family_has_a_case_and_resolvable_steps():
    assert set(CASES) == set(FAMILIES)
    for fam in FAMILIES.values():
        assert all(callable(fam.step(s)) for s in STEPS), fam.name
        assert all(callable(resolve(r.view)) for r in fam.recordings), fam.name


def test_resolve_imports_only_the_families_modules():
    assert set(ADAPTERS) == {f"pathrl.families.{n}" for n in FAMILIES}
    for bad in ("os:system", "pathrl.families.tracking", "pathrl.families.tracking:__import__('os')"):
        with pytest.raises(ValueError, match="not a family adapter"):
            resolve(bad)


@pytest.mark.parametrize("name", list(CASES))
def test_the_run_is_recognised(name):
    assert family_of(ROOT / CASES[name][0]).name == name


def _rrd_chunks(path: Path) -> int:
    from rerun.chunk import RrdReader

    return sum(1 for _ in RrdReader(path).stream().to_chunks())


@pytest.mark.parametrize("name", list(CASES))
def test_build_evaluate_record_view_and_table(name, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    run, keys = CASES[name]
    fam = FAMILIES[name]
    opts = EvalOptions(episodes=1, num_envs=1, backend="analytic", record=False, progress=False)
    env = fam.step("build")(Path(run), opts)
    assert env is not None
    getattr(env, "close", lambda: None)()

    out = tmp_path / "eval"
    assert eval_main([f"run_dir={run}", *keys, f"out={out}"]) == 0, capsys.readouterr().err
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["episodes"] >= 1 and f"wrote {out / 'metrics.json'}" in capsys.readouterr().out

    rec = fam.step("record")(Path(run), tmp_path / "rec", opts)
    assert rec.is_file() and family_of(rec) is fam
    assert view_main([str(rec.parent)]) == 0, capsys.readouterr().err
    rrd = rec.with_suffix(".rrd")
    assert rrd.is_file() and _rrd_chunks(rrd) > 0
    assert f"wrote {rrd}" in capsys.readouterr().out

    rows = fam.step("table_rows")(metrics)
    assert len(rows) >= 3 and all(r.startswith("|") and r.endswith("|") for r in rows)
    assert len({r.count("|") for r in rows}) == 1  # every row has the header's columns
