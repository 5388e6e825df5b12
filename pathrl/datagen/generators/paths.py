"""The chunked, seeded pipeline of the path kinds: chunks of a split run in worker processes, each from its own
random streams (:func:`pathrl.datagen.generators.context.chunk_rngs`); the result is saved with statistics of
the stored knots and of the default knot strategy (whose knots are cached)."""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pathrl.datagen.generators import path_kind
from pathrl.datagen.generators.context import chunk_rngs, process_context
from pathrl.datagen.generators.defaults import resolve_params
from pathrl.datagen.generators.jobs import SPLIT_IDS, Job, chunk_jobs, run_jobs, split_counts
from pathrl.dataset.io import (
    Dataset,
    DatasetError,
    check_destination,
    save_dataset,
    strategy_key,
    write_cache,
)
from pathrl.dataset.stats import path_lengths_and_gaps
from pathrl.paths.knots import KnotStrategy
from pathrl.robot.model import RobotSpec, load_robot

__all__ = ["generate_chunk", "generate_paths"]


def _path_metrics(knots_list: Sequence[np.ndarray]) -> np.ndarray:
    counts, lengths, gaps = path_lengths_and_gaps(knots_list)
    return np.stack([counts, lengths, gaps], axis=1) if len(counts) else np.zeros((0, 3))


def generate_chunk(
    robot_cfg: Mapping[str, Any],
    kind: str,
    params: Mapping[str, Any],
    seed: int,
    split_id: int,
    chunk: int,
    n: int,
) -> dict[str, Any]:
    """Generate one chunk: stored knots, knots under the default strategy and per-path metrics of both."""
    ctx = process_context(robot_cfg)
    rng, tgen = chunk_rngs(seed, split_id, chunk)
    stats: dict[str, int] = {}
    t0 = time.perf_counter()
    stored = path_kind(kind).stored_paths(ctx, params, n, rng, tgen, stats)
    strategy = KnotStrategy.from_cfg(params["default_knots"])
    resampled = [strategy.apply(k) for k in stored]
    return {
        "stored": stored,
        "resampled": resampled,
        "metrics_stored": _path_metrics(stored),
        "metrics_resampled": _path_metrics(resampled),
        "stats": stats,
        "seconds": time.perf_counter() - t0,
    }


def _metrics_stats(metrics: np.ndarray) -> dict[str, Any]:
    if len(metrics) == 0:
        return {"count": 0}
    c, length, g = metrics[:, 0], metrics[:, 1], metrics[:, 2]
    return {
        "count": len(metrics),
        "knots": {"min": int(c.min()), "mean": float(c.mean()), "max": int(c.max())},
        "length": {"min": float(length.min()), "mean": float(length.mean()), "max": float(length.max())},
        "max_knot_gap": float(g.max()),
    }


@dataclass
class _ChunkFn:
    robot_cfg: dict[str, Any]
    kind: str
    params: dict[str, Any]
    seed: int

    def __call__(self, job: Job) -> dict[str, Any]:
        return generate_chunk(self.robot_cfg, self.kind, self.params, self.seed, SPLIT_IDS[job.split], job.chunk, job.n)


@dataclass
class _Collected:
    """Chunk results gathered per split."""

    splits: dict[str, list[tuple[str, np.ndarray]]]
    resampled: dict[str, list[np.ndarray]]
    stats: dict[str, Any]
    gen_stats: dict[str, int]
    cpu: float


