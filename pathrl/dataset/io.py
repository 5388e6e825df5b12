"""On-disk dataset format (``pathrl-dataset/1``): one directory per dataset.

Layout::

    <dataset>/dataset.json   meta data (see below)
    <dataset>/train.npz      names (P,) str, knots (sum K_i, M) float64, offsets (P+1,) int64
    <dataset>/test.npz       same
    <dataset>/.cache/        resampled knots per knot strategy (written by :func:`load_pathset`)

A path is represented by its knots; its geometry is the natural cubic spline through them over the
chord-length parameter (:mod:`pathrl.paths.spline`). Path ``i`` of a split is
``knots[offsets[i]:offsets[i + 1]]``.

``dataset.json``: ``format``, ``robot``, ``kind``, ``path_joints``, ``seed``, ``generator`` (resolved
generator config + params), ``source`` (``generated`` | ``kiemel-json``), ``splits`` ({split: count}),
``content_hash`` (sha256 over the split files' arrays, see :func:`content_hash`), ``created`` (ISO time),
``stats`` ({split: {"stored": dataset_stats(...), optionally "<strategy>": stats after the default knot
strategy}}), ``default_knots`` (the knot strategy the stats refer to) and optional extra keys
(e.g. ``reference_max_knot_gap`` for imported sets).

Writes are atomic: everything goes to a temporary sibling directory that is renamed into place; an
existing dataset is only replaced with ``overwrite=True``.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import shutil
import sys
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pathrl.dataset.limits import LIMIT_TOL, limit_excess
from pathrl.dataset.stats import dataset_stats
from pathrl.paths.spline import PathError, dedupe_knots
from pathrl.storage import atomic_write

if TYPE_CHECKING:
    from pathrl.paths.knots import KnotStrategy
    from pathrl.paths.pathset import PathSet
    from pathrl.robot.model import RobotSpec

__all__ = ["CACHE_DIR", "Dataset", "DatasetError", "FORMAT", "MAX_KNOT_RAD", "MAX_PATH_LENGTH_RAD", "OUT_OF_LIMITS",
           "Split", "apply_strategy", "bounds_problem", "cache_path", "check_destination", "check_limits",
           "content_hash", "load_dataset", "load_pathset", "pack", "read_cache", "save_dataset", "strategy_key",
           "unpack", "write_cache"]

FORMAT = "pathrl-dataset/1"
#: Bounds on any stored or imported path, checked before anything is resampled or tabulated: far beyond any robot's
#: joints (the committed sets: |q| <= 3.2 rad, paths <= 30 rad), small enough that a path's arc-length table (one
#: sample per mrad) stays within memory, also when its knots are clipped into a robot's range afterwards.
MAX_KNOT_RAD = 100.0
MAX_PATH_LENGTH_RAD = 1000.0
META_FILE = "dataset.json"
CACHE_DIR = ".cache"
SPLITS = ("train", "test")


class DatasetError(ValueError):
    """A dataset on disk (or about to be written) is unusable. The message is one line naming the file."""


@dataclass(frozen=True)
class Split:
    """The paths of one split: names and knots (each (K_i, M) float64)."""

    names: tuple[str, ...]
    knots: tuple[np.ndarray, ...]

    def __len__(self) -> int:
        return len(self.names)

    def items(self) -> list[tuple[str, np.ndarray]]:
        """[(name, knots (K_i, M))] of the split."""
        return list(zip(self.names, self.knots, strict=True))


@dataclass(frozen=True)
class Dataset:
    """A loaded dataset: its directory, meta data (dataset.json) and splits."""

    path: Path
    meta: dict[str, Any]
    splits: dict[str, Split]

    @property
    def content_hash(self) -> str:
        """Hash of the dataset's paths (``content_hash`` of its metadata)."""
        return str(self.meta["content_hash"])

    @property
    def path_dof(self) -> int:
        """Number of path joints M (from the knots; from the metadata if every split is empty)."""
        for split in self.splits.values():
            if len(split):
                return int(split.knots[0].shape[1])
        return len(self.meta.get("path_joints", []))


# ----------------------------------------------------------------------------------------------------
# arrays <-> paths


