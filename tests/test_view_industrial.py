"""pathrl-industrial record + pathrl-view (issue 21): one optimisation with every execution in industrial.mcap, and
its Rerun recording."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from pathrl.cli.industrial import main as industrial_main
from pathrl.cli.view import main as view_main
from pathrl.industrial.controller import ControllerParams, execute
from pathrl.industrial.experiments import select_targets
from pathrl.industrial.iwa_env import IWAEpisode, IWASettings
from pathrl.industrial.mpgd import MPGDParams, run_mpgd
from pathrl.industrial.record import mpgd_iterations, policy_iterations
from pathrl.industrial.rl import run_policy_iwa
from pathrl.industrial.trajectories import baseline_program
from pathrl.logging.mcap_io import McapJsonWriter, read_messages
from pathrl.logging.schema import (
    INDUSTRIAL_ERROR,
    INDUSTRIAL_EXECUTED,
    INDUSTRIAL_SUMMARY,
    INDUSTRIAL_TARGET,
    INDUSTRIAL_WAYPOINTS,
)
from pathrl.viz.industrial import error_profile, magnified, magnify_factor, read_industrial

ROW = "Type 1 Medium"


@pytest.fixture(scope="module")
def target():
    return select_targets([ROW])[0]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("industrial")
    assert industrial_main(["record", f"traj={ROW}", "method=mpgd", "mpgd.k_max=3", f"out={out}"]) == 0
    return out


def feedback(gain: float):
    return lambda obs: np.tile([gain, 0.0, 0.0], (len(obs), 1))


def by_topic(path: Path) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = defaultdict(list)
    for topic, _, msg in read_messages(path):
        out[topic].append(msg)
    return out


def test_mpgd_iterations_are_run_mpgds(target):
    """The kept executions are run_mpgd's: same error history and the same best program."""
    params, ctrl = MPGDParams(k_max=3), ControllerParams()
    program = baseline_program(target)
    ref = run_mpgd(target, program, target.speed, params, ctrl)
    res, kept = mpgd_iterations(target, program, target.speed, params, ctrl)
    assert res.history == ref.history == [k.errors.max_pos_mm for k in kept]
    assert [k.k for k in kept] == list(range(len(ref.history)))
    assert np.array_equal(res.program.positions, ref.program.positions)
    assert np.array_equal(kept[0].waypoints, program.positions)  # iteration 0 = the baseline profile
    assert not np.array_equal(kept[1].waypoints, kept[0].waypoints)
    assert kept[0].profile.max() == pytest.approx(kept[0].errors.max_pos_mm)


def test_policy_iterations_keep_what_the_policy_saw(target):
    """The learned IWA's kept executions reproduce run_policy_iwa's history (the copy is the same execution)."""
    ctrl = ControllerParams()
    ref = run_policy_iwa(IWAEpisode(target, target.speed, ctrl, IWASettings(100, 10.0, 2)), feedback(0.5))
    res, kept = policy_iterations(target, target.speed, ctrl, feedback(0.5), IWASettings(k_max=2))
    assert res.history == ref.history == [k.errors.max_pos_mm for k in kept]
    assert len(kept) == 3 and kept[-1].errors.max_pos_mm < kept[0].errors.max_pos_mm
    ex = execute(baseline_program(target), target.speed, ctrl)
    assert np.array_equal(kept[0].executed, ex.p)


