"""Import of the authors' episode JSON format (original_pathtracking.md 4.1): round trip and errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import make_interp_spline

from pathrl.dataset.io import DatasetError, load_dataset, load_pathset
from pathrl.dataset.kiemel import import_kiemel
from pathrl.paths.knots import KnotStrategy
from pathrl.robot.external import load_robot_by_name


def episode_dict(knots: np.ndarray) -> dict:
    """An episode file as the authors' Spline class writes it."""
    d = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(knots, axis=0), axis=1))]
    u = d / d[-1]
    bs = make_interp_spline(u, knots, bc_type="natural")
    return {
        "_b_spline": {"t": bs.t.tolist(), "c": bs.c.tolist(), "k": int(bs.k)},
        "_tck": None,
        "_u": u.tolist(),
        "_uncorrected_curve_length": float(d[-1]),
        "_length_correction_step_size": 2e-05,
        "_use_normalized_length_correction_step_size": False,
        "_curve_data_slicing_step": 1,
        "_method": "auto",
        "_curvature_at_ends": 0,
    }


def random_knots(rng, m=7):
    return np.cumsum(rng.normal(scale=0.15, size=(int(rng.integers(6, 20)), m)), axis=0)


def write_set(root: Path, rng, layout: dict[str, int], m=7) -> dict[str, dict[str, np.ndarray]]:
    out: dict[str, dict[str, np.ndarray]] = {}
    for sub, n in layout.items():
        d = root / sub if sub else root
        d.mkdir(parents=True, exist_ok=True)
        out[sub] = {}
        for i in range(n):
            k = random_knots(rng, m)
            name = f"episode_{i * 7 + 3}_{1000 + i}"
            (d / f"{name}.json").write_text(json.dumps(episode_dict(k)))
            out[sub][name] = k
    return out


@pytest.fixture
def iiwa():
    return load_robot_by_name("iiwa7")


def test_round_trip_train_test(tmp_path, iiwa):
    rng = np.random.default_rng(1)
    src = tmp_path / "random"
    truth = write_set(src, rng, {"train": 4, "test": 2})
    (src / "spline_config.json").write_text(json.dumps({"max_dis_between_knots": 0.92897, "num_train": 4}))
    ds = import_kiemel(src, tmp_path / "out", iiwa)
    assert ds.meta["source"] == "kiemel-json"
    assert ds.meta["reference_max_knot_gap"] == pytest.approx(0.92897)
    loaded = load_dataset(tmp_path / "out", iiwa)
    for split in ("train", "test"):
        names = sorted(truth[split])
        assert loaded.splits[split].names == tuple(names)
        for name, k in zip(names, loaded.splits[split].knots, strict=True):
            np.testing.assert_allclose(k, truth[split][name], atol=1e-9, rtol=0)
    # the file strategy gives the authors' knots back
    ps = load_pathset(tmp_path / "out", "test", KnotStrategy("file"), iiwa)
    first = truth["test"][sorted(truth["test"])[0]]
    np.testing.assert_allclose(ps.knots[0, : len(first)].numpy(), first, atol=1e-9)


def test_flat_dir_goes_to_test_and_config_in_parent(tmp_path, iiwa):
    rng = np.random.default_rng(2)
    (tmp_path / "set").mkdir()
    (tmp_path / "set" / "spline_config.json").write_text(json.dumps({"max_dis_between_knots": 1.5}))
    truth = write_set(tmp_path / "set" / "test", rng, {"": 3})
    ds = import_kiemel(tmp_path / "set" / "test", tmp_path / "out", iiwa)
    assert ds.meta["splits"] == {"train": 0, "test": 3}
    assert ds.meta["kind"] == "set"
    assert ds.meta["reference_max_knot_gap"] == 1.5
    assert ds.splits["test"].names == tuple(sorted(truth[""]))


def _one_file(tmp_path, mutate, m=7):
    rng = np.random.default_rng(3)
    src = tmp_path / "src"
    src.mkdir()
    d = episode_dict(random_knots(rng, m))
    mutate(d)
    (src / "episode_1_1.json").write_text(json.dumps(d))
    return src


def _del(key):
    def f(d):
        if "." in key:
            a, b = key.split(".")
            del d[a][b]
        else:
            del d[key]

    return f


def _nan(d):
    d["_b_spline"]["c"][2][1] = float("nan")


def _nonmono(d):
    d["_u"][2], d["_u"][3] = d["_u"][3], d["_u"][2]


def _huge(d):
    """Coefficients 1e9 x: evaluated and tabulated, this path asked for a 35 TiB arc-length table (issue 50)."""
    d["_b_spline"]["c"] = (np.asarray(d["_b_spline"]["c"]) * 1e9).tolist()


