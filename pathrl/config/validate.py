"""Config keys checked against the dataclass schemas: a key the schema does not have is an error naming the
nearest valid key (Hydra's ``+key=value`` adds keys that no YAML or schema declares, so a typo would otherwise
run silently with the default)."""

from __future__ import annotations

import dataclasses
import difflib
import types
import typing
from collections.abc import Mapping
from typing import Any

__all__ = ["check_keys", "unknown_keys"]


def _dataclass_of(tp: Any) -> type | None:
    """The dataclass in a field type (``X``, ``X | None``), else None (free-form or a plain value)."""
    if dataclasses.is_dataclass(tp):
        return tp
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        for arg in typing.get_args(tp):
            if dataclasses.is_dataclass(arg):
                return arg
    return None


def unknown_keys(cfg: Mapping[str, Any], schema: type, prefix: str = "") -> list[str]:
    """One message per key of `cfg` that `schema` (a dataclass) does not declare, recursing into dataclass-typed
    fields; fields typed as plain dicts are free-form and not checked here."""
    hints = typing.get_type_hints(schema)
    names = [f.name for f in dataclasses.fields(schema)]
    out = []
    for key, value in cfg.items():
        if key not in hints:
            near = difflib.get_close_matches(str(key), names, n=1)
            hint = f"; did you mean {prefix}{near[0]}?" if near else f"; valid keys: {', '.join(names)}"
            out.append(f"unknown config key {prefix}{key}{hint}")
            continue
        sub = _dataclass_of(hints[key])
        if sub is not None and isinstance(value, Mapping):
            out += unknown_keys(value, sub, f"{prefix}{key}.")
    return out


def check_keys(cfg: Mapping[str, Any], schema: type) -> None:
    """Raise ValueError (one line: the first unknown key and the nearest valid one) if `cfg` has unknown keys."""
    bad = unknown_keys(cfg, schema)
    if bad:
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise ValueError(bad[0] + more)