def pack(paths: Sequence[tuple[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """[(name, knots (K_i, M))] -> {"names", "knots", "offsets"} arrays of one split file."""
    names = [str(n) for n, _ in paths]
    knots = [np.ascontiguousarray(k, dtype=np.float64) for _, k in paths]
    m = knots[0].shape[1] if knots else 0
    offsets = np.zeros(len(knots) + 1, dtype=np.int64)
    if knots:
        offsets[1:] = np.cumsum([k.shape[0] for k in knots])
    flat = np.concatenate(knots, axis=0) if knots else np.zeros((0, m), dtype=np.float64)
    return {
        "names": np.array(names, dtype=np.str_) if names else np.zeros(0, dtype="<U1"),
        "knots": np.ascontiguousarray(flat, dtype=np.float64),
        "offsets": offsets,
    }


def unpack(arrays: Mapping[str, np.ndarray]) -> Split:
    """The split packed by :func:`pack` (names, concatenated knots, offsets) as a :class:`Split`."""
    names = tuple(str(n) for n in arrays["names"])
    knots, offsets = arrays["knots"], arrays["offsets"]
    return Split(names, tuple(knots[offsets[i] : offsets[i + 1]] for i in range(len(names))))


def content_hash(split_arrays: Mapping[str, Mapping[str, np.ndarray]]) -> str:
    """sha256 over every split (sorted by name): split name, names (utf-8, NUL separated), offsets
    (int64 LE) and knots (float64 LE, C order), with their shapes."""
    h = hashlib.sha256()
    for split in sorted(split_arrays):
        arr = split_arrays[split]
        h.update(f"split:{split}\0".encode())
        h.update("\0".join(str(n) for n in arr["names"]).encode() + b"\0")
        offsets = np.ascontiguousarray(arr["offsets"], dtype="<i8")
        knots = np.ascontiguousarray(arr["knots"], dtype="<f8")
        h.update(f"offsets{offsets.shape}knots{knots.shape}".encode())
        h.update(offsets.tobytes())
        h.update(knots.tobytes())
    return h.hexdigest()


# ----------------------------------------------------------------------------------------------------
# validation


def bounds_problem(knots: np.ndarray) -> str | None:
    """Why the finite knots (K, M) are beyond :data:`MAX_KNOT_RAD` or their polyline beyond
    :data:`MAX_PATH_LENGTH_RAD` (checked before anything is tabulated), or None."""
    largest = float(np.abs(knots).max())
    if largest > MAX_KNOT_RAD:
        return f"knot {largest:.3g} rad is beyond {MAX_KNOT_RAD:g} rad (not joint angles in rad?)"
    length = float(np.linalg.norm(np.diff(knots, axis=0), axis=1).sum())
    if length > MAX_PATH_LENGTH_RAD:
        return f"its knots span {length:.3g} rad; at most {MAX_PATH_LENGTH_RAD:g} rad"
    return None


def _validate_paths(split: str, paths: Sequence[tuple[str, np.ndarray]], where: str) -> None:
    seen: set[str] = set()
    m = None
    for name, knots in paths:
        if not isinstance(name, str) or not name or "\0" in name or name != name.strip():
            raise DatasetError(f"{where}: split {split!r}: invalid path name {name!r}")
        if name in seen:
            raise DatasetError(f"{where}: split {split!r}: duplicate path name {name!r}")
        seen.add(name)
        k = np.asarray(knots)
        if k.ndim != 2 or k.shape[1] < 1:
            raise DatasetError(f"{where}: split {split!r}: path {name!r}: knots must be (K, M), got {k.shape}")
        if m is None:
            m = k.shape[1]
        elif k.shape[1] != m:
            raise DatasetError(f"{where}: split {split!r}: path {name!r} has {k.shape[1]} joints, others {m}")
        if not np.all(np.isfinite(k)):
            raise DatasetError(f"{where}: split {split!r}: path {name!r}: knots contain NaN or inf")
        problem = bounds_problem(k)
        if problem:
            raise DatasetError(f"{where}: split {split!r}: path {name!r}: {problem}")
        try:
            dedupe_knots(k)
        except PathError as exc:
            raise DatasetError(f"{where}: split {split!r}: path {name!r}: {exc}") from None


def _check_robot(meta: Mapping[str, Any], m: int | None, robot: RobotSpec | None, where: str) -> None:
    if robot is None:
        return
    if m is not None and m != robot.path_dof:
        raise DatasetError(f"{where}: paths have {m} joints but robot {robot.name!r} has {robot.path_dof} path joints")
    joints = meta.get("path_joints")
    if joints and list(joints) != list(robot.path_joints):
        raise DatasetError(f"{where}: path_joints {list(joints)} differ from robot {robot.name!r}'s path joints")


# ----------------------------------------------------------------------------------------------------
# save / load


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    return obj


def check_destination(dest: str | os.PathLike, overwrite: bool = False) -> Path:
    """Raise DatasetError if `dest` exists (and is not to be overwritten) or is not a dataset directory."""
    dest = Path(dest)
    if dest.exists():
        if not overwrite:
            raise DatasetError(f"{dest}: already exists (pass overwrite=true to replace it)")
        if not dest.is_dir() or (any(dest.iterdir()) and not (dest / META_FILE).is_file()):
            raise DatasetError(f"{dest}: exists and is not a pathrl dataset; refusing to overwrite it")
    return dest


def save_dataset(
    dest: str | os.PathLike,
    splits: Mapping[str, Sequence[tuple[str, np.ndarray]]],
    meta: Mapping[str, Any],
    overwrite: bool = False,
    stats: Mapping[str, Any] | None = None,
) -> Dataset:
    """Write a dataset directory atomically and return it (as :func:`load_dataset` would).

    Args:
        dest: dataset directory (created; its parent is created if missing).
        splits: {split name: [(path name, knots (K, M))]} (usually "train" and "test").
        meta: robot, kind, path_joints, seed, generator, source and any extra keys; format, splits,
            content_hash, created and (unless given) stats are filled in here.
        overwrite: replace an existing dataset at `dest`.
        stats: precomputed {split: stats}; default: {split: {"stored": dataset_stats(knots)}}.
    """
    dest = check_destination(dest, overwrite)
    where = str(dest)
    ms = set()
    for split, paths in splits.items():
        if not split.isidentifier():
            raise DatasetError(f"{where}: invalid split name {split!r}")
        _validate_paths(split, paths, where)
        ms.update(np.asarray(k).shape[1] for _, k in paths)
    if len(ms) > 1:
        raise DatasetError(f"{where}: splits have different joint counts {sorted(ms)}")
    m = ms.pop() if ms else None
    if m is not None and meta.get("path_joints") and len(meta["path_joints"]) != m:
        raise DatasetError(f"{where}: meta path_joints has {len(meta['path_joints'])} names, paths have {m} joints")
    arrays = {split: pack(paths) for split, paths in splits.items()}
    if stats is None:
        stats = {split: {"stored": dataset_stats([k for _, k in paths])} for split, paths in splits.items()}
    full = {
        "format": FORMAT,
        "robot": meta.get("robot"),
        "kind": meta.get("kind"),
        "path_joints": list(meta.get("path_joints", [])),
        "seed": meta.get("seed"),
        "generator": meta.get("generator", {}),
        "source": meta.get("source", "generated"),
        "splits": {split: len(paths) for split, paths in splits.items()},
        "content_hash": content_hash(arrays),
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "stats": stats,
    }
    for key, value in meta.items():
        full.setdefault(key, value)
    full = _jsonable(full)

    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=dest.parent, prefix=f".{dest.name}.tmp-"))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it 0700; the dataset gets the mode of any new directory
    try:
        for split, arr in arrays.items():
            with open(tmp / f"{split}.npz", "wb") as f:
                np.savez(f, **arr)
        with open(tmp / META_FILE, "w") as f:
            json.dump(full, f, indent=2)
            f.write("\n")
        if dest.exists():
            old = Path(tempfile.mkdtemp(dir=dest.parent, prefix=f".{dest.name}.old-"))
            os.rename(dest, old / "d")
            os.rename(tmp, dest)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(tmp, dest)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return Dataset(dest, full, {split: unpack(arr) for split, arr in arrays.items()})


def _read_split(path: Path) -> dict[str, np.ndarray]:
    if not path.is_file():
        raise DatasetError(f"{path}: split file missing")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = {"names", "knots", "offsets"} - set(z.files)
            if missing:
                raise DatasetError(f"{path}: missing arrays {sorted(missing)}")
            arr = {k: z[k] for k in ("names", "knots", "offsets")}
    except DatasetError:
        raise
    except Exception as exc:  # zipfile / pickle / value errors from a damaged file
        raise DatasetError(f"{path}: unreadable split file ({type(exc).__name__}: {exc})") from None
    names, knots, offsets = arr["names"], arr["knots"], arr["offsets"]
    if names.ndim != 1 or names.dtype.kind != "U":
        raise DatasetError(f"{path}: 'names' must be a 1-D string array")
    if knots.ndim != 2 or knots.dtype != np.float64:
        raise DatasetError(f"{path}: 'knots' must be a 2-D float64 array, got {knots.dtype} {knots.shape}")
    if offsets.ndim != 1 or offsets.dtype.kind not in "iu" or offsets.shape[0] != names.shape[0] + 1:
        raise DatasetError(f"{path}: 'offsets' must be (P+1,) integers for P = {names.shape[0]} names")
    if offsets[0] != 0 or offsets[-1] != knots.shape[0] or np.any(np.diff(offsets) < 0):
        raise DatasetError(f"{path}: 'offsets' must increase from 0 to the number of knots {knots.shape[0]}")
    return arr


def load_dataset(path: str | os.PathLike, robot: RobotSpec | None = None) -> Dataset:
    """Load and validate a dataset directory.

    Checks the format tag, every split file listed in dataset.json, the content hash, the joint
    count (and names) against `robot` (if given), finite knots, >= 2 distinct knots per path and the
    names. Every problem raises a one-line :class:`DatasetError` naming the offending file.
    """
    path = Path(path)
    meta_path = path / META_FILE
    if not path.is_dir():
        raise DatasetError(f"{path}: dataset directory not found")
    if not meta_path.is_file():
        raise DatasetError(f"{meta_path}: missing (not a pathrl dataset directory)")
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{meta_path}: invalid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise DatasetError(f"{meta_path}: expected a JSON object")
    if meta.get("format") != FORMAT:
        raise DatasetError(f"{meta_path}: unsupported format {meta.get('format')!r} (expected {FORMAT!r})")
    for key in ("splits", "content_hash"):
        if key not in meta:
            raise DatasetError(f"{meta_path}: missing key {key!r}")
    split_counts = meta["splits"]
    if not isinstance(split_counts, dict) or not all(isinstance(s, str) and s.isidentifier() for s in split_counts):
        raise DatasetError(f"{meta_path}: 'splits' must map split names to path counts")
    arrays = {split: _read_split(path / f"{split}.npz") for split in split_counts}
    digest = content_hash(arrays)
    if digest != meta["content_hash"]:
        bad = ", ".join(f"{s}.npz" for s in arrays) or "(no split files)"
        raise DatasetError(f"{path}: content hash mismatch: {bad} changed since {META_FILE} was written")
    m = None
    splits = {}
    for split, arr in arrays.items():
        file = path / f"{split}.npz"
        if arr["names"].shape[0] != split_counts[split]:
            raise DatasetError(f"{file}: has {arr['names'].shape[0]} paths, {META_FILE} says {split_counts[split]}")
        if arr["knots"].shape[0]:
            if m is not None and arr["knots"].shape[1] != m:
                raise DatasetError(f"{file}: {arr['knots'].shape[1]} joints, other splits have {m}")
            m = arr["knots"].shape[1]
        sp = unpack(arr)
        _validate_paths(split, sp.items(), str(file))
        splits[split] = sp
    _check_robot(meta, m, robot, str(path))
    return Dataset(path, meta, splits)


# ----------------------------------------------------------------------------------------------------
# knot strategy + PathSet (with cache)


def strategy_key(knots: KnotStrategy) -> str:
    """Cache key of a knot strategy, e.g. ``curvature_0.3_0.1``, ``distance_0.1`` or ``file``."""
    if knots.strategy == "file":
        return "file"
    if knots.strategy == "distance":
        return f"distance_{knots.spacing:g}"
    return f"curvature_{knots.spacing:g}_{knots.base_spacing:g}"


def cache_path(dataset: Dataset, split: str, knots: KnotStrategy) -> Path:
    """Cache file of a split's knots under a strategy: keyed by content hash + strategy."""
    return dataset.path / CACHE_DIR / f"{split}-{dataset.content_hash[:20]}-{strategy_key(knots)}.npz"


def write_cache(dataset: Dataset, split: str, knots: KnotStrategy, knots_list: Sequence[np.ndarray]) -> bool:
    """Store resampled knots of a split atomically in the cache; False if the directory is not writable."""
    cache = cache_path(dataset, split, knots)
    names = dataset.splits[split].names
    try:
        cache.parent.mkdir(exist_ok=True)
        atomic_write(cache, lambda tmp: np.savez(tmp, **pack(list(zip(names, knots_list, strict=True)))))
    except OSError:  # read-only dataset: no cache
        return False
    return True


def read_cache(dataset: Dataset, split: str, knots: KnotStrategy) -> list[np.ndarray] | None:
    """The cached knot arrays (K, D) of a split under `knots`; None if absent, damaged or out of date."""
    cache = cache_path(dataset, split, knots)
    if not cache.is_file():
        return None
    try:
        with np.load(cache, allow_pickle=False) as z:
            arr = {k: z[k] for k in ("names", "knots", "offsets")}
        cached = unpack(arr)
    except Exception:  # noqa: BLE001 - a damaged cache entry is recomputed
        return None
    if cached.names != dataset.splits[split].names:
        return None
    if any(k.ndim != 2 or k.shape[0] < 2 or not np.all(np.isfinite(k)) for k in cached.knots):
        return None
    return list(cached.knots)


def apply_strategy(dataset: Dataset, split: str, knots: KnotStrategy, use_cache: bool = True) -> list[np.ndarray]:
    """The split's knots after `knots` (resampling), cached in ``<dataset>/.cache/``."""
    if split not in dataset.splits:
        raise DatasetError(f"{dataset.path}: no split {split!r} (has {sorted(dataset.splits)})")
    sp = dataset.splits[split]
    if knots.strategy == "file":
        return [dedupe_knots(k) for k in sp.knots]
    if use_cache:
        cached = read_cache(dataset, split, knots)
        if cached is not None:
            return cached
    out = [knots.apply(k) for k in sp.knots]
    if use_cache:
        write_cache(dataset, split, knots, out)
    return out


#: What loading does with paths that leave the robot's position range: refuse the dataset, or clip the knots.
OUT_OF_LIMITS = ("refuse", "clip")


def check_limits(dataset: Dataset, split: str, robot: RobotSpec, out_of_limits: str) -> None:
    """Knots of the split outside the robot's position limits: a :class:`DatasetError` with ``refuse``, a one-line
    warning with ``clip`` (the caller clips)."""
    if out_of_limits not in OUT_OF_LIMITS:
        raise DatasetError(f"dataset.out_of_limits must be one of {list(OUT_OF_LIMITS)}, got {out_of_limits!r}")
    ex = limit_excess(dataset.splits[split].knots, robot)
    if not ex["paths_outside"]:
        return
    what = (f"{dataset.path}: split {split!r}: {ex['paths_outside']} of {ex['paths']} paths leave robot "
            f"{robot.name!r}'s position limits (by up to {1e3 * ex['max_excess_rad']:.3g} mrad, joint {ex['joint']})")
    if out_of_limits == "refuse":
        raise DatasetError(f"{what}; pass dataset.out_of_limits=clip to clip their knots into the limits")
    print(f"warning: {what}; their splines are clipped into the limits", file=sys.stderr)


def load_pathset(
    path: str | os.PathLike | Dataset,
    split: str,
    knots: KnotStrategy,
    robot: RobotSpec | None = None,
    table_step: float = 0.01,
    out_of_limits: str = "refuse",
) -> PathSet:
    """Load one split, apply the knot strategy (cached) and tabulate it as a PathSet. With a `robot`, paths that
    leave its position limits are refused or clipped (`out_of_limits`, :func:`check_limits`)."""
    from pathrl.paths.inside import PathOutsideError, keep_inside
    from pathrl.paths.pathset import build_pathset

    dataset = path if isinstance(path, Dataset) else load_dataset(path, robot)
    if isinstance(path, Dataset):
        _check_robot(dataset.meta, dataset.path_dof, robot, str(dataset.path))
    if split not in dataset.splits:
        raise DatasetError(f"{dataset.path}: no split {split!r} (has {sorted(dataset.splits)})")
    if not len(dataset.splits[split]):
        raise DatasetError(f"{dataset.path / (split + '.npz')}: split {split!r} is empty")
    if robot is not None:
        check_limits(dataset, split, robot, out_of_limits)
    clip = robot is not None and out_of_limits == "clip"  # also a spline leaving the range between inside knots
    resampled = apply_strategy(dataset, split, knots)
    paths = build_pathset(resampled, dataset.splits[split].names, table_step=table_step)
    if robot is None:
        return paths
    lim = robot.pos_limits[robot.path_index]
    try:  # the spline between clipped (or even inside) knots can still leave the range: what the env starts from
        return keep_inside(paths, resampled, lim[:, 0], lim[:, 1], clip=clip, tol=0.0 if clip else LIMIT_TOL)
    except PathOutsideError as exc:
        raise DatasetError(f"{dataset.path}: split {split!r}, robot {robot.name!r}, knots {strategy_key(knots)}: "
                           f"{exc}; pass dataset.out_of_limits=clip to clip them into the limits") from None
