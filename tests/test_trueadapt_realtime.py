"""Time per TrueAdapt decision (pathrl.eval.trueadapt_realtime) and its line in the tables."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pathrl.eval import trueadapt_realtime as rt
from pathrl.models import model_dir, model_ref
from pathrl.repro import trueadapt as adapt

ROOT = Path(__file__).resolve().parents[1]
MODEL = model_dir(adapt.REALTIME_MODEL)
DATA = ROOT / "datasets" / "iiwa7" / adapt.REALTIME_DATA


def test_the_shipped_student_is_timed_per_decision(tmp_path):
    out = tmp_path / "rt.json"
    assert rt.main([str(MODEL), str(out), "--dataset", str(DATA), "--decisions", "30"]) == 0
    r = json.loads(out.read_text())
    assert r["decisions"] == 30 and r["threads"] == 1 and r["cycle_ms"] == pytest.approx(50.0)
    assert 0 < r["valid_range_ms_max"] <= r["decision_ms_max"]
    assert 0 < r["decision_ms_mean"] <= r["decision_ms_p99"] <= r["decision_ms_max"]
    assert r["max_pct_of_cycle"] == pytest.approx(100 * r["decision_ms_max"] / 50.0)


def test_bad_arguments_are_one_line_errors(tmp_path, capsys):
    with pytest.raises(SystemExit):
        rt.main([str(tmp_path), str(tmp_path / "rt.json")])
    assert "not a model directory" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        rt.main([str(MODEL), str(tmp_path / "rt.json"), "--decisions", "0"])
    assert "--decisions must be >= 1" in capsys.readouterr().err
    assert not (tmp_path / "rt.json").exists()


def test_the_tables_show_the_measurement_or_say_it_is_missing(tmp_path):
    r = {"model": "models/x", "decisions": 2000, "limits": "native", "decision_ms_mean": 0.5, "decision_ms_max": 0.9,
         "max_pct_of_cycle": 1.8, "cycle_ms": 50.0, "valid_range_ms_max": 0.19}
    lines, csv = adapt.markdown({adapt.REALTIME_ID: r})
    line = next(x for x in lines if x.startswith("Time per decision"))
    assert "**0.50 ms** mean, 0.90 ms max (1.8 % of the 50 ms cycle)" in line and "**0.19 ms**" in line
    assert [adapt.ADAPT_TABLE, "realtime", "valid_range_ms_max", "0.19", "0.9"] in csv
    lines, _ = adapt.markdown({})
    assert "Time per decision: not measured." in lines
    # not shipped, or reused: no command
    assert adapt.realtime_command(ROOT, tmp_path, tmp_path, ROOT / "datasets", 10) is None
    (tmp_path / f"{adapt.REALTIME_ID}.json").write_text("{}")
    assert adapt.realtime_command(ROOT, tmp_path, ROOT / "models", ROOT / "datasets", 10, reuse=True) is None
    cmd = adapt.realtime_command(ROOT, tmp_path, ROOT / "models", ROOT / "datasets", 10)
    assert cmd[:6] == ["python", "-m", adapt.FAMILY_STEP, "trueadapt", "timing", model_ref(adapt.REALTIME_MODEL)]
