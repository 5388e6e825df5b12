"""Dataset generators: invariants of generated paths (limits, collisions, lengths, ball constraints)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from pathrl.config.paths import CONF_DIR
from pathrl.datagen.generate import generate_dataset
from pathrl.datagen.generators.ball_balancing import ball_constraint_violation
from pathrl.datagen.generators.defaults import resolve_params
from pathrl.dataset.io import DatasetError, load_dataset, load_pathset
from pathrl.paths.knots import KnotStrategy
from pathrl.paths.spline import sample_uniform
from pathrl.robot.external import load_robot_by_name

torch.set_num_threads(1)


def robot_cfg(name: str) -> dict:
    return OmegaConf.to_container(OmegaConf.load(CONF_DIR / "robot" / f"{name}.yaml"), resolve=True)


def dataset_cfg(kind: str, **params) -> dict:
    cfg = OmegaConf.to_container(OmegaConf.load(CONF_DIR / "dataset" / f"{kind}.yaml"), resolve=False)
    cfg.update(num_train=4, num_test=2, seed=5, params={"chunk_size": 2, **params})
    return cfg


@pytest.fixture(scope="module")
def checker():
    from pathrl.robot.collision import CollisionChecker

    cc = CollisionChecker(load_robot_by_name("iiwa7"))
    yield cc
    cc.close()


def _check_paths(ds, spec, checker, lo, hi, step=0.02, tol=1e-6):
    for split, n in (("train", 4), ("test", 2)):
        sp = ds.splits[split]
        assert len(sp) == n
        for knots in sp.knots:
            q, length = sample_uniform(knots, step)
            assert lo - 0.1 <= length <= hi + 0.05, length
            assert np.all(q >= spec.pos_limits[:, 0] - tol) and np.all(q <= spec.pos_limits[:, 1] + tol)
            assert not checker.in_collision(q).any()
    # train and test come from disjoint streams
    assert not any(np.array_equal(a, b) for a in ds.splits["train"].knots for b in ds.splits["test"].knots)


@pytest.mark.parametrize("kind, length", [("random", [4.0, 5.0]), ("target_point", [5.0, 6.0])])
def test_limit_respecting_generators(tmp_path, checker, kind, length):
    spec = load_robot_by_name("iiwa7")
    ds = generate_dataset(
        robot_cfg("iiwa7"), dataset_cfg(kind, length_range=length), dest=tmp_path / kind, progress=False
    )
    loaded = load_dataset(tmp_path / kind, spec)
    assert loaded.content_hash == ds.content_hash
    assert loaded.meta["kind"] == kind and loaded.meta["seed"] == 5
    assert loaded.meta["generator"]["params"]["length_range"] == length
    _check_paths(loaded, spec, checker, *length)
    # stored knots are distance-resampled at 0.1 rad
    gaps = np.linalg.norm(np.diff(loaded.splits["test"].knots[0], axis=0), axis=1)
    assert np.median(gaps) == pytest.approx(0.1, abs=0.005)
    # the default (curvature) strategy was cached at generation: loading it needs no resampling
    assert list((tmp_path / kind / ".cache").glob("test-*-curvature_0.3_0.1.npz"))
    ps = load_pathset(tmp_path / kind, "test", KnotStrategy("curvature", 0.3), spec)
    assert ps.num_paths == 2
    # deterministic: same seed -> same content
    ds2 = generate_dataset(
        robot_cfg("iiwa7"), dataset_cfg(kind, length_range=length), dest=tmp_path / "again", progress=False
    )
    assert ds2.content_hash == ds.content_hash


def test_ball_balancing_paths_keep_plate_horizontal(tmp_path, checker):
    from pathrl.robot.kinematics import ForwardKinematics

    spec = load_robot_by_name("iiwa7")
    generate_dataset(robot_cfg("iiwa7"), dataset_cfg("ball_balancing"), dest=tmp_path / "ball", progress=False)
    ds = load_dataset(tmp_path / "ball", spec)
    _check_paths(ds, spec, checker, 3.2, 5.1, tol=1e-9)
    fk = ForwardKinematics(spec)
    for knots in ds.splits["train"].knots + ds.splits["test"].knots:
        q, _ = sample_uniform(knots, 0.01)
        assert ball_constraint_violation(q).max() < 1e-9
        assert np.abs(q[:, 6]).max() <= 0.009
        _, rot = fk.link_transforms(torch.as_tensor(q), ["iiwa_link_7"])
        z_axis = rot[:, 0, :, 2].numpy()  # flange z axis in the base frame
        np.testing.assert_allclose(z_axis, np.tile([0.0, 0.0, 1.0], (len(q), 1)), atol=1e-9)
        gaps = np.linalg.norm(np.diff(knots, axis=0), axis=1)
        assert np.median(gaps) == pytest.approx(0.3, abs=0.01)


def test_ball_balancing_rejects_other_robots(tmp_path):
    with pytest.raises(DatasetError, match="iiwa7 only"):
        generate_dataset(robot_cfg("armar6"), dataset_cfg("ball_balancing"), dest=tmp_path / "x", progress=False)
    assert not (tmp_path / "x").exists()


def test_params_validation():
    p = resolve_params("random", "armar4", {})
    assert p["length_range"] == [18.0, 22.9]
    assert resolve_params("random", "unknown_robot", {})["length_range"] == [19.5, 26.0]
    with pytest.raises(DatasetError, match="unknown keys"):
        resolve_params("random", "iiwa7", {"lenght_range": [1, 2]})
    with pytest.raises(DatasetError, match="length_range"):
        resolve_params("random", "iiwa7", {"length_range": [5, 1]})
    with pytest.raises(DatasetError, match="unknown generator"):
        resolve_params("spiral", "iiwa7", {})


@pytest.mark.parametrize("kind", ["random", "target_point", "ball_balancing"])
def test_conf_params_match_code_defaults(kind):
    from pathrl.datagen.generators.defaults import DEFAULT_PARAMS

    cfg = OmegaConf.to_container(OmegaConf.load(CONF_DIR / "dataset" / f"{kind}.yaml"))
    assert cfg["params"] == DEFAULT_PARAMS[kind]


def test_parallel_workers_give_identical_dataset(tmp_path):
    """Chunks are seeded independently: 2 worker processes produce the same bytes as 1."""
    cfg = dataset_cfg("ball_balancing")
    one = generate_dataset(robot_cfg("iiwa7"), cfg, dest=tmp_path / "w1", workers=1, progress=False)
    two = generate_dataset(robot_cfg("iiwa7"), cfg, dest=tmp_path / "w2", workers=2, progress=False)
    assert one.content_hash == two.content_hash
    assert two.meta["generation"]["workers"] == 2


@pytest.mark.parametrize("approach", ["pursuit", "pd"])
def test_target_point_approaches(tmp_path, checker, approach):
    """The non-default target-point motions also give valid paths of the requested length."""
    spec = load_robot_by_name("iiwa7")
    cfg = dataset_cfg("target_point", length_range=[5.0, 6.0], approach=approach)
    ds = generate_dataset(robot_cfg("iiwa7"), cfg, dest=tmp_path / approach, progress=False)
    assert ds.meta["generator"]["params"]["approach"] == approach
    _check_paths(load_dataset(tmp_path / approach, spec), spec, checker, 5.0, 6.0)


@pytest.mark.parametrize("params, msg", [({"approach": "teleport"}, "approach"), ({"cruise": 0.0}, "cruise")])
def test_target_point_bad_params(tmp_path, params, msg):
    with pytest.raises(DatasetError, match=msg):
        generate_dataset(robot_cfg("iiwa7"), dataset_cfg("target_point", **params), dest=tmp_path / "x",
                         progress=False)
    assert not (tmp_path / "x").exists()


def test_action_smoothing_range_is_checked():
    assert resolve_params("random", "iiwa7", {"action_smoothing": [0.0, 0.995]})["action_smoothing"] == [0.0, 0.995]
    for bad in (1.0, -0.1, [0.5, 0.2], [0.1, 0.2, 0.3], "x"):
        with pytest.raises(DatasetError, match="action_smoothing"):
            resolve_params("random", "iiwa7", {"action_smoothing": bad})


def test_draw_smoothing_is_log_uniform_in_one_minus_rho():
    """1 - rho log-uniform on [1 - hi, 1 - lo]: inside the range, median sqrt((1 - lo)(1 - hi)), each decade of the
    correlation time equally common."""
    from pathrl.datagen.generators.random import draw_smoothing

    rho = draw_smoothing(0.0, 0.99, 200_000, torch.Generator().manual_seed(0)).squeeze(1)
    assert rho.shape == (200_000,) and rho.min() >= 0.0 and rho.max() <= 0.99
    assert abs(float((1 - rho).median()) - 0.1) < 0.002  # sqrt(1 * 0.01)
    assert abs(float((rho < 0.9).double().mean()) - 0.5) < 0.005  # 1 - rho in [0.1, 1]: one of two decades


def test_broad_random_paths_are_straighter(tmp_path, checker):
    """Actions smoothed near rho = 1 make long straight-ish sweeps: wider curvature-knot gaps than independent
    actions on the same seeds, and the paths still keep the limits and avoid collisions."""
    spec = load_robot_by_name("iiwa7")
    ks = KnotStrategy(strategy="curvature", spacing=0.3, base_spacing=0.1, n_state=9)
    widest = {}
    for name, rho in (("independent", 0.0), ("smooth", [0.99, 0.995])):
        cfg = dataset_cfg("random", length_range=[6.0, 7.0], action_smoothing=rho)
        generate_dataset(robot_cfg("iiwa7"), cfg, dest=tmp_path / name, progress=False)
        _check_paths(load_dataset(tmp_path / name, spec), spec, checker, 6.0, 7.0)
        ps = load_pathset(tmp_path / name, "train", ks)
        knots = zip(ps.knots.numpy(), ps.num_knots.tolist(), strict=True)
        gaps = [np.linalg.norm(np.diff(k[:n], axis=0), axis=1) for k, n in knots]
        widest[name] = float(np.quantile(np.concatenate(gaps), 0.9))
    assert widest["smooth"] > 1.3 * widest["independent"], widest


def test_ball_sweep_paths_sweep_the_base_and_keep_the_plate_horizontal(tmp_path, checker):
    """The authors'-shape options: start in the start region, q1 never turns back (before a reflection flips it), and
    every reflected path still keeps the plate horizontal and passes the checks."""
    from pathrl.datagen.generators.ball_balancing import REFLECTIONS

    spec = load_robot_by_name("iiwa7")
    cfg = OmegaConf.to_container(OmegaConf.load(CONF_DIR / "dataset" / "ball_balancing_sweep.yaml"), resolve=False)
    cfg.pop("defaults")
    params = {**cfg["params"], "chunk_size": 4}
    generate_dataset(robot_cfg("iiwa7"), dataset_cfg("ball_balancing", **params), dest=tmp_path / "s", progress=False)
    ds = load_dataset(tmp_path / "s", spec)
    _check_paths(ds, spec, checker, 3.2, 5.1, tol=1e-9)
    start_q1 = np.asarray(params["start_region"][0])
    for knots in ds.splits["train"].knots + ds.splits["test"].knots:
        q, _ = sample_uniform(knots, 0.01)
        assert ball_constraint_violation(q).max() < 1e-9
        signs = [s for s in REFLECTIONS if start_q1[0] - 1e-9 <= s[0] * knots[0, 0] <= start_q1[1] + 1e-9]
        assert signs, "the start's q1 is in the start region up to a reflection"
        base = knots * signs[0]  # undo the reflection
        # one way, up to the spline's overshoot where the base stops at the region's end (up to a few centiradians)
        assert np.all(np.diff(base[:, 0]) >= -0.05), "q1 sweeps one way"
        assert base[:, 0].max() <= params["region"][0][1] + 0.05


def test_ball_region_params_are_checked():
    from pathrl.datagen.generators.ball_balancing import region_box, step_weights

    lim = load_robot_by_name("iiwa7").pos_limits
    np.testing.assert_allclose(region_box(lim, None), lim[[0, 1, 3]])
    np.testing.assert_allclose(region_box(lim, [[-9, 0], [0, 1], [1, 9]])[[0, 2]], [[lim[0, 0], 0], [1, lim[3, 1]]])
    with pytest.raises(DatasetError, match="start_region: expected three"):
        region_box(lim, [[0, 1]])
    with pytest.raises(DatasetError, match="region: .* outside the position limits"):
        region_box(lim, [[5, 6], [0, 1], [0, 1]], "region")
    np.testing.assert_allclose(step_weights(None), np.ones(3))
    with pytest.raises(DatasetError, match="step_weights"):
        step_weights([1.0, 0.0, 1.0])
