"""pathrl-view: MCAP (episodes / run) -> Rerun .rrd, read back with rerun.chunk.RrdReader."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pathrl.cli.view import main
from pathrl.logging.mcap_io import McapJsonWriter, read_messages
from pathrl.viz import rerun_view as rv
from pathrl.viz.synthetic import write_synthetic_episodes, write_synthetic_run

STEPS = 20


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("run")
    write_synthetic_episodes(d / "episodes.mcap", "iiwa7", episodes=3, steps=STEPS, seed=1)
    write_synthetic_run(d / "run.mcap", iterations=12)
    return d


def rrd_rows(path: Path) -> dict[str, list[dict]]:
    """entity path -> list of chunk record batches (as python dicts, RowId dropped)."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    out: dict[str, list[dict]] = defaultdict(list)
    for chunk in RrdReader(path).stream().to_chunks():
        batch = chunk.to_record_batch()
        d = {}
        for name, col in zip(batch.schema.names, batch.columns, strict=True):
            if name != "rerun.controls.RowId":
                d[name] = (col.cast(pa.int64()) if pa.types.is_duration(col.type) else col).to_pylist()
        out[str(chunk.entity_path)].append(d)
    return out


def column(rows: dict[str, list[dict]], entity: str, col: str) -> list:
    """Values of component `col` on the `time` timeline, in time order."""
    pairs = [
        (t, v)
        for d in rows[entity]
        if col in d and "time" in d
        for t, v in zip(d["time"], d[col], strict=True)
    ]
    return [v for _, v in sorted(pairs, key=lambda p: p[0])]


def messages(path: Path, topic: str) -> list[dict]:
    return [m for t, _, m in read_messages(path, [topic]) if t == topic]


