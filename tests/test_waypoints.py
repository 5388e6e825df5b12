"""Paths from users: CSV / NumPy waypoint files imported (round trip, degrees, joint-name headers, checked against
the robot), a straight line of evenly spaced waypoints has the line's length, and a single path file is followed,
evaluated and solved by TOPP-RA without a dataset built by hand."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pathrl.cli.dataset import main
from pathrl.dataset.io import DatasetError, load_dataset, load_pathset
from pathrl.dataset.waypoints import as_dataset, read_path_file
from pathrl.models import model_dir
from pathrl.paths.knots import KnotStrategy
from pathrl.robot.external import load_robot_by_name

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def iiwa():
    return load_robot_by_name("iiwa7")


def _inside(robot, k: int, seed: int = 0) -> np.ndarray:
    lim = robot.pos_limits[robot.path_index]
    t = np.random.default_rng(seed).uniform(0.2, 0.8, (k, len(lim)))
    return lim[:, 0] + t * (lim[:, 1] - lim[:, 0])


def test_csv_round_trip_with_a_joint_name_header(tmp_path, iiwa, capsys):
    knots = _inside(iiwa, 6)
    order = [3, 0, 6, 1, 5, 2, 4]  # columns in another order, named in the header
    rows = [",".join(iiwa.path_joints[j] for j in order)] + [",".join(repr(float(x)) for x in k[order]) for k in knots]
    src = tmp_path / "my_path.csv"
    src.write_text("\n".join(rows) + "\n")
    assert main(["import", "--format", "csv", "--robot", "iiwa7", str(src), str(tmp_path / "ds")]) == 0
    assert "inside" in capsys.readouterr().out
    ds = load_dataset(tmp_path / "ds", iiwa)
    assert list(ds.splits["test"].names) == ["my_path"]
    assert np.array_equal(ds.splits["test"].knots[0], knots)


def test_degrees_npy_directory_and_split(tmp_path, iiwa):
    a, b = _inside(iiwa, 4, 1), _inside(iiwa, 5, 2)
    (tmp_path / "src").mkdir()
    np.save(tmp_path / "src" / "b.npy", np.rad2deg(b))
    np.save(tmp_path / "src" / "a.npy", np.rad2deg(a))
    (tmp_path / "src" / "notes.md").write_text("not a path")
    assert main(["import", "--format", "npy", "--robot", "iiwa7", "--degrees", "--split", "train",
                 str(tmp_path / "src"), str(tmp_path / "ds")]) == 0
    sp = load_dataset(tmp_path / "ds").splits["train"]
    assert list(sp.names) == ["a", "b"]
    assert np.allclose(sp.knots[0], a, atol=1e-12) and np.allclose(sp.knots[1], b, atol=1e-12)


def test_evenly_spaced_waypoints_on_a_line_give_a_path_of_its_length(tmp_path, iiwa):
    """Hand-checkable: 11 waypoints from a to b on a straight joint-space line -> a path of length |b - a|."""
    a = np.zeros(7)
    b = np.array([0.3, -0.4, 0.0, 0.5, 0.0, 0.0, 1.2])  # |b - a| = sqrt(0.09 + 0.16 + 0.25 + 1.44) = 1.3928...
    np.savetxt(tmp_path / "line.csv", np.linspace(a, b, 11), delimiter=",")
    src, dest = tmp_path / "line.csv", tmp_path / "ds"
    assert main(["import", "--format", "csv", "--robot", "iiwa7", str(src), str(dest)]) == 0
    for strategy in (KnotStrategy("distance", 0.3), KnotStrategy("curvature", 0.3), KnotStrategy("file")):
        ps = load_pathset(tmp_path / "ds", "test", strategy, iiwa)
        assert float(ps.length[0]) == pytest.approx(np.sqrt(1.94), abs=1e-9)


@pytest.mark.parametrize(("content", "message"), [
    ("0,0,0,0,0,0,0\n0,0,0,3.5,0,0,0\n", "waypoint 2 is outside iiwa7's position range on iiwa_joint_4"),
    ("0,0,0,0,0,0\n1,1,1,1,1,1\n", r"waypoints must be \(K, 7\)"),
    ("0,0,0,0,0,0,0\n0,0,x,0,0,0,0\n", "waypoint 2: not a row of numbers"),
    ("0,0,0,0,0,0,0\n0,0,0,0,0,0,0\n", "at least two distinct waypoints"),
    ("0,0,0,0,0,0,0\n0,0,nan,0,0,0,0\n", "waypoint 2 is not finite"),
])
def test_bad_path_files_are_one_line_errors_and_write_nothing(tmp_path, capsys, content, message):
    src = tmp_path / "p.csv"
    src.write_text(content)
    assert main(["import", "--format", "csv", "--robot", "iiwa7", str(src), str(tmp_path / "ds")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert __import__("re").search(message, err), err
    assert not (tmp_path / "ds").exists()


def test_a_single_path_file_is_followed_evaluated_and_solved_by_toppra(tmp_path, iiwa, capsys):
    from pathrl.cli.evaluate import main as eval_main
    from pathrl.cli.toppra import main as toppra_main
    from pathrl.deploy import Follower

    knots = np.linspace(_inside(iiwa, 1, 3)[0], _inside(iiwa, 1, 4)[0], 6)
    src = tmp_path / "one.csv"
    np.savetxt(src, knots, delimiter=",")
    follower = Follower.load(model_dir("iiwa7_random"))
    follower.reset(read_path_file(src, iiwa))
    for _ in range(300):
        follower.decide()
        if follower.done:
            break
    assert follower.done and np.abs(follower.state[0] - knots[-1]).max() <= 0.005
    cache = as_dataset(src, iiwa, tmp_path / "cache")
    assert as_dataset(src, iiwa, tmp_path / "cache") == cache  # imported once
    assert toppra_main(["robot=iiwa7", f"dataset.path={src}", "segments=full", "workers=1",
                        f"out={tmp_path / 'toppra.json'}"]) == 0
    assert (tmp_path / "toppra.json").is_file()
    assert eval_main(["run_dir=" + str(model_dir("iiwa7_random")), f"dataset.path={src}", "segments=full",
                      f"out={tmp_path / 'eval'}"]) == 0
    capsys.readouterr()
    with pytest.raises(DatasetError, match="unknown path file type"):
        as_dataset(tmp_path / "toppra.json", iiwa)
