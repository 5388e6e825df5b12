"""Hydra callback for multiruns: one line per job in ``<sweep dir>/jobs.jsonl`` and a summary at the end.

A failing job is recorded and the others keep running (Hydra's sweepers launch the whole batch first);
the summary names every failed job with its one-line error.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from hydra.core.utils import JobReturn, JobStatus
from hydra.experimental.callback import Callback
from omegaconf import DictConfig


class SweepReport(Callback):
    def on_job_end(self, config: DictConfig, job_return: JobReturn, **kwargs: Any) -> None:
        if config.hydra.mode is None or str(config.hydra.mode) != "RunMode.MULTIRUN":
            return
        ok = job_return.status == JobStatus.COMPLETED
        rec = {"job": config.hydra.job.num, "overrides": list(config.hydra.overrides.task),
               "status": "ok" if ok else "failed",
               "error": None if ok else str(job_return._return_value).splitlines()[0]}
        path = Path(config.hydra.sweep.dir) / "jobs.jsonl"
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "a") as f:  # one short append per job: atomic enough across worker processes
            f.write(json.dumps(rec) + "\n")
            f.flush()
            os.fsync(f.fileno())
        if not ok:
            print(f"sweep: job {rec['job']} FAILED [{' '.join(rec['overrides'])}]: {rec['error']}", flush=True)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        path = Path(config.hydra.sweep.dir) / "jobs.jsonl"
        if not path.exists():
            return
        recs = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
        failed = [r for r in recs if r["status"] != "ok"]
        print(f"sweep: {len(recs) - len(failed)}/{len(recs)} jobs finished ({path})")
        for r in failed:
            print(f"  FAILED job {r['job']} [{' '.join(r['overrides'])}]: {r['error']}")
