"""RSL-RL log writer that records a training run into ``run.mcap`` (resolved config once, scalars per iteration).

Topics: ``/run/config`` (once: the resolved pathrl config and the RSL-RL train cfg),
``/train/scalars`` (per iteration: {"iteration", "values": {tag: value}}). The file is flushed after
every iteration, so a killed run keeps everything up to its last finished iteration.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from rsl_rl.utils.log_writer import LogWriter

from pathrl.logging.mcap_io import McapJsonWriter, iter_messages
from pathrl.logging.schema import RUN_CONFIG, TRAIN_SCALARS

__all__ = ["McapLogWriter"]


class McapLogWriter(LogWriter):
    """Buffers the scalars of one iteration and writes them as one message when the iteration changes."""

    def __init__(self, log_dir: str, file_name: str = "run.mcap", run_config: dict | None = None,
                 keep_through: int | None = None) -> None:
        """``keep_through``: the iteration of the checkpoint a resume starts from. What an earlier (possibly killed)
        run logged up to it is kept; its later scalars (to be redone) are dropped, so every iteration is logged
        once. None (a fresh start) drops the log of an earlier failed or killed start."""
        self.path = Path(log_dir) / file_name
        kept = [] if keep_through is None else [(t, ts, m) for t, ts, m in _salvage(self.path)
                                                if t != TRAIN_SCALARS or m["iteration"] <= keep_through]
        # rewrite into a temp file and rename it over the old log: a kill in between leaves the old log whole
        tmp = self.path.with_name(f".{file_name}.tmp")
        self.writer = McapJsonWriter(tmp)
        self._config_written = False
        for topic, t, obj in kept:
            self.writer.write(topic, obj, t)
            self._config_written |= topic == RUN_CONFIG
        self.writer.flush()
        os.replace(tmp, self.path)  # the open writer goes on writing to the renamed file
        self.writer.path = self.path
        self.run_config = run_config
        self._step: int | None = None
        self._values: dict[str, float] = {}

    def store_config(self, env_cfg: Any, train_cfg: dict) -> None:
        """Write the run config (or `env_cfg` as text) and the RSL-RL `train_cfg` (without the logger) once."""
        if not self._config_written:
            agent = {k: v for k, v in train_cfg.items() if k != "logger"}
            self.writer.write(RUN_CONFIG, {"config": self.run_config or str(env_cfg), "train_cfg": agent})
            self._config_written = True
            self.writer.flush()

    def add_scalar(self, tag: str, scalar_value: float, global_step: int) -> None:
        """Collect one scalar of iteration `global_step` (TensorBoard's signature); an iteration's scalars are
        written as one message when the next iteration starts. ``*/time`` tags join the current iteration."""
        if tag.endswith("/time"):  # RSL-RL logs these against elapsed seconds, not the iteration
            self._values[tag] = float(scalar_value)
            return
        if self._step is not None and global_step != self._step:
            self._emit()
        self._step = int(global_step)
        self._values[tag] = float(scalar_value)

    def _emit(self) -> None:
        """Write the current iteration's scalars as one ``TRAIN_SCALARS`` message and start a new one."""
        if self._step is not None and self._values:
            self.writer.write(TRAIN_SCALARS, {"iteration": self._step, "values": self._values})
            self.writer.flush()
        self._values = {}

    def flush(self) -> None:
        """Write the scalars collected so far (the current iteration's message)."""
        self._emit()

    def stop(self) -> None:
        """Write the last scalars and close the MCAP file."""
        self._emit()
        self.writer.close()


def _salvage(path: Path) -> list[tuple[str, int, Any]]:
    """Messages of an existing run.mcap (finished or not); the new writer then rewrites the file."""
    return list(iter_messages(path)) if path.exists() else []

