"""Native builds of hot kernels, loaded with ctypes (CPU, float64): two of an env step, one of the industrial
controller model.

* ``valid_range.c``: the valid acceleration range of :mod:`pathrl.limits.feasible`, one element at a
  time, branching where the torch code must work on data-dependent subsets, so an element does only the
  work it needs and no per-op dispatch is paid.
* ``advance.c``: the env's integration, progress and deviation (:func:`pathrl.envs.tracking.advance`).
* ``drives.c``: the 1 kHz drive-train loop of the industrial controller model
  (:func:`pathrl.industrial.drives.drive_loop_python`, numpy in and out; :func:`drive_loop`).

The torch code is the reference of the env kernels (and runs on any device), the numpy loop that of the drive
loop; the tests compare each pair. The C files are compiled on first use with the system C compiler (``$CC``,
default ``cc``; no torch headers, about a second) into one library in ``$PATHRL_CACHE_DIR`` (default
``~/.cache/pathrl``), named by the hash of the sources, so an edited source is rebuilt and a stale library is never
loaded. No compiler: the reference code runs instead (:func:`available` is False; one warning).
``PATHRL_NATIVE=0`` makes the native code unavailable (the documented way to run without it, e.g. to compare).
Whether available native code is used is chosen, for the env kernels, by the limit backend in effect
(:class:`pathrl.limits.backend.LimitBackend`, ``native``; default on); the drive loop uses it whenever available.

The env kernels' rows are split over :func:`threads` threads (torch's count unless set); ctypes releases the GIL
during a call.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import subprocess
import tempfile
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

__all__ = ["advance", "advance_supports", "applies", "available", "drive_loop", "set_threads", "threads",
           "valid_range"]

SOURCES = tuple(Path(__file__).with_name(name) for name in ("valid_range.c", "advance.c", "drives.c"))
FLAGS = ("-O3", "-fPIC", "-shared", "-fno-fast-math", "-std=c99")
MIN_ROWS_PER_THREAD = 256  # below this a second thread costs more than it saves


def _cache_dir() -> Path:
    root = os.environ.get("PATHRL_CACHE_DIR") or os.path.join(os.path.expanduser("~"), ".cache", "pathrl")
    return Path(root)


def _build(sources: tuple[Path, ...], target: Path) -> None:
    """Compile `sources` into the shared library `target` (written to a temp name, then renamed)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=target.name, suffix=".tmp", dir=target.parent)
    os.close(fd)
    try:
        cc = os.environ.get("CC", "cc")
        subprocess.run([cc, *FLAGS, "-o", tmp, *map(str, sources), "-lm"], check=True, capture_output=True, text=True)
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


@functools.cache
def _library() -> ctypes.CDLL | None:
    """The loaded library, built first if needed; None where it cannot be built (warned once)."""
    if os.environ.get("PATHRL_NATIVE", "1") == "0":
        return None
    digest = hashlib.sha256(b"".join(f.read_bytes() for f in SOURCES) + " ".join(FLAGS).encode()).hexdigest()[:16]
    target = _cache_dir() / f"pathrl_native_{digest}.so"
    try:
        if not target.exists():
            _build(SOURCES, target)
        lib = ctypes.CDLL(str(target))
    except (OSError, subprocess.CalledProcessError) as err:
        failed_build = isinstance(err, subprocess.CalledProcessError) and err.stderr
        detail = err.stderr.strip().splitlines()[-1] if failed_build else err
        warnings.warn(f"pathrl: native code unavailable ({detail}); using the reference code", stacklevel=2)
        return None
    dptr, i64 = ctypes.POINTER(ctypes.c_double), ctypes.c_int64
    lib.pathrl_valid_range.argtypes = [dptr, dptr, dptr, i64, i64, i64, dptr, dptr, dptr, dptr, dptr,
                                       ctypes.c_double, ctypes.c_int, dptr, dptr, ctypes.POINTER(ctypes.c_uint8)]
    lib.pathrl_valid_range.restype = None
    lp = ctypes.POINTER(ctypes.c_int64)
    lib.pathrl_advance.argtypes = [dptr, dptr, dptr, dptr, i64, i64, i64, lp, i64, dptr, dptr, lp, dptr, i64, dptr,
                                   dptr, ctypes.c_double, i64, ctypes.c_double, dptr, dptr, dptr, dptr, dptr]
    lib.pathrl_advance.restype = ctypes.c_int
    lib.pathrl_drive_loop.argtypes = [dptr] * 5 + [i64] + [dptr] * 9 + [ctypes.c_double] * 3 + [dptr] * 6
    lib.pathrl_drive_loop.restype = None
    return lib


