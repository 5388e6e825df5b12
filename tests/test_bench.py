"""The benchmarks of `make bench` (pathrl.bench) on tiny sizes: an env bench, a family's realtime timing through its
registry step, and the merge into an existing results file."""

from __future__ import annotations

import json
from pathlib import Path

from pathrl.bench.env import bench_env
from pathrl.bench.suite import FAMILY_TIMING, family_timing, merge

ROOT = Path(__file__).resolve().parents[1]


def test_env_bench_steps_the_synthetic_env():
    r = bench_env("iiwa7", 8, 0.05, "eager")
    assert r["robot"] == "iiwa7" and r["limits"] == "eager" and r["steps"] >= 1 and r["env_steps_per_s"] > 0


def test_family_timing_is_the_registry_timing_step():
    """The TrueAdapt decision of bench/results.json (`trueadapt_decision`): the family's `timing` step, with the keys
    of the committed time per decision of the tables (results/raw/trueadapt_realtime.json, the same step)."""
    key, name, model, dataset, _, _ = FAMILY_TIMING[0]
    r = family_timing(name, ROOT / model, ROOT / dataset, 20)
    committed = json.loads((ROOT / "results" / "raw" / "trueadapt_realtime.json").read_text())
    assert key == "trueadapt_decision" and set(r) == set(committed)
    assert 0 < r["decision_ms_mean"] <= r["decision_ms_max"]


def test_merge_keeps_the_other_entries(tmp_path):
    out = tmp_path / "bench.json"
    merge(out, {"a": 1, "b": {"x": 2}})
    merge(out, {"b": 3})
    assert json.loads(out.read_text()) == {"a": 1, "b": 3}
