"""On-disk dataset format: round trip, hash, validation errors, knot-strategy cache."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pathrl.dataset.io import (
    CACHE_DIR,
    FORMAT,
    DatasetError,
    apply_strategy,
    load_dataset,
    load_pathset,
    save_dataset,
)
from pathrl.dataset.stats import dataset_stats
from pathrl.paths.knots import KnotStrategy
from pathrl.robot.external import load_robot_by_name


def _paths(rng, n, m=7, prefix="p"):
    out = []
    for i in range(n):
        k = rng.integers(5, 30)
        steps = rng.normal(scale=0.1, size=(k, m))
        out.append((f"{prefix}{i:03d}", np.cumsum(steps, axis=0)))
    return out


META = {"robot": "iiwa7", "kind": "random", "seed": 3, "generator": {"kind": "random"}, "source": "generated"}


@pytest.fixture
def splits():
    rng = np.random.default_rng(0)
    return {"train": _paths(rng, 4), "test": _paths(rng, 2, prefix="q")}


def test_round_trip(tmp_path, splits):
    dest = tmp_path / "ds"
    ds = save_dataset(dest, splits, META)
    assert (dest / "dataset.json").is_file() and (dest / "train.npz").is_file()
    meta = json.loads((dest / "dataset.json").read_text())
    assert meta["format"] == FORMAT and meta["splits"] == {"train": 4, "test": 2}
    assert meta["stats"]["train"]["stored"]["count"] == 4
    loaded = load_dataset(dest, load_robot_by_name("iiwa7"))
    assert loaded.content_hash == ds.content_hash == meta["content_hash"]
    for split, paths in splits.items():
        assert loaded.splits[split].names == tuple(n for n, _ in paths)
        for (_, k), k2 in zip(paths, loaded.splits[split].knots, strict=True):
            np.testing.assert_array_equal(k, k2)
    # no temp dirs left behind
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def test_no_overwrite_without_flag(tmp_path, splits):
    dest = tmp_path / "ds"
    ds1 = save_dataset(dest, splits, META)
    with pytest.raises(DatasetError, match="already exists"):
        save_dataset(dest, splits, META)
    small = {"train": splits["train"][:2], "test": splits["test"]}
    ds2 = save_dataset(dest, small, META, overwrite=True)
    assert ds2.content_hash != ds1.content_hash
    assert load_dataset(dest).meta["splits"]["train"] == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def test_refuses_to_overwrite_foreign_dir(tmp_path, splits):
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "precious.txt").write_text("keep")
    with pytest.raises(DatasetError, match="not a pathrl dataset"):
        save_dataset(tmp_path / "x", splits, META, overwrite=True)
    assert (tmp_path / "x" / "precious.txt").read_text() == "keep"


def test_corruption_detected(tmp_path, splits):
    dest = tmp_path / "ds"
    save_dataset(dest, splits, META)
    arr = dict(np.load(dest / "test.npz"))
    arr["knots"] = arr["knots"].copy()
    arr["knots"][3, 2] += 1e-6
    np.savez(dest / "test.npz", **arr)
    with pytest.raises(DatasetError, match="content hash mismatch") as exc:
        load_dataset(dest)
    assert "test.npz" in str(exc.value) and "\n" not in str(exc.value)


def test_truncated_file_detected(tmp_path, splits):
    dest = tmp_path / "ds"
    save_dataset(dest, splits, META)
    data = (dest / "train.npz").read_bytes()
    (dest / "train.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(DatasetError, match="train.npz"):
        load_dataset(dest)


def test_load_errors(tmp_path, splits):
    with pytest.raises(DatasetError, match="not found"):
        load_dataset(tmp_path / "nope")
    dest = tmp_path / "ds"
    save_dataset(dest, splits, META)
    # wrong joint count for the robot
    with pytest.raises(DatasetError, match="7 joints but robot 'armar6' has 17"):
        load_dataset(dest, load_robot_by_name("armar6"))
    # wrong format tag
    meta = json.loads((dest / "dataset.json").read_text())
    (dest / "dataset.json").write_text(json.dumps({**meta, "format": "other/9"}))
    with pytest.raises(DatasetError, match="unsupported format"):
        load_dataset(dest)
    (dest / "dataset.json").write_text("{nope")
    with pytest.raises(DatasetError, match="invalid JSON"):
        load_dataset(dest)
    (dest / "dataset.json").write_text(json.dumps(meta))
    (dest / "test.npz").unlink()
    with pytest.raises(DatasetError, match="test.npz: split file missing"):
        load_dataset(dest)


@pytest.mark.parametrize(
    "bad, match",
    [
        ([("a", np.array([[0.0, 1.0], [np.nan, 2.0]]))], "NaN"),
        ([("a", np.array([[0.0, 1.0], [0.0, 1.0]]))], "two distinct knots"),
        ([("a", np.array([[0.0, 1.0]]))], "two distinct knots|K>=2"),
        ([("a", np.eye(2)), ("a", np.eye(2) * 2)], "duplicate path name"),
        ([("", np.eye(2))], "invalid path name"),
        ([("a", np.eye(2)), ("b", np.eye(3))], "joints"),
        ([("a", np.array([[0.0, 0.0], [1e6, 0.0]]))], "beyond 100 rad"),  # mrad or degrees, not rad
        ([("a", np.tile([[0.0], [99.0]], (12, 1)))], "at most 1000 rad"),  # 1089 rad of back and forth
    ],
)
def test_save_validates(tmp_path, bad, match):
    with pytest.raises(DatasetError, match=match):
        save_dataset(tmp_path / "ds", {"train": bad, "test": []}, META)
    assert not (tmp_path / "ds").exists()


def test_hand_written_invalid_knots_detected(tmp_path):
    """A split file written without save_dataset (valid hash) but with NaN knots is rejected on load."""
    from pathrl.dataset.io import content_hash, pack

    dest = tmp_path / "ds"
    dest.mkdir()
    arr = pack([("a", np.array([[0.0, 0.0], [1.0, np.nan], [2.0, 0.0]]))])
    np.savez(dest / "test.npz", **arr)
    meta = {"format": FORMAT, "splits": {"test": 1}, "content_hash": content_hash({"test": arr})}
    (dest / "dataset.json").write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match=r"test\.npz.*NaN"):
        load_dataset(dest)


def test_hand_written_huge_knots_are_refused_before_any_tabulation(tmp_path):
    """Finite but huge knots (a native file written by hand) are refused on load, so dataset.out_of_limits=clip never
    tabulates a path of 10^6 rad."""
    from pathrl.dataset.io import content_hash, pack

    dest = tmp_path / "ds"
    dest.mkdir()
    arr = pack([("a", np.array([[0.0, 0.0], [1e6, 0.0], [2.0, 0.0]]))])
    np.savez(dest / "test.npz", **arr)
    meta = {"format": FORMAT, "splits": {"test": 1}, "content_hash": content_hash({"test": arr})}
    (dest / "dataset.json").write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match=r"test\.npz.*beyond 100 rad"):
        load_dataset(dest)


def test_stats():
    line = np.linspace([0.0, 0.0], [3.0, 4.0], 6)  # length 5, knot gap 1
    st = dataset_stats([line, line[:3]])
    assert st["count"] == 2
    assert st["knots"] == {"min": 3, "mean": 4.5, "max": 6}
    assert st["length"]["max"] == pytest.approx(5.0, abs=1e-6)
    assert st["length"]["min"] == pytest.approx(2.0, abs=1e-6)
    assert st["max_knot_gap"] == pytest.approx(1.0, abs=1e-6)


def test_load_pathset_and_cache(tmp_path, splits):
    dest = tmp_path / "ds"
    save_dataset(dest, splits, META)
    strat = KnotStrategy("distance", spacing=0.2)
    ps = load_pathset(dest, "train", strat, load_robot_by_name("iiwa7"))
    assert ps.names == tuple(n for n, _ in splits["train"])
    assert ps.num_paths == 4 and ps.dof == 7
    cache = list((dest / CACHE_DIR).glob("train-*-distance_0.2.npz"))
    assert len(cache) == 1
    # second load uses the cache: identical knots
    ps2 = load_pathset(dest, "train", strat)
    np.testing.assert_array_equal(ps.knots.numpy(), ps2.knots.numpy())
    # a damaged cache entry is recomputed, not trusted
    cache[0].write_bytes(b"garbage")
    ps3 = load_pathset(dest, "train", strat)
    np.testing.assert_allclose(ps.knots.numpy(), ps3.knots.numpy())
    # the file strategy keeps the stored knots
    ds = load_dataset(dest)
    kept = apply_strategy(ds, "test", KnotStrategy("file"))
    np.testing.assert_array_equal(kept[0], splits["test"][0][1])
    with pytest.raises(DatasetError, match="no split 'val'"):
        load_pathset(dest, "val", strat)


def test_paths_leaving_the_position_limits_are_refused_or_clipped(tmp_path, capsys):
    import os
    import stat

    from pathrl.dataset.io import DatasetError, load_pathset
    from pathrl.dataset.limits import limit_excess
    from pathrl.dataset.synthetic import smooth_paths
    from pathrl.paths.knots import KnotStrategy
    from pathrl.robot.external import load_robot_by_name

    robot = load_robot_by_name("iiwa7")
    paths = smooth_paths(robot, 3, 0)
    hi = robot.pos_limits[robot.path_index][2, 1]
    paths[1][1][5, 2] = hi + 0.003  # 3 mrad past joint 3's upper limit, as released third-party sets do
    meta = {"robot": "iiwa7", "kind": "synthetic", "path_joints": list(robot.path_joints), "seed": 0}
    ds = save_dataset(tmp_path / "d", {"test": paths}, meta)
    ex = limit_excess(ds.splits["test"].knots, robot)
    assert ex["paths_outside"] == 1 and ex["joint"] == robot.path_joints[2]
    assert abs(ex["max_excess_rad"] - 0.003) < 1e-12
    strategy = KnotStrategy("curvature", 0.3)
    with pytest.raises(DatasetError, match=r"1 of 3 paths leave robot 'iiwa7'.*3 mrad.*out_of_limits=clip"):
        load_pathset(ds.path, "test", strategy, robot=robot)
    ps = load_pathset(ds.path, "test", strategy, robot=robot, out_of_limits="clip")
    assert "clipped" in capsys.readouterr().err
    assert float(ps.knots[:, :, 2].max()) <= hi
    load_pathset(ds.path, "test", strategy)  # no robot given: nothing to check against
    with pytest.raises(DatasetError, match="out_of_limits must be one of"):
        load_pathset(ds.path, "test", strategy, robot=robot, out_of_limits="ignore")
    # a new dataset directory gets the mode of any new directory, not mkdtemp's 0700
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(os.stat(ds.path).st_mode) == 0o777 & ~umask


def test_clip_also_clips_a_spline_that_leaves_the_range_between_inside_knots(tmp_path):
    """Every knot inside, the natural spline through a step overshoots the upper limit: refused by default, and
    dataset.out_of_limits=clip (which the refusal suggests) keeps the whole tabulated spline inside."""
    from pathrl.dataset.io import load_pathset
    from pathrl.paths.knots import KnotStrategy
    from pathrl.robot.external import load_robot_by_name

    robot = load_robot_by_name("iiwa7")
    hi = robot.pos_limits[robot.path_index][2, 1]
    t = np.linspace(0.0, 1.0, 9)
    k = np.zeros((9, robot.path_dof))
    k[:, 0] = np.linspace(-0.5, 0.5, 9)
    k[:, 2] = np.where(t < 0.5, hi - 0.5, hi - 0.001)  # a step up to 1 mrad below the limit
    meta = {"robot": "iiwa7", "kind": "synthetic", "path_joints": list(robot.path_joints), "seed": 0}
    ds = save_dataset(tmp_path / "d", {"test": [("a", k)]}, meta)
    strategy = KnotStrategy("curvature", 0.3)
    with pytest.raises(DatasetError, match=r"1 of 1 paths leave the position range.*out_of_limits=clip"):
        load_pathset(ds.path, "test", strategy, robot=robot)
    ps = load_pathset(ds.path, "test", strategy, robot=robot, out_of_limits="clip")
    assert float(ps.table[..., 2].max()) <= hi
