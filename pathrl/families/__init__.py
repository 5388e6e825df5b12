"""The family registry: one entry per task family, naming every step of its lifecycle.

A family is what a run, a model directory or a recording belongs to: ``tracking`` (path tracking, with or without a
feedback task), ``trueadapt`` (TrueAdapt trajectory adaptation) and ``industrial`` (motion-profile optimisation on
the simulated industrial controller). Each entry names, as ``"module:function"`` strings resolved lazily inside
this package (:data:`ADAPTERS`, never from user input), one function per lifecycle step with one signature shared
by all families:

  detect(run_dir) -> bool                       a directory without config.yaml is this family's (its files)
  build(run_dir, opts) -> env                   its env, tiny or full (``opts``: :class:`EvalOptions`)
  evaluate(run_dir, opts) -> metrics            rollouts and metrics (``metrics.json`` in ``opts.out_dir``)
  report(metrics, out, opts) -> None            what ``pathrl-eval`` prints after an evaluation
  record(run_dir, out, opts) -> Path            a recording ``pathrl-view`` converts (an MCAP file in ``out``)
  timing(run_dir, opts) -> dict                 realtime timing (compute per decision or per episode)
  validate(run_dir, opts) -> dict | None        limit validation (None: the family has none)
  table_rows(metrics) -> list[str]              its table rows (markdown) from an evaluation's metrics

and the recordings it owns (:class:`Recording`: kind, file name, converter ``view_<kind>(src, out, ViewOptions) ->
ConvertStats`` to ``.rrd``). ``pathrl-eval`` and
``pathrl-view`` serve every family through :func:`family_of` and these functions. Adding a family: its module
``pathrl/families/<name>.py`` with those functions, and its line in :data:`FAMILIES`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["ADAPTERS", "DEFAULT", "FAMILIES", "Family", "Recording", "ViewOptions", "family", "family_of",
           "family_of_kind", "file_names", "recording_of", "resolve", "task_of"]

@dataclass(frozen=True)
class ViewOptions:
    """What ``pathrl-view`` passes a converter: the episode selection (ids or the worst N) and the timeline."""

    ids: list[int] | None = None
    worst: int | None = None
    timeline: str = "time"


@dataclass(frozen=True)
class Recording:
    """A recording a family writes: its MCAP file name, its kind (:func:`pathrl.viz.rerun_view.kind_of`), the word for
    its items in ``pathrl-view``'s output, its converter ``(src, out, ViewOptions) -> ConvertStats`` and whether
    ``--episodes`` / ``--worst`` select from it."""

    kind: str
    file_name: str
    items: str
    view: str  # "module:function"
    selectable: bool = False


@dataclass(frozen=True)
class Family:
    """One task family: its lifecycle steps as ``"module:function"`` strings (module doc) and its recordings."""

    name: str
    summary: str
    tasks: tuple[str, ...]  # the env registry's tasks (pathrl.envs.registry.TASKS) of the family, if any
    detect: str
    build: str
    evaluate: str
    report: str
    record: str
    timing: str
    validate: str
    table_rows: str
    recordings: tuple[Recording, ...]

    def step(self, name: str) -> Callable[..., Any]:
        """The function of lifecycle step `name` (e.g. ``"evaluate"``), imported now."""
        return resolve(getattr(self, name))


def _family(name: str, summary: str, tasks: tuple[str, ...], recordings: tuple[tuple[str, str, bool], ...]) -> Family:
    """The entry of family `name`: every step is the function of that name in ``pathrl.families.<name>``, and so is
    each recording's converter (``view_<kind>``); `recordings`: (kind, item word, selectable by ``--episodes`` /
    ``--worst``)."""
    module = f"{__name__}.{name}"
    steps = {s: f"{module}:{s}" for s in ("detect", "build", "evaluate", "report", "record", "timing", "validate",
                                          "table_rows")}
    recs = tuple(Recording(kind, f"{kind}.mcap", items, f"{module}:view_{kind}", sel)
                 for kind, items, sel in recordings)
    return Family(name, summary, tasks, recordings=recs, **steps)


#: The registered families (one line each; the order of their recordings is the order ``pathrl-view DIR`` converts).
FAMILIES: dict[str, Family] = {f.name: f for f in (
    _family("tracking", "path tracking, with or without a feedback task", ("tracking", "ball_on_plate", "standing"),
            (("episodes", "episodes", True), ("run", "training curves", False))),
    _family("industrial", "motion-profile optimisation on the simulated industrial controller", (),
            (("industrial", "executions", False),)),
    _family("trueadapt", "TrueAdapt trajectory adaptation (ball on plate)", ("trueadapt_on_plate",
            "trueadapt_in_place"), (("trueadapt", "TrueAdapt episodes", False),)),
)}

#: The modules a registry entry may name (``"module:function"``): the families' own; nothing else is ever imported
#: by :func:`resolve`.
ADAPTERS = tuple(f"{__name__}.{name}" for name in FAMILIES)

#: The family of a directory no family claims (a run directory that does not exist gets its errors from here).
DEFAULT = "tracking"


def resolve(ref: str) -> Callable[..., Any]:
    """The function named by ``"module:function"``; ValueError unless the module is one of :data:`ADAPTERS`."""
    module, _, name = ref.partition(":")
    if module not in ADAPTERS or not name.isidentifier():
        raise ValueError(f"not a family adapter: {ref!r} (modules: {', '.join(ADAPTERS)})")
    return getattr(importlib.import_module(module), name)


def family(name: str) -> Family:
    """The registered family `name`; ValueError listing the known ones."""
    if name not in FAMILIES:
        raise ValueError(f"unknown family {name!r}; known: {', '.join(FAMILIES)}")
    return FAMILIES[name]


def family_of(path: Path) -> Family:
    """The family a run / model directory or a recording belongs to: an MCAP file by its kind (its channels,
    :func:`pathrl.viz.rerun_view.kind_of`; ViewError if it has none), a directory by the first family whose
    ``detect`` accepts it, else :data:`DEFAULT`. A directory with a ``config.yaml`` (a run or model) belongs to the
    family whose ``tasks`` hold its task (:func:`pathrl.envs.registry.task_cfg`)."""
    path = Path(path)
    if path.is_file():
        from pathrl.viz.rerun_view import kind_of

        return family_of_kind(kind_of(path))
    task = task_of(path)
    if task is not None:
        return next((f for f in FAMILIES.values() if task in f.tasks), FAMILIES[DEFAULT])
    return next((f for f in FAMILIES.values() if f.step("detect")(path)), FAMILIES[DEFAULT])


def task_of(run_dir: Path) -> str | None:
    """The task name of the run config ``run_dir/config.yaml`` (``tracking`` for a config saved before tasks), None
    without a readable one."""
    import yaml

    from pathrl.envs.registry import task_cfg

    try:
        cfg = yaml.safe_load((Path(run_dir) / "config.yaml").read_text())
    except (OSError, yaml.YAMLError):
        return None
    return str(task_cfg(cfg)["name"]) if isinstance(cfg, dict) else None


def recording_of(kind: str) -> Recording:
    """The recording of file kind `kind` (``episodes``, ``run``, ``industrial``, ``trueadapt``)."""
    return next(r for f in FAMILIES.values() for r in f.recordings if r.kind == kind)


def family_of_kind(kind: str) -> Family:
    """The family owning recordings of kind `kind`."""
    return next(f for f in FAMILIES.values() if any(r.kind == kind for r in f.recordings))


def file_names() -> tuple[str, ...]:
    """Every recording file name of every family, in registry order."""
    return tuple(r.file_name for f in FAMILIES.values() for r in f.recordings)
