"""Real-time figure (Table IX): per-episode compute / duration ratios from real single-env rollouts."""

from pathlib import Path

import pytest

from pathrl.eval.realtime import main, realtime_ratios
from pathrl.robot.external import load_robot_by_name

DATA = Path(__file__).resolve().parents[1] / "datasets"


@pytest.mark.parametrize("simulate", [False, True])
def test_realtime_ratios(simulate):
    r = realtime_ratios(load_robot_by_name("iiwa7"), str(DATA / "iiwa7" / "random"), episodes=2, simulate=simulate,
                        compile_limits=False)
    assert r["episodes"] == 2 and r["decisions"] >= 2 and r["simulated"] is simulate
    assert 0.0 < r["mean_compute_to_duration_pct"] <= r["max_compute_to_duration_pct"]
    assert 0.0 < r["decision_ms_mean"] <= r["decision_ms_max"]


def test_realtime_cli_writes_both_variants(tmp_path):
    out = tmp_path / "rt.json"
    assert main(["armar6", str(DATA / "armar6" / "random"), str(out), "--episodes", "1", "--eager"]) == 0
    import json

    res = json.loads(out.read_text())
    assert set(res) == {"policy_and_limits", "with_simulation"}
    assert res["with_simulation"]["simulated"] and not res["policy_and_limits"]["simulated"]
