"""Hydra callback for multiruns: one line per job in ``<sweep dir>/jobs.jsonl`` and a summary at the end.

A failing job is recorded and the others keep running (the task function returns ``{"error": ...}`` for a
user error instead of raising, so Hydra finishes the sweep); the summary names every failed job with its
one-line error. :func:`sweep_exit_code` turns the record into the process's exit code: the number of failed
jobs (0: all finished).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from hydra.core.utils import JobReturn, JobStatus
from hydra.experimental.callback import Callback
from omegaconf import DictConfig

__all__ = ["LAST_SWEEP", "SweepReport", "job_error", "print_summary", "read_jobs", "sweep_exit_code"]

#: The sweep directory of the multirun this process started (set in the launching process), else None.
LAST_SWEEP: Path | None = None
_SUMMARIZED = False


def job_error(job_return: JobReturn) -> str | None:
    """The one-line error of a finished job, None if it succeeded."""
    if job_return.status != JobStatus.COMPLETED:
        text = str(job_return._return_value).strip()
        return text.splitlines()[0] if text else type(job_return._return_value).__name__
    value = job_return._return_value
    if isinstance(value, dict) and value.get("error"):
        return str(value["error"])
    return None


def read_jobs(sweep_dir: Path) -> list[dict[str, Any]]:
    """The job records of a sweep (``<sweep_dir>/jobs.jsonl``, one dict per finished job: job, overrides, status,
    error); [] if none."""
    path = Path(sweep_dir) / "jobs.jsonl"
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def print_summary(sweep_dir: Path) -> None:
    """Print how many of a sweep's jobs finished and one line per failed job (its overrides and error)."""
    recs = read_jobs(sweep_dir)
    failed = [r for r in recs if r["status"] != "ok"]
    print(f"sweep: {len(recs) - len(failed)}/{len(recs)} jobs finished ({Path(sweep_dir) / 'jobs.jsonl'})", flush=True)
    for r in failed:
        print(f"  FAILED job {r['job']} [{' '.join(r['overrides'])}]: {r['error']}", flush=True)


def sweep_exit_code(fallback: int) -> int:
    """After a multirun: the number of failed jobs (at most 100), printing the summary if Hydra stopped before its
    end callback; `fallback` (the process's own exit code) when no job failed or no multirun ran."""
    if LAST_SWEEP is None:
        return fallback
    recs = read_jobs(LAST_SWEEP)
    if not _SUMMARIZED:
        print_summary(LAST_SWEEP)
    failed = sum(r["status"] != "ok" for r in recs)
    return min(failed, 100) if failed else fallback


class SweepReport(Callback):
    """Hydra callback: appends each multirun job's outcome to ``jobs.jsonl`` and prints the summary when the sweep
    ends."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        """Remember the sweep directory and start a new ``jobs.jsonl`` there."""
        global LAST_SWEEP, _SUMMARIZED
        LAST_SWEEP, _SUMMARIZED = Path(config.hydra.sweep.dir), False
        (LAST_SWEEP / "jobs.jsonl").unlink(missing_ok=True)  # a reused sweep dir starts a new record

    def on_job_end(self, config: DictConfig, job_return: JobReturn, **kwargs: Any) -> None:
        """Append the job's number, overrides, status and one-line error to ``jobs.jsonl`` (multiruns only)."""
        if config.hydra.mode is None or str(config.hydra.mode) != "RunMode.MULTIRUN":
            return
        error = job_error(job_return)
        rec = {"job": config.hydra.job.num, "overrides": list(config.hydra.overrides.task),
               "status": "ok" if error is None else "failed", "error": error}
        path = Path(config.hydra.sweep.dir) / "jobs.jsonl"
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "a") as f:  # one short append per job: atomic enough across worker processes
            f.write(json.dumps(rec) + "\n")
            f.flush()
            os.fsync(f.fileno())
        if error is not None:
            print(f"sweep: job {rec['job']} FAILED [{' '.join(rec['overrides'])}]: {error}", flush=True)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        """Print the sweep's summary."""
        global _SUMMARIZED
        print_summary(Path(config.hydra.sweep.dir))
        _SUMMARIZED = True