def _collect(jobs: Sequence[Job], results: Sequence[dict[str, Any]], skey: str) -> _Collected:
    """Named stored knots, resampled knots and statistics (stored / `skey`) per split, summed counters."""
    splits: dict[str, list[tuple[str, np.ndarray]]] = {"train": [], "test": []}
    resampled: dict[str, list[np.ndarray]] = {"train": [], "test": []}
    metrics: dict[str, list[np.ndarray]] = {"train": [], "test": []}
    metrics_r: dict[str, list[np.ndarray]] = {"train": [], "test": []}
    gen_stats: dict[str, int] = {}
    cpu = 0.0
    for job, res in zip(jobs, results, strict=True):
        for k in res["stored"]:
            splits[job.split].append((f"{job.split}_{len(splits[job.split]):05d}", k))
        resampled[job.split].extend(res["resampled"])
        metrics[job.split].append(res["metrics_stored"])
        metrics_r[job.split].append(res["metrics_resampled"])
        for key, val in res["stats"].items():
            gen_stats[key] = gen_stats.get(key, 0) + int(val)
        cpu += res["seconds"]
    stats = {}
    for split in splits:
        ms = np.concatenate(metrics[split]) if metrics[split] else np.zeros((0, 3))
        mr = np.concatenate(metrics_r[split]) if metrics_r[split] else np.zeros((0, 3))
        stats[split] = {"stored": _metrics_stats(ms), skey: _metrics_stats(mr)}
    return _Collected(splits, resampled, stats, gen_stats, cpu)


def _checked_request(
    kind: str, spec: RobotSpec, dataset_cfg: Mapping[str, Any], dest: str | None, workers: int, overwrite: bool
) -> tuple[dict[str, Any], int, dict[str, int], str]:
    """(params, seed, counts per split, destination) of a request; DatasetError (one line) before any work."""
    path_kind(kind).check_robot(spec)
    if spec.dof != spec.path_dof:
        raise DatasetError(
            f"robot {spec.name!r} controls joints outside the path; generate with a robot whose joints are "
            f"all path joints (e.g. armar4 for armar4_legs: the datasets share path_joints)"
        )
    params = resolve_params(kind, spec.name, dataset_cfg.get("params"))
    seed = int(dataset_cfg.get("seed", 0))
    counts = split_counts(dataset_cfg)
    dest = str(dest if dest is not None else dataset_cfg["path"])
    check_destination(dest, overwrite)
    if workers < 1:
        raise DatasetError(f"workers must be >= 1, got {workers}")
    return params, seed, counts, dest


def generate_paths(
    kind: str,
    robot_cfg: Mapping[str, Any],
    dataset_cfg: Mapping[str, Any],
    dest: str | None = None,
    workers: int = 1,
    overwrite: bool = False,
    progress: bool = True,
) -> Dataset:
    """Generate and save a path dataset (train + test) of `kind` as configured by a resolved robot and dataset config.

    The destination is checked before any work; the result is written atomically. The default knot
    strategy's resampled knots are written to the dataset's cache, and meta["stats"] holds the stored
    and the resampled statistics per split.
    """
    robot_cfg = dict(robot_cfg)
    spec = load_robot(robot_cfg)
    params, seed, counts, dest = _checked_request(kind, spec, dataset_cfg, dest, workers, overwrite)
    t0 = time.perf_counter()
    jobs = chunk_jobs(counts, int(params["chunk_size"]))
    fn = _ChunkFn(robot_cfg, kind, params, seed)
    results = run_jobs(jobs, fn, workers, progress, f"{spec.name}/{kind}", sum(counts.values()))
    strategy = KnotStrategy.from_cfg(params["default_knots"])
    got = _collect(jobs, results, strategy_key(strategy))
    elapsed = time.perf_counter() - t0
    meta = {
        "robot": spec.name,
        "kind": kind,
        "path_joints": list(spec.path_joints),
        "seed": seed,
        "generator": {
            "name": str(dataset_cfg.get("name", kind)),
            "kind": kind,
            "params": params,
            "num_train": counts["train"],
            "num_test": counts["test"],
            "robot_config": robot_cfg,
        },
        "source": "generated",
        "default_knots": dict(params["default_knots"]),
        "generation": {
            "seconds": round(elapsed, 2),
            "worker_seconds": round(got.cpu, 2),
            "workers": workers,
            **got.gen_stats,
        },
    }
    ds = save_dataset(dest, got.splits, meta, overwrite=overwrite, stats=got.stats)
    for split in got.splits:
        if got.resampled[split]:
            write_cache(ds, split, strategy, got.resampled[split])
    return ds
