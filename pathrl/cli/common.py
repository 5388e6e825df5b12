"""Shared CLI plumbing: compose a config from ``conf/`` with Hydra overrides, one-line errors."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

CONF_DIR = Path(__file__).resolve().parents[2] / "conf"


class UserError(Exception):
    """Bad user input (argument, config, dataset, checkpoint): reported as one line, exit code 2."""


def compose(config_name: str, overrides: Sequence[str]) -> DictConfig:
    """Compose ``conf/<config_name>.yaml`` with Hydra overrides (``key=value``, ``group=option``)."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from pathrl.config.store import register

    register()
    try:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            cfg = hydra_compose(config_name=config_name, overrides=list(overrides))
        OmegaConf.resolve(cfg)
    except (HydraException, OmegaConfBaseException) as exc:
        msg = str(exc).strip().splitlines()[0]
        raise UserError(f"config error: {msg}") from None
    return cfg


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