def test_run_directory_gives_both_recordings(run_dir, capsys):
    assert main([str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert "open with: rerun" in out
    ep = rrd_rows(run_dir / "episodes.rrd")
    states = messages(run_dir / "episodes.mcap", "/eval/joint_state")
    n = len(states)
    # robot: URDF geometry + one animated transform per joint and step (+ one final pose per episode)
    assert any(e.startswith("/world/iiwa7/visual_geometries/") for e in ep)
    assert len(column(ep, "/world/joint_transforms", "Transform3D:child_frame")) == 7 * (n + 3)
    assert {"/world/reference", "/world/executed", "/world/tcp", "/world/reference_point"} <= set(ep)
    assert len(column(ep, "/world/reference", "LineStrips3D:strips")) == 3
    assert len(column(ep, "/world/executed", "LineStrips3D:strips")) == n + 3
    for q in ("position", "velocity", "acceleration", "jerk"):
        vals = [v for v in column(ep, f"/joints/iiwa_joint_4/{q}", "Scalars:scalars")]
        assert len(vals) == (n if q != "jerk" else n - 3) + 2  # + NaN gap rows between the 3 episodes
        assert len(column(ep, f"/joints/iiwa_joint_4/{q}/limits", "Scalars:scalars")) == 2
    assert {"/progress/fraction", "/deviation/joint_rad", "/deviation/cartesian_cm/iiwa_link_7"} <= set(ep)
    texts = column(ep, "/metrics/episode", "TextDocument:text")
    assert len(texts) == 3 and "Episode 0" in texts[0][0] and "cart_pos_dev_mean_cm" in texts[0][0]
    assert "/metrics/summary" in ep and "/episode_metrics/cart_pos_dev_mean_cm" in ep

    run = rrd_rows(run_dir / "run.rrd")
    loss = [d for d in run["/training/Loss/value"] if "iteration" in d]
    assert sum(len(d["iteration"]) for d in loss) == 12
    assert (
        sum(len(d["iteration"]) for d in run["/training/Train/mean_episode_length"] if "iteration" in d) == 10
    )
    assert "/training/config" in run
    wall = [d for d in run["/training/Train/mean_reward/time"] if "train_time" in d]
    assert sum(len(d["train_time"]) for d in wall) == 10 and not any("iteration" in d for d in wall)


def test_joint_transforms_reproduce_the_logged_tcp(run_dir, tmp_path):
    """Chaining the logged joint transforms of one step gives the TCP that FK wrote into the MCAP."""
    out = tmp_path / "one.rrd"
    assert main([str(run_dir / "episodes.mcap"), "--episodes", "1", "--save", str(out)]) == 0
    rows = rrd_rows(out)
    by_child: dict[str, list] = {}
    for d in rows["/world/joint_transforms"]:
        if "episode" in d:
            continue
        rows_by_time = sorted(
            zip(d["time"], d["Transform3D:translation"], d["Transform3D:quaternion"], strict=True)
        )
        by_child[d["Transform3D:child_frame"][0][0]] = [(t, q) for _, t, q in rows_by_time]
    k = 7
    pose = np.eye(4)
    for j in range(1, 8):
        (t,), (q,) = by_child[f"iiwa_link_{j}"][k]
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = Rotation.from_quat(q).as_matrix(), t
        pose = pose @ m
    tcp = pose[:3, :3] @ [0, 0, 0.126] + pose[:3, 3]
    logged = [m for m in messages(run_dir / "episodes.mcap", "/eval/tcp") if m["episode"] == 1][k]
    np.testing.assert_allclose(tcp, logged["position"][0], atol=1e-5)


def test_selection_by_ids_and_worst(run_dir, tmp_path):
    out = tmp_path / "sel.rrd"
    assert main([str(run_dir / "episodes.mcap"), "--episodes", "2,0", "--save", str(out)]) == 0
    texts = column(rrd_rows(out), "/metrics/episode", "TextDocument:text")
    assert [t[0].splitlines()[0].split()[2] for t in texts] == ["2", "0"]
    metrics = messages(run_dir / "episodes.mcap", "/eval/episode_metrics")
    worst = max(metrics, key=lambda m: m["cart_pos_dev_mean_cm"])["episode"]
    assert main([str(run_dir / "episodes.mcap"), "--worst", "1", "--save", str(out)]) == 0
    texts = column(rrd_rows(out), "/metrics/episode", "TextDocument:text")
    assert len(texts) == 1 and texts[0][0].startswith(f"### Episode {worst} ")


def test_a_selection_never_replaces_the_full_recording(run_dir, tmp_path, capsys):
    """``--worst N`` used to write episodes.rrd, the full recording's name, with N episodes (issue 50)."""
    src = tmp_path / "episodes.mcap"
    src.write_bytes((run_dir / "episodes.mcap").read_bytes())
    assert main([str(src)]) == 0
    full = (tmp_path / "episodes.rrd").read_bytes()
    assert main([str(src), "--worst", "1"]) == 0 and main([str(src), "--episodes", "2,0"]) == 0
    assert (tmp_path / "episodes.rrd").read_bytes() == full
    assert len(column(rrd_rows(tmp_path / "episodes_worst1.rrd"), "/metrics/episode", "TextDocument:text")) == 1
    assert len(column(rrd_rows(tmp_path / "episodes_ep2-0.rrd"), "/metrics/episode", "TextDocument:text")) == 2
    assert "wrote " + str(tmp_path / "episodes_worst1.rrd") in capsys.readouterr().out


def test_a_truncated_file_says_so(run_dir, tmp_path, capsys):
    """A file cut inside its first chunk used to be reported as "no pathrl channels"."""
    src = tmp_path / "episodes.mcap"
    src.write_bytes((run_dir / "episodes.mcap").read_bytes()[:300])
    assert main([str(src)]) == 2
    err = capsys.readouterr().err
    assert "truncated or damaged MCAP" in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["episodes.mcap"]


def test_jerk_progress_and_deviation(run_dir):
    robot, episodes = rv.read_episodes(run_dir / "episodes.mcap")
    e = episodes[0]
    j = rv.jerk(e.a, e.t)
    np.testing.assert_allclose(j[0], (e.a[1] - e.a[0]) / (e.t[1] - e.t[0]))
    d = rv.progress_and_deviation(e, robot)
    assert d["fraction"][0] == 0 and 0.95 < d["fraction"][-1] <= 1.0
    assert np.all(np.diff(d["fraction"]) >= -1e-12)
    assert d["cartesian_cm"].shape == (len(e.t), 1) and d["cartesian_cm"].max() < 20


def test_extra_channels_and_missing_urdf(run_dir, tmp_path):
    """A file written elsewhere (URDF path not on this machine) with an /eval/ball channel."""
    src = tmp_path / "episodes.mcap"
    with McapJsonWriter(src) as w:
        for topic, t, msg in read_messages(run_dir / "episodes.mcap"):
            if topic == "/eval/robot":
                msg = {**msg, "urdf": "/elsewhere/iiwa7.urdf"}
            w.write(topic, msg, t)
            if topic == "/eval/tcp":
                w.write(
                    "/eval/ball",
                    {"episode": msg["episode"], "t": msg["t"], "position": [0.5, 0.0, msg["t"]]},
                    t,
                )
    assert main([str(src)]) == 0
    rows = rrd_rows(tmp_path / "episodes.rrd")
    assert len(column(rows, "/world/ball", "Points3D:positions")) == len(messages(src, "/eval/tcp"))
    assert any(e.startswith("/world/iiwa7/visual_geometries/") for e in rows)  # conf robot's URDF


def test_armar_urdf_is_sanitized_for_rerun(tmp_path):
    import rerun as rr
    from armar import get_path_to_urdf_file

    src = Path(get_path_to_urdf_file("armar6"))
    fixed = rv.sanitize_urdf(src, tmp_path)
    text = fixed.read_text()
    assert fixed != src and "package://" not in text and 'rpy="1.5707963, ' not in text
    tree = rr.urdf.UrdfTree.from_file_path(fixed)
    assert len([j for j in tree.joints() if j.joint_type != "fixed"]) == 17


def _no_channels(tmp: Path) -> Path:
    p = tmp / "other.mcap"
    with McapJsonWriter(p) as w:
        w.write("/foo", {"x": 1}, 0)
    return p


@pytest.mark.parametrize(
    "case", ["missing", "not_mcap", "no_channels", "bad_ids", "unknown_id", "save_two", "worst_on_run",
             "save_missing_dir"]
)
def test_bad_inputs_give_one_line_and_exit_2(case, run_dir, tmp_path, capsys):
    junk = tmp_path / "junk.mcap"
    junk.write_text("not an mcap\n")
    eps = str(run_dir / "episodes.mcap")
    argv = {
        "missing": [str(tmp_path / "nope")],
        "not_mcap": [str(junk)],
        "no_channels": [str(_no_channels(tmp_path))],
        "bad_ids": [eps, "--episodes", "1,x"],
        "unknown_id": [eps, "--episodes", "0,99"],
        "save_two": [str(run_dir), "--save", str(tmp_path / "x.rrd")],
        "worst_on_run": [str(run_dir / "run.mcap"), "--worst", "2"],
        "save_missing_dir": [eps, "--save", str(tmp_path / "no" / "such" / "dir.rrd")],
    }[case]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