def test_record_writes_the_topics_and_counts(recorded, target):
    msgs = by_topic(recorded / "industrial.mcap")
    assert {k: len(v) for k, v in msgs.items()} == {INDUSTRIAL_TARGET: 1, INDUSTRIAL_WAYPOINTS: 4,
                                                    INDUSTRIAL_EXECUTED: 4, INDUSTRIAL_ERROR: 4,
                                                    INDUSTRIAL_SUMMARY: 1}
    t = msgs[INDUSTRIAL_TARGET][0]
    assert t["name"] == ROW and t["method"] == "mpgd" and t["speed_mm_s"] == target.speed
    assert np.allclose(t["positions"], target.p)
    assert [m["iteration"] for m in msgs[INDUSTRIAL_EXECUTED]] == [0, 1, 2, 3]
    assert all(np.shape(m["positions"]) == (100, 3) for m in msgs[INDUSTRIAL_WAYPOINTS])
    ex, err = msgs[INDUSTRIAL_EXECUTED][0], msgs[INDUSTRIAL_ERROR][0]
    assert np.shape(ex["positions"]) == (len(ex["t"]), 3) and len(err["profile_mm"]) == len(ex["t"])
    s = msgs[INDUSTRIAL_SUMMARY][0]
    assert s["history"] == [m["max_pos_mm"] for m in msgs[INDUSTRIAL_ERROR]]
    assert s["best_iteration"] == int(np.argmin(s["history"])) and s["executions"] == 4


def test_view_converts_it(recorded, capsys):
    assert view_main([str(recorded)]) == 0
    out = recorded / "industrial.rrd"
    assert "4 executions" in capsys.readouterr().out and out.stat().st_size > 10_000
    rows = rrd_entities(out)
    for ent in ("/world/target", "/world/baseline", "/world/best", "/world/executed", "/world/waypoints",
                "/magnified/executed", "/error/max_mm", "/error/profile", "/summary"):
        assert ent in rows, ent
    assert rows["/world/executed"] == 4 and rows["/error/max_mm"] == 4 and rows["/error/profile"] == 4


def test_magnified_paths_and_the_error_profile(recorded):
    rec = read_industrial(recorded / "industrial.mcap")
    f = magnify_factor(rec)
    assert f >= 1 and f / 10 ** np.floor(np.log10(f)) in (1, 2, 5)
    ex, wp = magnified(rec, f)
    u = np.asarray(rec.errors[0]["target_index"])
    d_true = np.asarray(rec.errors[0]["profile_mm"])
    i0 = np.clip(np.floor(u).astype(int), 0, len(rec.target_p) - 2)
    base = rec.target_p[i0] + (u - i0)[:, None] * (rec.target_p[i0 + 1] - rec.target_p[i0])
    assert np.allclose(np.linalg.norm(ex[0] - base, axis=1), f * d_true, rtol=1e-9, atol=1e-6)
    assert wp[0].shape == (100, 3)
    arc, prof = error_profile(rec, 0, bins=50)
    assert arc.shape == prof.shape == (50,) and prof.max() == pytest.approx(d_true.max())


def rrd_entities(path: Path) -> dict[str, int]:
    """entity path -> rows (on any timeline or static) of an .rrd."""
    from rerun.chunk import RrdReader

    rows: dict[str, int] = defaultdict(int)
    for chunk in RrdReader(path).stream().to_chunks():
        rows[str(chunk.entity_path)] += 0 if chunk.is_static else chunk.num_rows
        rows.setdefault(str(chunk.entity_path), 0)
    return rows


@pytest.mark.parametrize("args, msg", [
    (["traj=Type 9", "method=mpgd"], "unknown evaluation row 'Type 9'"),
    ([f"traj={ROW}", "method=rl"], "method=rl needs policy="),
    ([f"traj={ROW}", "method=rl", "policy=models/no_such_policy"], "no such run directory"),
    ([f"traj={ROW}", "method=mpgd", "policy=models/industrial/industrial_td3"], "policy= is for method=rl"),
    ([f"traj={ROW}", "method=gd"], "method must be mpgd or rl"),
    ([f"traj={ROW}"], "missing method="),
])
def test_bad_record_arguments_are_one_line(args, msg, tmp_path, capsys):
    assert industrial_main(["record", *args, f"out={tmp_path}"]) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and "\n" not in err and not (tmp_path / "industrial.mcap").exists()


def test_a_non_industrial_mcap_is_one_line(tmp_path, capsys):
    bad = tmp_path / "industrial.mcap"
    with McapJsonWriter(bad) as w:
        w.write("/something/else", {"x": 1})
    assert view_main([str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "no pathrl channels" in err and "/industrial/target" in err and "\n" not in err
