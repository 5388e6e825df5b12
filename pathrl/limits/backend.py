"""Which code computes the joint limits: one explicit setting, :class:`LimitBackend`.

Two independent choices, each giving the torch reference's results to the tolerance below:

* ``native``: the valid acceleration range (:mod:`pathrl.limits.feasible`) and the tracking env's fused step run in
  the C build of :mod:`pathrl.native` where it applies (float64 CPU tensors, the library built). Where it does not
  (no C compiler, ``PATHRL_NATIVE=0``, a GPU tensor) the torch code runs, so ``native=True`` means "native where
  available". Agreement with torch: 1e-9 of the acceleration limit (``tests/test_limits_native.py``).
* ``compiled``: the torch kernels (functions marked :func:`pathrl.limits.kernels.kernel`) run ``torch.compile``-d;
  same results as eager to rounding (~1e-16 relative, ``tests/test_limits_compiled.py``).

Where the setting comes from, innermost first:

1. an env's own ``limit_backend`` (``TrackingEnvCfg`` / ``AdaptEnvCfg``; None: it follows 2 and 3), applied to its
   steps and observations, so two envs in one process can use different backends;
2. a ``with backend.active():`` block (context-local, nests; :func:`current` reads it). Training runs its
   iterations in the run config's backend (:meth:`LimitBackend.from_run`: ``native_limits``, ``compile_limits``),
   evaluation its rollouts with its ``compile_limits`` flag. A new thread starts outside every block;
3. the process default :data:`DEFAULT`: native where available, kernels not compiled. It is a constant; there is
   no process-wide switch. ``PATHRL_NATIVE=0`` makes the native code unavailable to every backend.

No torch import here (configs read this module).
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

__all__ = ["DEFAULT", "LimitBackend", "current", "env_scoped"]

F = TypeVar("F", bound=Callable)


@dataclass(frozen=True)
class LimitBackend:
    """The limit code to run: native C where it applies (``native``), compiled torch kernels (``compiled``)."""

    native: bool = True
    compiled: bool = False

    def __post_init__(self) -> None:
        for key in ("native", "compiled"):
            value = getattr(self, key)
            if not isinstance(value, bool):
                raise ValueError(f"LimitBackend.{key} must be true or false, got {value!r}")

    @classmethod
    def from_run(cls, cfg: Mapping[str, Any]) -> LimitBackend:
        """The backend of a resolved or saved run config: ``native_limits`` (absent: True) and ``compile_limits``
        (absent: False); a one-line ValueError naming the key for a value that is not a bool."""
        values = {}
        for field, key, default in (("native", "native_limits", True), ("compiled", "compile_limits", False)):
            value = cfg.get(key, default)
            if not isinstance(value, bool):
                raise ValueError(f"{key} must be true or false, got {value!r}")
            values[field] = value
        return cls(**values)

    @contextlib.contextmanager
    def active(self) -> Iterator[LimitBackend]:
        """This backend for the code inside the ``with`` block (this thread / context); the previous one after it."""
        token = _ACTIVE.set(self)
        try:
            yield self
        finally:
            _ACTIVE.reset(token)


#: The process default: native code where available, kernels not compiled (what every run did without a setting).
DEFAULT = LimitBackend()

_ACTIVE: contextvars.ContextVar[LimitBackend | None] = contextvars.ContextVar("pathrl_limit_backend", default=None)


def current() -> LimitBackend:
    """The backend in effect: the innermost :meth:`LimitBackend.active` block's, else :data:`DEFAULT`."""
    return _ACTIVE.get() or DEFAULT


def env_scoped(method: F) -> F:
    """Decorate an env method to run in the env's own ``limit_backend`` (None: the one in effect at the call)."""

    @functools.wraps(method)
    def run(self, *args, **kwargs):
        backend = self.limit_backend
        if backend is None:
            return method(self, *args, **kwargs)
        with backend.active():
            return method(self, *args, **kwargs)

    return run  # type: ignore[return-value]
