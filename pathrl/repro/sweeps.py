"""Read ``sweeps/<table>.yaml``: the rows of one reproduced table and the experiments its training sweep runs.

A file holds ``rows`` (a list; each a ``key``, the evaluation's fields, and the flags ``not_in_paper`` and
``controller``), optional ``defaults`` (evaluation fields every row starts from), ``train`` (the experiments
``pathrl-train -m +sweep=<table>`` runs), ``paper_table`` (compare with another table's published values) and
``ours_only`` (no published values at all). Any other key, a missing or mistyped field or a repeated row key is a
:class:`SweepsError` with a one-line message naming the file and row. Also :func:`warm_starts`, read from the
experiments' ``init_from``. Pure (PyYAML only): the files are package data (``pathrl/sweeps``; ``sweeps/`` at the
top of a checkout is a symlink to it), so an installed copy finds them too.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from pathrl.models import ModelError, model_name

__all__ = ["SWEEPS_DIR", "RowSpec", "SweepsError", "TableSpec", "load_table", "load_tables", "warm_starts"]

#: ``pathrl/sweeps`` (``sweeps/`` in a checkout is a symlink to it).
SWEEPS_DIR = Path(__file__).resolve().parent.parent / "sweeps"
FILE_KEYS = ("rows", "defaults", "train", "paper_table", "ours_only")
FLAGS = ("not_in_paper", "controller")  # row flags besides the evaluation's fields
_TYPES = {"str": str, "bool": bool, "int": int, "None": type(None)}
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml when built with it: ~5x faster at import


def _read(path: Path) -> Any:
    return yaml.load(path.read_text(), Loader=_LOADER)


class SweepsError(ValueError):
    """A sweeps/ file (or an experiment's ``init_from``) that cannot be read as table rows: a one-line message."""


@dataclass(frozen=True)
class RowSpec:
    """One row of a table: its key, the evaluation that fills it, and whether the paper lacks it or it is a model-based
    controller."""

    key: str  # row key in the paper's table (pathrl/config/paper/tracking.yaml)
    evaluation: Any  # an instance of the evaluation class given to load_table (pathrl.repro.tables.Evaluation)
    not_in_paper: bool = False  # the paper has no such row (shown with a dash for its value)
    controller: bool = False  # models/<family>/<model> holds a model-based controller: evaluated, never trained


@dataclass(frozen=True)
class TableSpec:
    """One table of ``pathrl/sweeps``: its name, rows, training sweep experiments and which published table it is
    compared with."""

    name: str  # file stem, e.g. table_II (also the Hydra sweep: +sweep=table_II)
    rows: tuple[RowSpec, ...]
    train: tuple[str, ...] = ()  # experiments of its training sweep (none: no sweep)
    paper_table: str | None = None  # compare with this table's published values (default: its own)
    ours_only: bool = False  # no counterpart in the paper


def _check_type(where: str, name: str, value: Any, annotation: Any) -> None:
    annotation = annotation if isinstance(annotation, str) else annotation.__name__
    allowed = tuple(_TYPES[t.strip()] for t in annotation.split("|"))
    if not isinstance(value, allowed) or (isinstance(value, bool) and bool not in allowed):
        raise SweepsError(f"{where}: {name} must be {annotation}, got {value!r}")


def _row(where: str, raw: Any, defaults: dict[str, Any], evaluation_cls: type) -> RowSpec:
    """One row: defaults, then the row's own fields, checked against the evaluation class's fields."""
    fields = {f.name: f for f in dataclasses.fields(evaluation_cls)}
    if not isinstance(raw, dict) or not isinstance(raw.get("key"), str):
        raise SweepsError(f"{where}: a row must be a mapping with a string 'key', got {raw!r}")
    where = f"{where} ({raw['key']})"
    merged = {**defaults, **{k: v for k, v in raw.items() if k != "key"}}
    unknown = sorted(set(merged) - set(fields) - set(FLAGS))
    if unknown:
        raise SweepsError(f"{where}: unknown key {unknown[0]!r}; expected key, {', '.join([*fields, *FLAGS])}")
    missing = [n for n, f in fields.items() if n not in merged and f.default is dataclasses.MISSING]
    if missing:
        raise SweepsError(f"{where}: missing {', '.join(missing)}")
    for name, value in merged.items():
        _check_type(where, name, value, fields[name].type if name in fields else "bool")
    ev = evaluation_cls(**{k: v for k, v in merged.items() if k in fields})
    return RowSpec(raw["key"], ev, bool(merged.get("not_in_paper", False)), bool(merged.get("controller", False)))


def _names(where: str, value: Any, what: str) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise SweepsError(f"{where}: {what} must be a list of names, got {value!r}")
    return tuple(value)


def load_table(path: Path, evaluation_cls: type) -> TableSpec:
    """The table of one sweeps/ file; its rows' evaluations are ``evaluation_cls(**fields)``."""
    where = path.name
    try:
        data = _read(path)
    except (OSError, yaml.YAMLError) as exc:
        raise SweepsError(f"{where}: {' '.join(str(exc).split())}") from None
    if not isinstance(data, dict):
        raise SweepsError(f"{where}: expected a mapping with keys {', '.join(FILE_KEYS)}")
    unknown = sorted(set(data) - set(FILE_KEYS))
    if unknown:
        raise SweepsError(f"{where}: unknown key {unknown[0]!r}; expected {', '.join(FILE_KEYS)}")
    defaults = data.get("defaults") or {}
    if not isinstance(defaults, dict) or "key" in defaults:
        raise SweepsError(f"{where}: defaults must be a mapping of evaluation fields, got {defaults!r}")
    raw_rows = data.get("rows")
    if not isinstance(raw_rows, list) or not raw_rows:
        raise SweepsError(f"{where}: rows must be a non-empty list")
    rows = tuple(_row(f"{where}: row {i + 1}", r, defaults, evaluation_cls) for i, r in enumerate(raw_rows))
    keys = [r.key for r in rows]
    repeated = sorted({k for k in keys if keys.count(k) > 1})
    if repeated:
        raise SweepsError(f"{where}: row key {repeated[0]!r} appears more than once")
    paper_table, ours_only = data.get("paper_table"), data.get("ours_only", False)
    _check_type(where, "paper_table", paper_table, "str | None")
    _check_type(where, "ours_only", ours_only, "bool")
    return TableSpec(path.stem, rows, _names(where, data.get("train", []), "train"), paper_table, ours_only)


def load_tables(directory: Path, names: tuple[str, ...], evaluation_cls: type) -> dict[str, TableSpec]:
    """``<directory>/<name>.yaml`` for each name, in that order; a file not named (or a name without a file)
    is an error, so a new table cannot be silently left out."""
    found = {p.stem for p in directory.glob("*.yaml")}
    extra, absent = sorted(found - set(names)), [n for n in names if n not in found]
    if absent:
        raise SweepsError(f"{directory}: no {absent[0]}.yaml")
    if extra:
        raise SweepsError(f"{directory}/{extra[0]}.yaml: not a known table (add it to pathrl.repro.tables.TABLE_FILES)")
    return {n: load_table(directory / f"{n}.yaml", evaluation_cls) for n in names}


def _init_from(experiments: dict[str, dict[str, Any]], name: str, seen: tuple[str, ...] = ()) -> tuple[bool, Any]:
    """(whether set, value) of an experiment's ``init_from`` as Hydra composes it: its own value, else that of the
    last experiment in its defaults list that sets one (a config's own values merge after its defaults)."""
    if name in seen:
        raise SweepsError(f"experiment/{name}.yaml: its defaults include itself")
    cfg = experiments.get(name)
    if cfg is None:
        raise SweepsError(f"experiment/{seen[-1]}.yaml: defaults name a missing experiment {name!r}")
    if "init_from" in cfg:
        return True, cfg["init_from"]
    found: tuple[bool, Any] = (False, None)
    for entry in cfg.get("defaults") or []:
        if isinstance(entry, str) and entry != "_self_":  # another experiment of the same group
            inherited = _init_from(experiments, entry, (*seen, name))
            found = inherited if inherited[0] else found
    return found


def warm_starts(experiment_dir: Path) -> dict[str, str]:
    """``{experiment: source}`` for every experiment trained from a shipped policy
    (``init_from: models/<family>/<source>``, its own or inherited through its defaults list), in file-name order."""
    experiments = {p.stem: _read(p) or {} for p in sorted(experiment_dir.glob("*.yaml"))}
    out: dict[str, str] = {}
    for name in experiments:
        _, value = _init_from(experiments, name)
        if value is None:
            continue
        try:
            out[name] = model_name(value)
        except ModelError as err:
            raise SweepsError(f"experiment/{name}.yaml: init_from: {err}") from None
    return out
