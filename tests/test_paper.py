"""The source papers' published values (pathrl/config/paper/, read by pathrl.config.paper): one file per paper, the
main paper's tables identical to their upstream transcription, and every reader sees the same numbers."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
import yaml

from pathrl.config import paper
from pathrl.config.paper import DIR, PAPERS, PaperError, load

ROOT = Path(__file__).resolve().parents[1]
UPSTREAM = ROOT.parent / "shared" / "reference" / "paper_tables.yaml"  # the main paper's tables, upstream


def test_one_file_per_paper_shipped_as_package_data():
    assert sorted(p.stem for p in DIR.glob("*.yaml")) == sorted(PAPERS)
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["pathrl"]
    assert "config/paper/*.yaml" in data
    for name in PAPERS:
        p = load(name)
        assert p.tables and all(len(r) == len(t.columns) for t in p.tables.values() for r in t.rows.values())


@pytest.mark.skipif(not UPSTREAM.is_file(), reason="no ../shared/reference/paper_tables.yaml next to the checkout")
def test_main_paper_tables_equal_the_upstream_transcription():
    ours = yaml.safe_load((DIR / "tracking.yaml").read_text())
    ours.pop("values")
    assert ours == yaml.safe_load(UPSTREAM.read_text())


def test_readers_take_their_values_from_the_files():
    from pathrl.cli import toppra
    from pathrl.eval import curve
    from pathrl.industrial import tables, timing
    from pathrl.repro import trueadapt

    assert toppra.PAPER_EPISODES == curve.PAPER_EPISODES == load("tracking").value("episodes") == 1200
    assert trueadapt.paper() == load("trueadapt").table("trueadapt_table_I").as_dict()
    ind = load("industrial")
    t2 = ind.table("table_II")
    assert tables.PAPER_TABLE2["Type 1 Easy"] == (250, 0.80, 1.02, 0.20, 3, 95.45)
    assert tables.PAPER_RL["Type 1 Easy"] == (0.23, 1, 9.61) and list(tables.PAPER_RL) == list(t2.rows)
    assert tables.PAPER_TABLE3["Type 1 Hard"] == (0.49, 91.13, 3.0)
    assert list(tables.PAPER_TABLE4) == ["RL", "RL-PER", "RL-P_target", "RL-q-F_jac", "RL-e"]
    assert tables.PAPER_TABLE4["RL-e"]["Type 2 (pose 4)"] == (0.54, None)
    assert (timing.PAPER_EXECUTION_S, timing.PAPER_MPGD_DECISION_S, timing.PAPER_POLICY_DECISION_S) == (
        ind.value("execution_s"), ind.value("mpgd_decision_s"), ind.value("policy_decision_s"))


def test_lookups_name_what_exists(tmp_path, monkeypatch):
    with pytest.raises(KeyError, match="no paper 'nope'"):
        load("nope")
    with pytest.raises(KeyError, match="has no table 'table_X'.*table_I_tracking_no_feedback"):
        load("tracking").table("table_X")
    with pytest.raises(KeyError, match="has no value 'nope'.*episodes"):
        load("tracking").value("nope")
    assert load("tracking").table("table_II_tradeoff_length_vs_deviation").row("length_eq_deviation") == {
        "duration_s": 4.28, "cart_pos_dev_mean_cm": 3.3, "cart_pos_dev_max_cm": 7.5, "cart_pos_dev_final_cm": 2.7}
    # as_dict hands out copies: a renderer cannot change the loaded values
    d = load("tracking").as_dict()
    d["table_IX_computation_time"]["rows"]["iiwa7"][0] = 0.0
    assert load("tracking").table("table_IX_computation_time").rows["iiwa7"] == (7.50,)


def test_a_malformed_file_is_one_error_naming_it(tmp_path, monkeypatch):
    (tmp_path / "tracking.yaml").write_text("t:\n  columns: [a, b]\n  rows:\n    r: [1]\n")
    monkeypatch.setattr(paper, "DIR", tmp_path)
    load.cache_clear()
    try:
        with pytest.raises(PaperError, match=r"tracking.yaml: t: row 'r' needs one value per column \(2\)"):
            load("tracking")
    finally:
        load.cache_clear()
