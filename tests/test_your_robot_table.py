"""The new-robot students' table (tools/lab/your_robot_table.py): hand-checked cells from made-up files, and the
committed table is what the committed results give."""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools" / "lab"))

import your_robot_table as table  # noqa: E402


def test_cells_from_the_files(tmp_path):
    per = [{"termination": "robot_stopped"}] * 3 + [{"termination": "time_out"}]
    (tmp_path / "arm_student.json").write_text(json.dumps({
        "episodes": 4, "duration_s": 2.3, "cart_pos_dev_mean_cm": 1.5, "cart_pos_dev_max_cm": 4.0,
        "limit_violations": 0, "per_episode": per}))
    (tmp_path / "arm_toppra.json").write_text(json.dumps({"toppra_duration_s": 2.0}))
    (tmp_path / "arm_training.json").write_text(json.dumps({"wall_time_s": 600.0, "iterations": 800,
                                                            "env_steps": 13_107_200}))
    (r,) = table.rows(tmp_path)
    assert r["ratio"] == 2.3 / 2.0 and r["timeouts"] == 25.0 and r["minutes"] == 10.0
    md = table.markdown([r])
    assert "| arm | random | 4 | 2.30 | 2.00 | 1.150 | 1.50 / 4.00 | 25.0 | 0 | 10.0, 800, 13.1 | yes |" in md
    md_slow = table.markdown([{**r, "minutes": 16.0}])
    assert md_slow.rstrip().endswith("| no |")


def test_the_committed_table_is_current():
    assert (table.DIR / "table.md").is_file() and table.main(["--check"]) == 0
    assert {r["robot"] for r in table.rows(table.DIR)} == {"panda", "xarm6"}
