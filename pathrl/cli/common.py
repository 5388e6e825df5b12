"""Shared CLI plumbing: compose a config from ``conf/`` with Hydra overrides, one-line errors."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import Any

from omegaconf import DictConfig, OmegaConf

from pathrl.config.paths import CONF_DIR

__all__ = ["CONF_DIR", "UserError", "compose", "hydra_message", "parse_key_values", "run_cli", "to_container"]


class UserError(Exception):
    """Bad user input (argument, config, dataset, checkpoint): reported as one line, exit code 2."""


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
            cfg = hydra_compose(config_name=config_name, overrides=list(overrides))
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
    struct``), without the hints and the key dumps."""
    text = str(exc).strip() + ("\n" + str(exc.__cause__).strip() if exc.__cause__ is not None else "")
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    keep = [ln for ln in lines if not ln.startswith(("To append", "full_key:", "reference_type", "object_type"))]
    return " ".join(keep[:2]) if keep else type(exc).__name__


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


def parse_key_values(argv: Sequence[str], keys: set[str], usage: str, required: Sequence[str] = ()) -> dict[str, str]:
    """``key=value`` arguments of a CLI that takes a fixed set of `keys` (``-h`` prints `usage`); UserError on an
    unknown key, a word without ``=`` or a missing required key."""
    args: dict[str, str] = {}
    for a in argv:
        if a in ("-h", "--help"):
            print(usage)
            raise SystemExit(0)
        if "=" not in a:
            raise UserError(f"expected key=value, got {a!r}; {usage}")
        k, v = a.split("=", 1)
        if k not in keys:
            raise UserError(f"unknown argument {k!r}; known: {', '.join(sorted(keys))}")
        args[k] = v
    for k in required:
        if k not in args:
            raise UserError(f"{k} is required; {usage}")
    return args


def to_container(cfg: DictConfig) -> dict[str, Any]:
    """Plain dict of a resolved config (for saving and for library code that takes mappings)."""
    return OmegaConf.to_container(cfg, resolve=True)  # type: ignore[return-value]
