"""Job runner of the generators: chunks of a split, run in-process or in worker processes (joblib/loky)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from pathrl.dataset.io import DatasetError

__all__ = ["Job", "SPLIT_IDS", "chunk_jobs", "run_jobs", "split_counts"]

SPLIT_IDS = {"train": 0, "test": 1}


@dataclass
class Job:
    """`n` items of chunk `chunk` of split `split`."""

    split: str
    chunk: int
    n: int


def split_counts(dataset_cfg: Mapping[str, Any]) -> dict[str, int]:
    """Items per split (``num_train``, ``num_test``); DatasetError (one line) if one is negative or both are 0."""
    counts = {"train": int(dataset_cfg.get("num_train", 0)), "test": int(dataset_cfg.get("num_test", 0))}
    if any(c < 0 for c in counts.values()) or sum(counts.values()) == 0:
        raise DatasetError(f"dataset.num_train / num_test must be >= 0 and not both 0, got {counts}")
    return counts


def chunk_jobs(counts: Mapping[str, int], chunk: int) -> list[Job]:
    """The jobs of `counts` items per split in chunks of at most `chunk`, train first."""
    return [Job(split, c, min(chunk, counts[split] - c * chunk))
            for split in ("train", "test") for c in range(math.ceil(counts[split] / chunk))]


def run_jobs(
    jobs: list[Job],
    fn: Callable[[Job], dict[str, Any]],
    workers: int,
    progress: bool,
    label: str,
    total: int,
) -> list[dict[str, Any]]:
    """fn(job) for every job, in order; a rich progress bar over `total` items (job.n each)."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    results: list[dict[str, Any] | None] = [None] * len(jobs)
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        disable=not progress,
        transient=False,
    ) as bar:
        task = bar.add_task(label, total=total)
        if workers <= 1 or len(jobs) <= 1:
            for i, job in enumerate(jobs):
                results[i] = fn(job)
                bar.advance(task, job.n)
        else:
            from joblib import Parallel, delayed

            par = Parallel(n_jobs=workers, return_as="generator_unordered", backend="loky")
            for i, res in par(delayed(_indexed)(fn, i, job) for i, job in enumerate(jobs)):
                results[i] = res
                bar.advance(task, jobs[i].n)
    return results  # type: ignore[return-value]


def _indexed(fn: Callable[[Job], dict[str, Any]], i: int, job: Job) -> tuple[int, dict[str, Any]]:
    return i, fn(job)

