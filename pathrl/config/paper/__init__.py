"""The source papers' published values, one YAML file per paper in this folder (package data), read here only.

- ``tracking.yaml``: Kiemel et al., *Learning Time-optimized Path Tracking with or without Sensory Feedback* (IROS
  2022), Tables I-IX; its tables are ``../shared/reference/paper_tables.yaml``, the upstream transcription, verbatim;
- ``trueadapt.yaml``: Kiemel, Weitemeyer et al., *TrueAdapt*, Table I and the time to compute the valid range;
- ``industrial.yaml``: Wen et al., Tables II-IV and the costs of an execution and of a decision.

A file maps table names to ``{columns: [...], rows: {key: [one value per column]}}`` (``null``: the paper prints no
value) and holds single values under ``values``. Readers: :mod:`pathrl.repro` (the reproduced tables), the industrial
tables and cost model (:mod:`pathrl.industrial.tables`, :mod:`pathrl.industrial.timing`), the evaluation protocol's
episode count (``pathrl-eval``, ``pathrl-toppra``) and the tools that compare with the paper.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from types import MappingProxyType
from typing import Any

import yaml

__all__ = ["DIR", "PAPERS", "Paper", "PaperError", "Table", "load"]

DIR = Path(__file__).resolve().parent
#: The papers, by file name: the main paper, the second (TrueAdapt), the third (industrial motion profiles).
PAPERS = ("tracking", "trueadapt", "industrial")

Cell = float | int | bool | str | None


class PaperError(ValueError):
    """A paper file that does not have the layout above."""


@dataclass(frozen=True)
class Table:
    """One published table: its columns and, per row key, one value per column."""

    columns: tuple[str, ...]
    rows: Mapping[str, tuple[Cell, ...]]

    def row(self, key: str) -> dict[str, Cell]:
        """Row `key` as {column: value}."""
        return dict(zip(self.columns, self.rows[key], strict=True))

    def as_dict(self) -> dict[str, Any]:
        """``{"columns": [...], "rows": {key: [...]}}``, fresh lists (as the file reads)."""
        return {"columns": list(self.columns), "rows": {k: list(v) for k, v in self.rows.items()}}


@dataclass(frozen=True)
class Paper:
    """One paper's file: its tables and single values."""

    name: str
    tables: Mapping[str, Table]
    values: Mapping[str, Cell]

    def table(self, key: str) -> Table:
        if key not in self.tables:
            raise KeyError(f"{self.name}.yaml has no table {key!r} (tables: {', '.join(self.tables)})")
        return self.tables[key]

    def value(self, key: str) -> Cell:
        if key not in self.values:
            raise KeyError(f"{self.name}.yaml has no value {key!r} (values: {', '.join(self.values)})")
        return self.values[key]

    def as_dict(self) -> dict[str, dict[str, Any]]:
        """Every table as :meth:`Table.as_dict`, by name: what the renderers of :mod:`pathrl.repro` take."""
        return {k: t.as_dict() for k, t in self.tables.items()}


def _table(where: str, raw: Any) -> Table:
    if not isinstance(raw, dict) or set(raw) != {"columns", "rows"} or not isinstance(raw["rows"], dict):
        raise PaperError(f"{where}: a table is a mapping of `columns` and `rows`")
    columns = tuple(str(c) for c in raw["columns"])
    for key, values in raw["rows"].items():
        if not isinstance(values, list) or len(values) != len(columns):
            raise PaperError(f"{where}: row {key!r} needs one value per column ({len(columns)})")
    return Table(columns, MappingProxyType({str(k): tuple(v) for k, v in raw["rows"].items()}))


@cache
def load(name: str) -> Paper:
    """The paper `name` (one of :data:`PAPERS`), read once."""
    if name not in PAPERS:
        raise KeyError(f"no paper {name!r} (papers: {', '.join(PAPERS)})")
    path = DIR / f"{name}.yaml"
    raw = yaml.safe_load(path.read_text())
    values = raw.pop("values", {})
    if not isinstance(values, dict):
        raise PaperError(f"{path}: `values` is a mapping of names to single values")
    tables = {str(k): _table(f"{path}: {k}", v) for k, v in raw.items()}
    return Paper(name, MappingProxyType(tables), MappingProxyType(dict(values)))
