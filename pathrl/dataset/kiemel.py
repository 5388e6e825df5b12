"""Import datasets in the format of the paper's original code (Kiemel et al., ``tracking/dataset``).

Source layout (original_pathtracking.md 4.1, 9.1)::

    SRC_DIR/spline_config.json          (or in SRC_DIR's parent) with max_dis_between_knots
    SRC_DIR/train/episode_*.json        and SRC_DIR/test/episode_*.json,  or
    SRC_DIR/episode_*.json              (then all files go to the ``test`` split)

Each episode file holds ``_b_spline`` = {t, c, k} (scipy BSpline, c: (K+2) x M) and ``_u`` (the knots'
chord-length parameters); the knot positions are ``BSpline(t, c, k)(_u)``. The knots are stored as
they are (the authors' curvature / distance resampling was already applied), so load imported sets
with the ``file`` knot strategy to reproduce the authors' knots exactly. The source file's stem is the
path's name; files are processed in sorted order.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from scipy.interpolate import BSpline

from pathrl.dataset.io import MAX_KNOT_RAD, MAX_PATH_LENGTH_RAD, Dataset, DatasetError, check_destination, save_dataset
from pathrl.dataset.stats import dataset_stats
from pathrl.robot.model import RobotSpec

__all__ = ["MAX_KNOTS", "find_spline_config", "import_kiemel", "read_episode", "reflection_vectors"]

SPLINE_CONFIG = "spline_config.json"

#: Knots or coefficients an episode file may hold (the committed sets: <= 300), checked before anything is evaluated;
#: values and length are bounded by MAX_KNOT_RAD and MAX_PATH_LENGTH_RAD of pathrl.dataset.io. A B-spline lies in
#: the convex hull of its coefficients, so coefficients within MAX_KNOT_RAD bound the path.
MAX_KNOTS = 100_000


def read_episode(path: Path, path_dof: int | None = None) -> np.ndarray:
    """Knot positions (K, M) of one authors' episode file. Raises a one-line DatasetError."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{path}: invalid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise DatasetError(f"{path}: expected a JSON object")
    for key in ("_b_spline", "_u"):
        if key not in data or data[key] is None:
            raise DatasetError(f"{path}: missing key {key!r}")
    bs = data["_b_spline"]
    if not isinstance(bs, dict):
        raise DatasetError(f"{path}: '_b_spline' must be an object with t, c, k")
    for key in ("t", "c", "k"):
        if key not in bs or bs[key] is None:
            raise DatasetError(f"{path}: missing key '_b_spline.{key}'")
    try:
        t = np.asarray(bs["t"], dtype=np.float64)
        c = np.asarray(bs["c"], dtype=np.float64)
        u = np.asarray(data["_u"], dtype=np.float64)
        k = int(bs["k"])
    except (TypeError, ValueError) as exc:
        raise DatasetError(f"{path}: non-numeric spline data ({exc})") from None
    if t.ndim != 1 or u.ndim != 1 or c.ndim != 2:
        raise DatasetError(f"{path}: expected 1-D '_b_spline.t' and '_u' and 2-D '_b_spline.c'")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(c)) and np.all(np.isfinite(u))):
        raise DatasetError(f"{path}: NaN or inf in '_b_spline' or '_u'")
    if len(u) > MAX_KNOTS or len(c) > MAX_KNOTS:
        raise DatasetError(f"{path}: {max(len(u), len(c))} knots or coefficients; at most {MAX_KNOTS} are imported")
    if c.size and np.abs(c).max() > MAX_KNOT_RAD:
        raise DatasetError(f"{path}: spline coefficient {np.abs(c).max():.3g} rad is beyond {MAX_KNOT_RAD:g} rad "
                           "(not joint positions in rad?)")
    if path_dof is not None and c.shape[1] != path_dof:
        raise DatasetError(f"{path}: spline has {c.shape[1]} joints, robot has {path_dof} path joints")
    if len(u) < 2:
        raise DatasetError(f"{path}: '_u' needs at least 2 knot parameters, got {len(u)}")
    if np.any(np.diff(u) <= 0):
        raise DatasetError(f"{path}: '_u' is not strictly increasing")
    if not 1 <= k <= 5:
        raise DatasetError(f"{path}: B-spline degree k={k}; expected 1 to 5 (the authors' splines are cubic)")
    if len(t) != c.shape[0] + k + 1:
        raise DatasetError(f"{path}: inconsistent B-spline: len(t)={len(t)}, len(c)={c.shape[0]}, k={k}")
    if np.any(np.diff(t) < 0):
        raise DatasetError(f"{path}: '_b_spline.t' is not non-decreasing")
    if u[0] < t[k] - 1e-12 or u[-1] > t[-k - 1] + 1e-12:
        raise DatasetError(f"{path}: '_u' outside the spline's domain [{t[k]}, {t[-k - 1]}]")
    knots = BSpline(t, c, k)(u)
    if not np.all(np.isfinite(knots)):
        raise DatasetError(f"{path}: spline evaluates to NaN at '_u'")
    gaps = np.linalg.norm(np.diff(knots, axis=0), axis=1)
    if np.all(gaps <= 1e-9):
        raise DatasetError(f"{path}: path has fewer than two distinct knots")
    if gaps.sum() > MAX_PATH_LENGTH_RAD:
        raise DatasetError(f"{path}: path through the knots is {gaps.sum():.3g} rad long; at most "
                           f"{MAX_PATH_LENGTH_RAD:g} rad are imported")
    return knots


