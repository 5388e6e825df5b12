"""Native build of the valid acceleration range (``valid_range.c``), loaded with ctypes.

The torch code in :mod:`pathrl.limits.feasible` is the reference; ``valid_range.c`` computes the same
range one element at a time, branching where the torch code must work on data-dependent subsets, so
an element does only the work it needs and no per-op dispatch is paid (iiwa7, 4096 envs: measured in
``make bench``). The tests compare both on random and on recorded states.

The C file is compiled on first use with the system C compiler (``$CC``, default ``cc``; no torch
headers, about a second) into ``$PATHRL_CACHE_DIR`` (default ``~/.cache/pathrl``), named by the hash of
the source, so an edited source is rebuilt and a stale library is never loaded. No compiler: the torch
code runs instead (:func:`available` is False; one warning). ``PATHRL_NATIVE_LIMITS=0`` switches the
native code off for the process.

Rows are split over ``torch.get_num_threads()`` threads; ctypes releases the GIL during the call.
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

import torch
from torch import Tensor

SOURCE = Path(__file__).with_name("valid_range.c")
FLAGS = ("-O3", "-fPIC", "-shared", "-fno-fast-math", "-std=c99")
MIN_ROWS_PER_THREAD = 256  # below this a second thread costs more than it saves


def _cache_dir() -> Path:
    root = os.environ.get("PATHRL_CACHE_DIR") or os.path.join(os.path.expanduser("~"), ".cache", "pathrl")
    return Path(root)


def _build(source: Path, target: Path) -> None:
    """Compile `source` into the shared library `target` (written to a temp name, then renamed)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=target.name, suffix=".tmp", dir=target.parent)
    os.close(fd)
    try:
        cc = os.environ.get("CC", "cc")
        subprocess.run([cc, *FLAGS, "-o", tmp, str(source), "-lm"], check=True, capture_output=True, text=True)
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


@functools.cache
def _library() -> ctypes.CDLL | None:
    """The loaded library, built first if needed; None where it cannot be built (warned once)."""
    if os.environ.get("PATHRL_NATIVE_LIMITS", "1") == "0":
        return None
    digest = hashlib.sha256(SOURCE.read_bytes() + " ".join(FLAGS).encode()).hexdigest()[:16]
    target = _cache_dir() / f"pathrl_valid_range_{digest}.so"
    try:
        if not target.exists():
            _build(SOURCE, target)
        lib = ctypes.CDLL(str(target))
    except (OSError, subprocess.CalledProcessError) as err:
        failed_build = isinstance(err, subprocess.CalledProcessError) and err.stderr
        detail = err.stderr.strip().splitlines()[-1] if failed_build else err
        warnings.warn(f"pathrl: native limit code unavailable ({detail}); using the torch code", stacklevel=2)
        return None
    dptr, i64 = ctypes.POINTER(ctypes.c_double), ctypes.c_int64
    lib.pathrl_valid_range.argtypes = [dptr, dptr, dptr, i64, i64, i64, dptr, dptr, dptr, dptr, dptr,
                                       ctypes.c_double, ctypes.c_int, dptr, dptr, ctypes.POINTER(ctypes.c_uint8)]
    lib.pathrl_valid_range.restype = None
    return lib


def available() -> bool:
    """Whether the native code is built and loadable (and not switched off)."""
    return _library() is not None


def applies(*tensors: Tensor) -> bool:
    """Whether the native code can take these inputs: float64 CPU tensors without autograd."""
    return all(t.dtype == torch.float64 and t.device.type == "cpu" and not t.requires_grad for t in tensors)


@functools.cache
def _pool(workers: int) -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=workers, thread_name_prefix="pathrl-limits")


def _ptr(t: Tensor, kind=ctypes.c_double):
    return ctypes.cast(t.data_ptr(), ctypes.POINTER(kind))


def valid_range(p: Tensor, v: Tensor, a: Tensor, pos: Tensor, vel: Tensor, acc: Tensor, jerk: Tensor,
                radius: Tensor, dt: float, stop_at_knot: bool) -> tuple[Tensor, Tensor, Tensor]:
    """Native ``feasible._valid_range``: p, v, a (..., D) float64; limits as in :class:`JointLimits`,
    ``radius`` (D,) the reach radius. Returns ``(lo, hi, overlap)`` shaped like ``p``."""
    lib = _library()
    if lib is None:
        raise RuntimeError("native limit code unavailable")
    dof = int(vel.shape[0])
    p, v, a = (t.contiguous() for t in (p, v, a))
    lims = [t.contiguous() for t in (pos, vel, acc, jerk, radius)]
    lo, hi = torch.empty_like(p), torch.empty_like(p)
    overlap = torch.empty(p.shape, dtype=torch.bool)
    rows = p.numel() // dof if dof else 0
    args = (_ptr(p), _ptr(v), _ptr(a))
    tail = (dof, *(_ptr(t) for t in lims), float(dt), int(bool(stop_at_knot)), _ptr(lo), _ptr(hi),
            _ptr(overlap, ctypes.c_uint8))
    chunks = max(1, min(torch.get_num_threads(), rows // MIN_ROWS_PER_THREAD))
    if chunks == 1:
        lib.pathrl_valid_range(*args, 0, rows, *tail)
    else:
        bounds = [rows * k // chunks for k in range(chunks + 1)]
        futures = [_pool(chunks - 1).submit(lib.pathrl_valid_range, *args, bounds[k], bounds[k + 1], *tail)
                   for k in range(1, chunks)]
        lib.pathrl_valid_range(*args, bounds[0], bounds[1], *tail)  # the first chunk on this thread
        for f in futures:
            f.result()
    return lo, hi, overlap
