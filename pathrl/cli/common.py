"""Shared CLI plumbing: compose a config from ``conf/`` with Hydra overrides, one-line errors."""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
import typing
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from pathrl.config.paths import CONF_DIR

__all__ = [
    "CONF_DIR", "ArgParser", "UserError", "compose", "hydra_message", "hydra_safe", "key_value_app",
    "key_value_overrides", "output_dir", "output_file", "quoted", "reword_type_error", "run_cli", "schema_keys",
    "to_container",
]


class UserError(Exception):
    """Bad user input (argument, config, dataset, checkpoint): reported as one line, exit code 2."""


class ArgParser(argparse.ArgumentParser):
    """An argparse parser whose errors are a one-line UserError (exit code 2 under :func:`run_cli`) instead of the
    usage and the message on two or more lines."""

    def error(self, message: str) -> None:  # type: ignore[override]
        """Raise UserError with the parser's message (and where to find the usage)."""
        raise UserError(f"{message} (see {self.prog} --help)")


def compose(config_name: str, overrides: Sequence[str], schema: type | None = None) -> DictConfig:
    """Compose ``conf/<config_name>.yaml`` with Hydra overrides (``key=value``, ``group=option``); with a `schema`
    (the app's dataclass) a key it does not declare (added by ``+key=value``) is an error naming the nearest."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from pathrl.cli.store import register

    register()
    try:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            cfg = hydra_compose(config_name=config_name, overrides=hydra_safe(overrides))
        OmegaConf.resolve(cfg)
    except (HydraException, OmegaConfBaseException) as exc:
        raise UserError(f"config error: {hydra_message(exc)}") from None
    if schema is not None:
        from pathrl.config.validate import check_keys

        try:
            check_keys(to_container(cfg), schema)
        except ValueError as exc:
            raise UserError(str(exc)) from None
    return cfg


def hydra_message(exc: BaseException) -> str:
    """One line from a Hydra / OmegaConf error: its first line and the line saying why (``Key 'x' is not in
    struct``), without the hints and the key dumps; a missing group option lists every option of the group."""
    text = str(exc).strip() + ("\n" + str(exc.__cause__).strip() if exc.__cause__ is not None else "")
    options = re.search(r"Available options in '([^']+)':\n((?:\t.*\n?)*)", text)
    if options is not None:
        names = [n.strip() for n in options.group(2).splitlines() if n.strip() and not n.strip().endswith("_schema")]
        first = text.splitlines()[0].strip()
        return f"{first}; options of {options.group(1)}: {', '.join(names)}"
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    keep = [ln for ln in lines if not ln.startswith(("To append", "full_key:", "reference_type", "object_type"))]
    return " ".join(keep[:2]) if keep else type(exc).__name__


#: Characters that make a Hydra override value more than one plain string (lists, dicts, sweeps, quotes, ...).
_GRAMMAR = set(",[]{}()'\"=:")


def hydra_safe(overrides: Sequence[str]) -> list[str]:
    """`overrides` with plain values that hold non-ASCII characters (``dataset.path=/data/tëst``) quoted: Hydra's
    grammar takes unquoted values as ASCII only. Values with grammar characters (lists, sweeps, quotes) and flags
    are left as written."""
    out = []
    for a in overrides:
        key, eq, value = a.partition("=")
        plain = eq and not a.startswith("-") and value and not (_GRAMMAR & set(value))
        out.append(f"{key}={quoted(value)}" if plain and not value.isascii() else a)
    return out


def output_file(path: str | Path, what: str) -> Path:
    """`path` as a Path if a file can be written there (:func:`pathrl.storage.check_file_destination`), checked
    before any work; UserError (one line naming `what`) if not."""
    from pathrl.storage import DestinationError, check_file_destination

    try:
        return check_file_destination(path, what)
    except DestinationError as exc:
        raise UserError(str(exc)) from None


def output_dir(path: str | Path, what: str, files: Sequence[str] = ()) -> Path:
    """`path` as a Path if a directory of outputs (with `files` in it) can be written there
    (:func:`pathrl.storage.check_dir_destination`), checked before any work; UserError (one line) if not."""
    from pathrl.storage import DestinationError, check_dir_destination

    try:
        return check_dir_destination(path, what, files)
    except DestinationError as exc:
        raise UserError(str(exc)) from None


def run_cli(main: Callable[[list[str]], Any], argv: Sequence[str] | None = None) -> int:
    """Run `main(argv)`; turn UserError / ValueError from user input into a one-line message on stderr."""
    args = list(sys.argv[1:] if argv is None else argv)
    try:
        main(args)
    except UserError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    return 0


def key_value_overrides(argv: Sequence[str], keys: Sequence[str], usage: str,
                        literal: Sequence[str] = ()) -> list[str]:
    """``key=value`` arguments as Hydra overrides; the values of `literal` keys (paths, names) are quoted so they are
    taken as written (``out=/tmp/a,b`` is not a list). UserError on a word without ``=`` or a key outside `keys`
    (``+key`` and ``~key`` included)."""
    out = []
    for a in argv:
        if "=" not in a:
            raise UserError(f"expected key=value, got {a!r}; {usage}")
        key, value = a.split("=", 1)
        if key not in keys:  # no +key / ~key: the app's keys are fixed
            raise UserError(f"unknown argument {key!r}; known: {', '.join(sorted(keys))}")
        out.append(f"{key}={quoted(value)}" if key in literal and value != "null" else a)
    return out


def key_value_app(config_name: str, schema: type, argv: Sequence[str], usage: str, literal: Sequence[str] = (),
                  keys: Sequence[str] | None = None) -> dict[str, Any]:
    """The composed config of a ``key=value`` CLI (``conf/<config_name>.yaml``, `schema`) as a dict: the arguments
    as overrides (:func:`key_value_overrides`; `keys` default: the schema's leaves), Hydra's type errors reworded
    (:func:`reword_type_error`), ``run_dir`` required. UserError: one line."""
    keys = schema_keys(schema, leaves=True) if keys is None else keys
    overrides = key_value_overrides(argv, keys, usage, literal)
    try:
        cfg = to_container(compose(config_name, overrides, schema))
    except UserError as exc:
        raise UserError(reword_type_error(str(exc))) from None
    if cfg.get("run_dir") == "???":
        raise UserError(f"run_dir is required; {usage}")
    return cfg


def quoted(value: str) -> str:
    """`value` as a Hydra quoted string (commas, brackets, ``<>`` and spaces kept; Hydra unescapes only the
    backslashes before a quote or the closing quote)."""
    q = "'" if "'" not in value else '"'
    body = re.sub(rf"(\\*)({q}|$)", lambda m: m.group(1) * 2 + ("\\" + m.group(2) if m.group(2) else ""), value)
    return q + body + q


def reword_type_error(message: str) -> str:
    """Hydra's type errors of an override as ``KEY must be ...``; other messages unchanged."""
    m = re.search(r"override ([\w.]+)=(.*?) Value .*(could not be converted to Integer|is not a valid bool)", message)
    if m is None:
        return message
    kind = "an integer" if "Integer" in m.group(3) else "true or false"
    return f"{m.group(1)} must be {kind}, got {m.group(2)!r}"


def schema_keys(schema: type, prefix: str = "", leaves: bool = False) -> list[str]:
    """The dotted keys of a dataclass schema, recursing into dataclass fields (``dataset``, ``dataset.path``);
    `leaves`: only the keys of values (``dataset.path``, not ``dataset``)."""
    out = []
    hints = typing.get_type_hints(schema)
    for f in dataclasses.fields(schema):
        nested = dataclasses.is_dataclass(hints[f.name])
        if not (leaves and nested):
            out.append(prefix + f.name)
        if nested:
            out += schema_keys(hints[f.name], f"{prefix}{f.name}.", leaves)
    return out


def to_container(cfg: DictConfig) -> dict[str, Any]:
    """Plain dict of a resolved config (for saving and for library code that takes mappings)."""
    return OmegaConf.to_container(cfg, resolve=True)  # type: ignore[return-value]