def _long(d):
    """Knots inside the coefficient bound, but zig-zagging 4000 times between +-50 rad: 4e5 rad of path."""
    u = np.linspace(0.0, 1.0, 4001)
    knots = np.zeros((4001, 7))
    knots[:, 0] = np.where(np.arange(4001) % 2, 50.0, -50.0)
    d["_b_spline"] = {"t": np.r_[0.0, u, 1.0].tolist(), "c": knots.tolist(), "k": 1}
    d["_u"] = u.tolist()


@pytest.mark.parametrize(
    "mutate, match",
    [
        (_del("_b_spline"), "missing key '_b_spline'"),
        (_del("_u"), "missing key '_u'"),
        (_del("_b_spline.c"), r"missing key '_b_spline\.c'"),
        (_del("_b_spline.t"), r"missing key '_b_spline\.t'"),
        (_nan, "NaN"),
        (_nonmono, "not strictly increasing"),
        (lambda d: d.__setitem__("_u", d["_u"][:1]), "at least 2"),
        (lambda d: d["_b_spline"].__setitem__("t", d["_b_spline"]["t"][:-1]), "inconsistent B-spline"),
        (_huge, "beyond 100 rad"),
        (_long, "at most 1000 rad"),
        (lambda d: d["_b_spline"].__setitem__("k", 10**9), "expected 1 to 5"),
    ],
)
def test_errors(tmp_path, iiwa, mutate, match):
    src = _one_file(tmp_path, mutate)
    with pytest.raises(DatasetError, match=match) as exc:
        import_kiemel(src, tmp_path / "out", iiwa)
    msg = str(exc.value)
    assert "episode_1_1.json" in msg and "\n" not in msg
    assert not (tmp_path / "out").exists()


def test_wrong_joint_count(tmp_path, iiwa):
    src = _one_file(tmp_path, lambda d: None, m=17)
    with pytest.raises(DatasetError, match="17 joints, robot has 7"):
        import_kiemel(src, tmp_path / "out", iiwa)


def test_invalid_json_and_empty_dir(tmp_path, iiwa):
    src = tmp_path / "src"
    src.mkdir()
    with pytest.raises(DatasetError, match="no episode_"):
        import_kiemel(src, tmp_path / "out", iiwa)
    (src / "episode_1.json").write_text("{")
    with pytest.raises(DatasetError, match="episode_1.json: invalid JSON"):
        import_kiemel(src, tmp_path / "out", iiwa)
    with pytest.raises(DatasetError, match="source directory not found"):
        import_kiemel(tmp_path / "missing", tmp_path / "out", iiwa)


def test_reflections_store_every_path_once_per_sign_pattern(tmp_path, iiwa):
    """--reflections: the authors' ball evaluation drew one of the set's reflection vectors per episode; the import
    stores each path times each vector, named <name>_r<i>."""
    rng = np.random.default_rng(4)
    src = tmp_path / "ball"
    truth = write_set(src, rng, {"test": 2})
    signs = [[1] * 7, [-1] * 7, [-1, 1, -1, 1, -1, 1, -1]]
    (src / "spline_config.json").write_text(json.dumps({"max_dis_between_knots": 0.32, "reflection_vectors": signs}))
    ds = import_kiemel(src, tmp_path / "out", iiwa, reflections=True)
    assert ds.meta["reflections"] is True and ds.meta["splits"] == {"train": 0, "test": 6}
    loaded = load_dataset(tmp_path / "out", iiwa).splits["test"]
    got = dict(zip(loaded.names, loaded.knots, strict=True))
    for name, k in truth["test"].items():
        for i, v in enumerate(signs):
            np.testing.assert_allclose(got[f"{name}_r{i}"], k * np.asarray(v), atol=1e-9, rtol=0)


@pytest.mark.parametrize("vectors, match", [(None, "no 'reflection_vectors'"), ([[1, -1]], "7 values of \\+1 or -1"),
                                            ([[1, 1, 1, 1, 1, 1, 0.5]], "7 values")])
def test_reflections_need_valid_sign_patterns(tmp_path, iiwa, vectors, match):
    src = tmp_path / "ball"
    write_set(src, np.random.default_rng(5), {"test": 1})
    cfg = {"max_dis_between_knots": 0.32} | ({"reflection_vectors": vectors} if vectors else {})
    (src / "spline_config.json").write_text(json.dumps(cfg))
    with pytest.raises(DatasetError, match=match):
        import_kiemel(src, tmp_path / "out", iiwa, reflections=True)
    assert not (tmp_path / "out").exists()
