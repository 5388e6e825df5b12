"""Paths from users: joint-space waypoints in CSV or NumPy files, one path per file.

A path file holds the waypoints (K, M) of one path, one row per waypoint, one column per path joint in the robot's
``path_joints`` order:

- ``.csv`` / ``.txt``: numbers separated by commas (or whitespace); a first line that is not numbers is a header. A
  header of joint names (all of the robot's path joints, any order) selects and orders the columns by name;
- ``.npy``: a 2-D float array.

Radians by default (metres for a prismatic joint); ``degrees=True`` converts every column. Every path is checked
against the robot: finite, at least two distinct waypoints, every waypoint inside the position range (the robot's
usable range, limits shrunk by its margin). The spline through the waypoints may still overshoot between them near
a limit; loading with ``dataset.out_of_limits=clip`` (or a follower with ``out_of_limits="clip"``) handles that.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np

from pathrl.dataset.io import META_FILE, Dataset, DatasetError, check_destination, load_dataset, save_dataset
from pathrl.robot.model import RobotSpec

__all__ = ["FORMATS", "LIMIT_TOL", "SUFFIXES", "as_dataset", "check_waypoints", "import_waypoints", "read_path_file",
           "read_waypoints"]

#: Import formats and the file suffixes each reads.
SUFFIXES = {"csv": (".csv", ".txt"), "npy": (".npy",)}
FORMATS = tuple(SUFFIXES)
#: How far (rad) a waypoint may lie outside the position range and count as inside (rounding of data at a limit).
LIMIT_TOL = 1e-6


def _format_of(path: Path) -> str:
    for fmt, suffixes in SUFFIXES.items():
        if path.suffix.lower() in suffixes:
            return fmt
    raise DatasetError(f"{path}: unknown path file type {path.suffix!r} (expected one of "
                       f"{', '.join(s for v in SUFFIXES.values() for s in v)})")


def _read_csv(path: Path, joints: tuple[str, ...]) -> np.ndarray:
    """Waypoints (K, M) of a CSV file, columns reordered by a header of joint names if there is one."""
    try:
        lines = [ln.strip() for ln in path.read_text().splitlines()]
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{path}: cannot read ({exc})") from None
    lines = [ln for ln in lines if ln and not ln.startswith("#")]
    if not lines:
        raise DatasetError(f"{path}: no waypoints")

    def split(line: str) -> list[str]:
        return [c.strip() for c in (line.split(",") if "," in line else line.split())]

    header = None
    try:
        [float(c) for c in split(lines[0])]
    except ValueError:
        header, lines = split(lines[0]), lines[1:]
    rows = []
    for i, line in enumerate(lines, start=1):
        try:
            rows.append([float(c) for c in split(line)])
        except ValueError:
            raise DatasetError(f"{path}: waypoint {i}: not a row of numbers: {line[:60]!r}") from None
    if len({len(r) for r in rows}) > 1:
        raise DatasetError(f"{path}: rows have different numbers of columns {sorted({len(r) for r in rows})}")
    arr = np.asarray(rows, dtype=np.float64).reshape(len(rows), -1)
    if header is not None and set(joints) <= set(header):
        if len(header) != arr.shape[1]:
            raise DatasetError(f"{path}: header has {len(header)} names, rows have {arr.shape[1]} columns")
        arr = arr[:, [header.index(j) for j in joints]]
    return arr


def read_waypoints(path: str | os.PathLike, robot: RobotSpec, degrees: bool = False) -> np.ndarray:
    """The waypoints (K, M) of one path file (module docstring), in radians, checked against `robot`; a one-line
    DatasetError otherwise."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: path file not found")
    if _format_of(path) == "csv":
        arr = _read_csv(path, robot.path_joints)
    else:
        try:
            arr = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise DatasetError(f"{path}: not a NumPy .npy array ({exc})") from None
        if not np.issubdtype(arr.dtype, np.number):
            raise DatasetError(f"{path}: expected a numeric array, got dtype {arr.dtype}")
        arr = np.asarray(arr, dtype=np.float64)
    m = robot.path_dof
    if arr.ndim != 2 or arr.shape[1] != m:
        raise DatasetError(f"{path}: waypoints must be (K, {m}) (one column per path joint of {robot.name}: "
                           f"{', '.join(robot.path_joints)}), got {arr.shape}")
    if degrees:
        arr = np.deg2rad(arr)
    check_waypoints(arr, robot, str(path))
    return arr


