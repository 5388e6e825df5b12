"""MCAP files with JSON messages: run logs (``run.mcap``) and evaluation episodes (``episodes.mcap``).

Writers flush a chunk at every :meth:`McapJsonWriter.flush`, so a killed process leaves a file whose
flushed messages are all readable with :func:`read_messages` (which falls back to a linear scan of an
unfinished file). Channels use JSON encoding with a JSON schema (Foxglove's well-known schema names
where one fits).
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import NonSeekingReader, make_reader
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, Writer

__all__ = ["MCAP_MAGIC", "McapJsonWriter", "dumps", "is_finished", "iter_messages", "read_messages", "topics_of"]

#: The bytes an MCAP file starts and (once finished) ends with.
MCAP_MAGIC = b"\x89MCAP0\r\n"

GENERIC_SCHEMA = {"type": "object"}


def _default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if hasattr(obj, "tolist"):  # torch tensors
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


def dumps(obj: Any) -> bytes:
    """Compact JSON bytes of `obj` (numpy arrays and scalars, tensors and paths converted; NaN / inf kept)."""
    return json.dumps(obj, default=_default, allow_nan=True, separators=(",", ":")).encode()


class McapJsonWriter:
    """Append-only MCAP writer with one JSON channel per topic."""

    def __init__(self, path: str | Path, profile: str = "pathrl", chunk_size: int = 1 << 20) -> None:
        self.path = Path(path)
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        self._writer.start(profile=profile, library="pathrl")
        self._channels: dict[str, int] = {}
        self._seq = 0
        self._closed = False
        self._file.flush()

    def channel(self, topic: str, schema_name: str = "", schema: Mapping[str, Any] | None = None) -> int:
        """Register (once) the channel of `topic`; returns its id."""
        if topic not in self._channels:
            sid = self._writer.register_schema(
                name=schema_name or topic.strip("/").replace("/", "."),
                encoding=SchemaEncoding.JSONSchema,
                data=json.dumps(schema or GENERIC_SCHEMA).encode(),
            )
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding=MessageEncoding.JSON, schema_id=sid
            )
        return self._channels[topic]

    def write(self, topic: str, obj: Any, log_time_ns: int | None = None) -> None:
        """Write `obj` as JSON on `topic` at `log_time_ns` (default: now)."""
        cid = self.channel(topic)
        t = time.time_ns() if log_time_ns is None else int(log_time_ns)
        self._writer.add_message(channel_id=cid, log_time=t, publish_time=t, sequence=self._seq, data=dumps(obj))
        self._seq += 1

    def flush(self) -> None:
        """Close the open chunk and flush it to disk (everything written so far survives a kill)."""
        self._writer.flush()
        self._file.flush()

    def close(self) -> None:
        """Finish the file (idempotent)."""
        if not self._closed:
            self._writer.finish()
            self._file.close()
            self._closed = True

    def __enter__(self) -> McapJsonWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def iter_messages(path: str | Path, topics: Iterable[str] | None = None) -> Iterator[tuple[str, int, Any]]:
    """Yield (topic, log_time_ns, decoded JSON) in file order; reads unfinished (killed) files too."""
    wanted = set(topics) if topics is not None else None
    with open(path, "rb") as f:
        try:
            reader = make_reader(f)
            summary = reader.get_summary()
        except Exception:
            summary = None
        if summary is not None:
            f.seek(0)
            for _, ch, msg in make_reader(f).iter_messages(topics=list(wanted) if wanted else None,
                                                           log_time_order=False):
                yield ch.topic, msg.log_time, json.loads(msg.data)
            return
        f.seek(0)
        try:
            for _, ch, msg in NonSeekingReader(f).iter_messages(log_time_order=False):
                if wanted is None or ch.topic in wanted:
                    yield ch.topic, msg.log_time, json.loads(msg.data)
        except Exception:  # truncated tail of a killed writer: stop at the damage
            return


def read_messages(path: str | Path, topics: Iterable[str] | None = None) -> list[tuple[str, int, Any]]:
    """All messages of `path` (optionally only `topics`) as a list; see :func:`iter_messages`."""
    return list(iter_messages(path, topics))


def topics_of(path: str | Path) -> set[str]:
    """The topics that have messages in the MCAP file at `path`."""
    return {t for t, _, _ in iter_messages(path)}


def is_finished(path: str | Path) -> bool:
    """Whether the MCAP file at `path` ends with the closing magic bytes: finished, not cut off or still open."""
    with open(path, "rb") as f:
        f.seek(0, 2)
        size = f.tell()
        if size < 2 * len(MCAP_MAGIC):
            return False
        f.seek(size - len(MCAP_MAGIC))
        return f.read() == MCAP_MAGIC