def available() -> bool:
    """Whether the native library is built and loadable (``PATHRL_NATIVE=0`` makes it unavailable)."""
    return _library() is not None


def applies(*floats: Tensor, longs: tuple[Tensor, ...] = ()) -> bool:
    """Whether the native code is available and can take these inputs: `floats` float64 and `longs` int64 CPU
    tensors, none requiring grad. (Whether to use it is the caller's limit backend.)"""
    def fits(t: Tensor, dtype: torch.dtype) -> bool:
        return t.dtype == dtype and t.device.type == "cpu" and not t.requires_grad

    return all(fits(t, torch.float64) for t in floats) and all(fits(t, torch.int64) for t in longs) and available()


@functools.cache
def _pool(workers: int) -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=workers, thread_name_prefix="pathrl-native")


def _ptr(t: Tensor, kind=ctypes.c_double):
    return ctypes.cast(t.data_ptr(), ctypes.POINTER(kind))


def _np_ptr(x: np.ndarray):
    return x.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def valid_range(p: Tensor, v: Tensor, a: Tensor, pos: Tensor, vel: Tensor, acc: Tensor, jerk: Tensor,
                radius: Tensor, dt: float, stop_at_knot: bool) -> tuple[Tensor, Tensor, Tensor]:
    """Native ``feasible._valid_range``: p, v, a (..., D) float64; limits as in :class:`JointLimits`,
    ``radius`` (D,) the reach radius. Returns ``(lo, hi, overlap)`` shaped like ``p``."""
    lib = _library()
    if lib is None:
        raise RuntimeError("native code unavailable")
    dof = int(vel.shape[0])
    p, v, a = (t.contiguous() for t in (p, v, a))
    lims = [t.contiguous() for t in (pos, vel, acc, jerk, radius)]
    lo, hi = torch.empty_like(p), torch.empty_like(p)
    overlap = torch.empty(p.shape, dtype=torch.bool)
    rows = p.numel() // dof if dof else 0
    args = (_ptr(p), _ptr(v), _ptr(a))
    tail = (dof, *(_ptr(t) for t in lims), float(dt), int(bool(stop_at_knot)), _ptr(lo), _ptr(hi),
            _ptr(overlap, ctypes.c_uint8))
    _over_rows(lib.pathrl_valid_range, rows, args, tail)
    return lo, hi, overlap


_threads: int | None = None


def set_threads(n: int | None) -> None:
    """Threads the native code splits rows over; None (default): ``$PATHRL_NATIVE_THREADS``, else torch's
    intra-op thread count. With torch on 2 threads its OpenMP workers keep spinning between ops and compete
    with these threads; on a 2-core machine the env steps fastest with torch on 1 thread and 2 here."""
    if n is not None and int(n) < 1:
        raise ValueError(f"native threads must be >= 1, got {n}")
    global _threads
    _threads = None if n is None else int(n)


def threads() -> int:
    """Threads the native code uses now (see :func:`set_threads`)."""
    if _threads is not None:
        return _threads
    env = os.environ.get("PATHRL_NATIVE_THREADS")
    return max(1, int(env)) if env and env.isdigit() else torch.get_num_threads()