def check_waypoints(knots: np.ndarray, robot: RobotSpec, where: str) -> None:
    """DatasetError unless `knots` (K, M) are finite, hold two distinct waypoints and lie inside the robot's
    position range (path joints)."""
    if not np.isfinite(knots).all():
        row = int(np.flatnonzero(~np.isfinite(knots).all(axis=1))[0])
        raise DatasetError(f"{where}: waypoint {row + 1} is not finite")
    if len(knots) < 2 or not (np.linalg.norm(np.diff(knots, axis=0), axis=1) > 1e-9).any():
        raise DatasetError(f"{where}: a path needs at least two distinct waypoints")
    lim = robot.pos_limits[robot.path_index]
    excess = np.maximum(lim[:, 0] - knots, knots - lim[:, 1])  # (K, M), > 0 outside
    if excess.max() > LIMIT_TOL:
        row, j = np.unravel_index(int(excess.argmax()), excess.shape)
        raise DatasetError(f"{where}: waypoint {row + 1} is outside {robot.name}'s position range on "
                           f"{robot.path_joints[j]} by {excess[row, j]:.4g} rad ({knots[row, j]:.4g} not in "
                           f"[{lim[j, 0]:.4g}, {lim[j, 1]:.4g}]; radians unless --degrees)")


def _path_files(src: Path, fmt: str | None) -> list[Path]:
    """The path files of `src` (a file, or a directory: its files of the format, sorted by name)."""
    if src.is_file():
        if fmt is not None and src.suffix.lower() not in SUFFIXES[fmt]:
            raise DatasetError(f"{src}: not a {fmt} file ({', '.join(SUFFIXES[fmt])})")
        return [src]
    if not src.is_dir():
        raise DatasetError(f"{src}: no such file or directory")
    suffixes = SUFFIXES[fmt] if fmt else tuple(s for v in SUFFIXES.values() for s in v)
    files = sorted(p for p in src.iterdir() if p.is_file() and p.suffix.lower() in suffixes)
    if not files:
        raise DatasetError(f"{src}: no path files ({', '.join(suffixes)})")
    return files


def import_waypoints(src: str | os.PathLike, dest: str | os.PathLike, robot: RobotSpec, fmt: str | None = None,
                     degrees: bool = False, split: str = "test", overwrite: bool = False,
                     kind: str | None = None) -> Dataset:
    """A dataset at `dest` (atomic) from one path file or a directory of them (`fmt`: "csv" or "npy", None: by
    suffix), each file one path named by its stem, all in `split`; a one-line DatasetError for any bad file."""
    if fmt is not None and fmt not in FORMATS:
        raise DatasetError(f"unknown format {fmt!r}; choose one of {list(FORMATS)}")
    src = Path(src)
    check_destination(dest, overwrite)
    files = _path_files(src, fmt)
    paths = [(f.stem, read_waypoints(f, robot, degrees)) for f in files]
    meta = {
        "robot": robot.name,
        "kind": kind or (src.stem if src.is_file() else src.name),
        "path_joints": list(robot.path_joints),
        "seed": None,
        "generator": {"format": fmt or "by suffix", "src": str(src.resolve()), "degrees": degrees},
        "source": "waypoints",
    }
    return save_dataset(dest, {split: paths}, meta, overwrite=overwrite)


def read_path_file(path: str | os.PathLike, robot: RobotSpec, degrees: bool = False) -> np.ndarray:
    """One path file's waypoints (K, M) in radians, checked (for :meth:`pathrl.deploy.Follower.reset`)."""
    return read_waypoints(path, robot, degrees)


def as_dataset(path: str | os.PathLike, robot: RobotSpec, cache_dir: str | os.PathLike | None = None) -> Path:
    """`path` itself if it is a dataset directory; a path file or a directory of path files (radians) imported
    once into a dataset under `cache_dir` (default: the system's temporary directory), keyed by the files'
    contents and the robot, whose ``test`` split holds them. -> the dataset directory."""
    path = Path(path)
    if (path / META_FILE).is_file() or not path.exists():
        return path  # a dataset (or nothing: the loader says so)
    files = _path_files(path, None)
    digest = hashlib.sha256(robot.name.encode() + repr(robot.pos_limits.tolist()).encode())
    for f in files:
        digest.update(f.name.encode() + f.read_bytes())
    root = Path(cache_dir) if cache_dir is not None else Path(tempfile.gettempdir()) / "pathrl-path-files"
    dest = root / f"{path.stem}-{digest.hexdigest()[:16]}"
    if (dest / META_FILE).is_file():
        load_dataset(dest, robot)
        return dest
    import_waypoints(path, dest, robot, overwrite=True)
    return dest
