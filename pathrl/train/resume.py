"""Resuming a run: the checkpoint to continue from, the config it must match, and whether anything is left to do."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml

from pathrl.config.migrate import migrate
from pathrl.logging.mcap_io import is_finished
from pathrl.storage import (
    CheckpointError,
    checkpoint_iteration,
    clean_leftovers,
    latest_checkpoint,
    latest_valid_checkpoint,
    run_checkpoints,
)

__all__ = ["RESUME_MAY_CHANGE", "config_change", "finished_summary", "resume_checkpoint", "resume_point",
           "saved_config"]


def resume_point(run_dir: Path) -> Path | None:
    """The checkpoint a resume continues from: the newest one that verifies. Temp files of interrupted writes
    are removed and damaged newer checkpoints renamed to ``*.damaged`` (kept for inspection, never loaded).
    None when the run has no checkpoint yet; an error when it has some but none verifies."""
    clean_leftovers(run_dir)
    newest, ckpt = latest_checkpoint(run_dir), latest_valid_checkpoint(run_dir)
    if newest is not None and ckpt is None:
        raise CheckpointError(f"{run_dir}: no checkpoint verifies; nothing to resume from")
    for path in run_checkpoints(run_dir):
        if ckpt is not None and checkpoint_iteration(path) > checkpoint_iteration(ckpt):
            path.rename(path.with_name(path.name + ".damaged"))
    return ckpt


def resume_checkpoint(run_dir: Path, cfg: dict[str, Any], resume: bool) -> Path | None:
    """The checkpoint a run resumes from (None: a new run, the leftovers of a killed start cleaned); refuses to
    overwrite checkpoints without `resume` and to resume under another config."""
    if latest_checkpoint(run_dir) is not None and not resume:
        raise FileExistsError(f"{run_dir} already holds checkpoints; pass resume=true or choose another run_dir")
    ckpt = resume_point(run_dir) if resume else None
    if ckpt is None:
        clean_leftovers(run_dir)
    if ckpt is not None and (run_dir / "config.yaml").exists():
        diff = config_change(saved_config(run_dir / "config.yaml"), cfg)
        if diff:
            raise ValueError(f"resume with a different config ({diff}); use the same overrides or a new run_dir")
    return ckpt


def finished_summary(run_dir: Path, ckpt: Path | None, total: int) -> dict[str, Any] | None:
    """The run's summary if a resume from `ckpt` has nothing to do: the checkpoint is at or past `total`
    iterations, the summary is the finished one of at least `total` iterations and the log is closed. None
    otherwise (train on, or close the log of a run killed after its last checkpoint)."""
    if ckpt is None or checkpoint_iteration(ckpt) + 1 < total:
        return None
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    log = run_dir / "run.mcap"
    done_its = summary.get("iterations") if isinstance(summary, dict) else None
    done = isinstance(done_its, int) and done_its >= total and "mean_reward" in summary
    return summary if done and log.is_file() and is_finished(log) else None


def saved_config(path: Path) -> dict[str, Any]:
    """A run's saved config.yaml; ValueError (one line) if it is not YAML or not a mapping."""
    try:
        saved = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: invalid YAML ({str(exc).splitlines()[0]}); cannot resume this run") from None
    if not isinstance(saved, dict):
        raise ValueError(f"{path}: expected a mapping of config groups, got {type(saved).__name__}; cannot resume "
                         "this run")
    return saved


#: Top-level keys a resume may change.
RESUME_MAY_CHANGE = frozenset({"resume", "iterations", "compile_limits", "native_limits"})


def config_change(saved: dict[str, Any], cfg: dict[str, Any]) -> str:
    """The first difference (``key: saved != now``) between a run's saved config and the config it is resumed with,
    both in the current layout (:func:`pathrl.config.migrate.migrate`: a key added after the run was saved counts
    as its old behaviour); "" when they agree up to :data:`RESUME_MAY_CHANGE`."""
    return _config_diff(migrate(saved), migrate(cfg), ignore=set(RESUME_MAY_CHANGE))


def _config_diff(a: Any, b: Any, ignore: set[str], prefix: str = "") -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if not prefix and k in ignore:
                continue
            d = _config_diff(a.get(k), b.get(k), ignore, f"{prefix}{k}.")
            if d:
                return d
        return ""
    return "" if a == b else f"{prefix.rstrip('.')}: {a!r} != {b!r}"