def _over_rows(fn, rows: int, head: tuple, tail: tuple) -> list:
    """``fn(*head, row0, row1, *tail)`` over all rows, split into up to :func:`threads` chunks (the first on
    this thread); returns the chunks' return values."""
    chunks = max(1, min(threads(), rows // MIN_ROWS_PER_THREAD))
    if chunks == 1:
        return [fn(*head, 0, rows, *tail)]
    bounds = [rows * k // chunks for k in range(chunks + 1)]
    futures = [_pool(chunks - 1).submit(fn, *head, bounds[k], bounds[k + 1], *tail) for k in range(1, chunks)]
    first = fn(*head, bounds[0], bounds[1], *tail)
    return [first, *(f.result() for f in futures)]


MAX_PATH_JOINTS = MAX_SUBSTEPS = 64  # advance.c's stack arrays


def advance_supports(path_joints: int, substeps: int, table_samples: int) -> bool:
    """Whether :func:`advance` takes these sizes (else the torch kernel must run)."""
    return path_joints <= MAX_PATH_JOINTS and 1 <= substeps <= MAX_SUBSTEPS and table_samples >= 2


def advance(pos: Tensor, vel: Tensor, acc: Tensor, a1: Tensor, path_index: Tensor, s: Tensor, end_s: Tensor,
            path: Tensor, table: Tensor, length: Tensor, dev_weights: Tensor, dt: float, substeps: int,
            table_step: float) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Native :func:`pathrl.envs.tracking.advance` (same arguments and results)."""
    lib = _library()
    if lib is None:
        raise RuntimeError("native code unavailable")
    if not advance_supports(int(path_index.numel()), int(substeps), int(table.shape[1])):
        raise ValueError(f"native advance: unsupported sizes (path joints {path_index.numel()} <= 64, "
                         f"substeps {substeps} in 1..64, table samples {table.shape[1]} >= 2)")
    pos, vel, acc, a1, s, end_s, table, length, dev_weights = (
        t.contiguous() for t in (pos, vel, acc, a1, s, end_s, table, length, dev_weights))
    path_index, path = path_index.contiguous(), path.contiguous()
    n, dof = pos.shape
    p1, v1 = torch.empty_like(pos), torch.empty_like(pos)
    moved, dev_max, dev_mean = torch.empty_like(s), torch.empty_like(s), torch.empty_like(s)
    lp = ctypes.c_int64
    head = (_ptr(pos), _ptr(vel), _ptr(acc), _ptr(a1))
    tail = (dof, _ptr(path_index, lp), int(path_index.numel()), _ptr(s), _ptr(end_s), _ptr(path, lp), _ptr(table),
            int(table.shape[1]), _ptr(length), _ptr(dev_weights), float(dt), int(substeps), float(table_step),
            _ptr(p1), _ptr(v1), _ptr(moved), _ptr(dev_max), _ptr(dev_mean))
    if any(_over_rows(lib.pathrl_advance, n, head, tail)):  # advance.c checks the sizes itself too
        raise RuntimeError("native advance rejected sizes that advance_supports accepted")
    return p1, v1, moved, dev_max, dev_mean


def drive_loop(series: tuple[np.ndarray, ...], axes: tuple[np.ndarray, ...], state: tuple[np.ndarray, ...],
               f_scale: float, ff_vel: float, dt: float) -> np.ndarray:
    """Native :func:`pathrl.industrial.drives.drive_loop_python` (same arguments and result): `series` the motor
    setpoints th_r, their rates thd_r, the feed-forward torques tau_ff, the plant's bias torques h (n, 6) and its
    inverse mass matrices (n, 6, 6); `axes` kp, kv, ki, tau_max, k_gear, d_gear, b, fc, fv (6,); `state` the
    initial th, thd, q, qd, integ (6,), not modified. Returns the link angles (n, 6) after each step."""
    lib = _library()
    if lib is None:
        raise RuntimeError("native code unavailable")
    if len(series) != 5 or len(axes) != 9 or len(state) != 5:
        raise ValueError("native drive_loop: 5 series, 9 axis vectors and 5 state vectors expected")
    series = tuple(np.ascontiguousarray(x, dtype=np.float64) for x in series)
    n = len(series[0])
    shapes = [x.shape for x in series] + [np.shape(x) for x in (*axes, *state)]
    if shapes != [(n, 6)] * 4 + [(n, 6, 6)] + [(6,)] * 14:
        raise ValueError(f"native drive_loop: shapes {shapes}, expected (n, 6) x4, (n, 6, 6), (6,) x14")
    axes = tuple(np.ascontiguousarray(x, dtype=np.float64) for x in axes)
    state = tuple(np.array(x, dtype=np.float64) for x in state)  # fresh copies: the C code updates them in place
    out = np.empty((n, 6))
    lib.pathrl_drive_loop(*map(_np_ptr, series), n, *map(_np_ptr, axes), float(f_scale), float(ff_vel), float(dt),
                          *map(_np_ptr, state), _np_ptr(out))
    return out