def find_spline_config(src: Path) -> tuple[Path | None, dict[str, Any]]:
    """``spline_config.json`` in `src` or its parent: (its path, its settings), or (None, {}) if there is none;
    DatasetError if invalid."""
    for d in (src, src.parent):
        p = d / SPLINE_CONFIG
        if p.is_file():
            try:
                cfg = json.loads(p.read_text())
            except (OSError, ValueError) as exc:
                raise DatasetError(f"{p}: invalid JSON ({exc})") from None
            if not isinstance(cfg, dict):
                raise DatasetError(f"{p}: expected a JSON object")
            gap = cfg.get("max_dis_between_knots")
            if gap is not None and not (isinstance(gap, (int, float)) and np.isfinite(gap) and gap > 0):
                raise DatasetError(f"{p}: 'max_dis_between_knots' must be a positive number, got {gap!r}")
            return p, cfg
    return None, {}


def reflection_vectors(cfg: dict[str, Any], path_dof: int, where: Path) -> np.ndarray:
    """(R, M) joint sign patterns of a ``spline_config.json``'s ``reflection_vectors``; DatasetError if it has none or
    they are not +-1 vectors of the path's M joints (`where` names the file in the message)."""
    vectors = cfg.get("reflection_vectors")
    if not vectors:
        raise DatasetError(f"{where}: no 'reflection_vectors' in spline_config.json (--reflections needs them)")
    try:
        v = np.asarray(vectors, dtype=np.float64)
    except (TypeError, ValueError):
        v = np.zeros(0)
    if v.ndim != 2 or v.shape[1] != path_dof or not np.all(np.abs(v) == 1.0):
        raise DatasetError(f"{where}: 'reflection_vectors' must be lists of {path_dof} values of +1 or -1")
    return v


def import_kiemel(
    src_dir: str | os.PathLike,
    dest: str | os.PathLike,
    robot: RobotSpec,
    overwrite: bool = False,
    kind: str | None = None,
    reflections: bool = False,
) -> Dataset:
    """Convert an authors'-format dataset directory into a pathrl dataset at `dest` (atomic). With `reflections`,
    every path is stored once per ``reflection_vectors`` entry of the set's ``spline_config.json`` (the joint sign
    patterns their ball evaluation drew from), as ``<name>_r<i>``."""
    src = Path(src_dir)
    if not src.is_dir():
        raise DatasetError(f"{src}: source directory not found")
    check_destination(dest, overwrite)
    subdirs = [s for s in ("train", "test") if (src / s).is_dir()]
    layout = {s: src / s for s in subdirs} if subdirs else {"test": src}
    splits: dict[str, list[tuple[str, np.ndarray]]] = {"train": [], "test": []}
    for split, d in layout.items():
        files = sorted(d.glob("episode_*.json"))
        splits[split] = [(f.stem, read_episode(f, robot.path_dof)) for f in files]
    if not any(splits.values()):
        raise DatasetError(f"{src}: no episode_*.json files found (looked in {', '.join(map(str, layout.values()))})")
    cfg_path, cfg = find_spline_config(src)
    if reflections:
        signs = reflection_vectors(cfg, robot.path_dof, cfg_path or src)
        splits = {s: [(f"{n}_r{i}", k * v) for n, k in p for i, v in enumerate(signs)] for s, p in splits.items()}
    stats = {s: {"stored": dataset_stats([k for _, k in p])} for s, p in splits.items()}
    meta = {
        "robot": robot.name,
        "kind": kind or (src.parent.name if src.name in ("train", "test") else src.name),
        "path_joints": list(robot.path_joints),
        "seed": None,
        "generator": {"format": "kiemel-json", "src_dir": str(src.resolve())},
        "source": "kiemel-json",
        "default_knots": {"strategy": "file"},
        "reference_max_knot_gap": cfg.get("max_dis_between_knots"),
        "spline_config": cfg,
        "spline_config_path": str(cfg_path) if cfg_path else None,
        "reflections": bool(reflections),
    }
    return save_dataset(dest, splits, meta, overwrite=overwrite, stats=stats)
