"""Recording is just another subscriber: every sample of the robot's keys into an MCAP file.

:class:`McapSink` writes :class:`~agent.bus.bridge.RawSample` s: one MCAP channel per
(key, Zenoh encoding), topic = the key expression, schema from the encoding's schema name:

* ``application/protobuf;foxglove.X`` → schema ``foxglove.X``, schema encoding ``protobuf``
  (the SDK's FileDescriptorSet), message encoding ``protobuf``: Foxglove shows laser scans,
  poses, images and scene updates natively.
* ``application/json;loci.Y/N`` → schema ``loci.Y/N``, schema encoding ``jsonschema`` (the
  registry's JSON Schema), message encoding ``json``.
* anything else → no schema, message encoding = the Zenoh MIME type.

Each channel's metadata keeps the Zenoh encoding (``zenoh_encoding``) so a replay can
publish the samples exactly as they were. Log time = when the sample arrived, publish time
= the publisher's Zenoh timestamp when it sent one (else the log time).

Chunks are zstd-compressed and flushed to the file at least every ``flush_interval``
seconds, so a writer that crashes loses at most that much; such a file has no summary, and
:mod:`agent.recording.replay` still reads every complete chunk.

:class:`Recorder` feeds a sink from a :class:`~agent.bus.bridge.Subscription` in the event
loop; the writing (and compression) runs in a worker thread so the loop is not held up.
The file is written in place, not atomically: a partial recording is worth keeping.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import IO, Any

import zenoh
from mcap.writer import CompressionType, Writer

from agent.bus.bridge import BusClosed, BusStats, RawSample, Subscription
from agent.bus.codecs import McapSchema, mcap_schema_for, split_encoding
from agent.bus.keys import Policy
from agent.bus.schemas import SCHEMAS, SchemaRegistry
from knowledge.errors import DataError

log = logging.getLogger(__name__)

#: The MCAP ``library`` field of our recordings.
LIBRARY = "genius-loci"
_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


class McapSink:
    """Writes raw bus samples to an MCAP file (not thread-safe: one writer thread at a time).

    Args:
        path: the output file.
        overwrite: replace an existing file (default: refuse with :class:`DataError`).
        metadata: key/value strings stored as the file's ``loci`` metadata record.
        chunk_size: uncompressed bytes per chunk before it is written out.
        compression: ``"zstd"`` (default), ``"lz4"`` or ``"none"``.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        overwrite: bool = False,
        metadata: Mapping[str, str] | None = None,
        chunk_size: int = 1024 * 1024,
        compression: str = "zstd",
        registry: SchemaRegistry = SCHEMAS,
    ) -> None:
        if compression not in _COMPRESSION:
            raise ValueError(f"compression must be one of {', '.join(_COMPRESSION)}, got {compression!r}")
        self.path = Path(path)
        if self.path.exists() and not overwrite:
            raise DataError(f"{self.path} exists; choose another name or allow overwriting (--force)")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._registry = registry
        self._file: IO[bytes] = self.path.open("wb")
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=_COMPRESSION[compression])
        self._writer.start(profile="", library=LIBRARY)
        self._writer.add_metadata(
            "loci", {"created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **(metadata or {})}
        )
        self._file.flush()
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._sequence: dict[int, int] = {}
        self.messages = 0
        self.closed = False

    def _schema_id(self, schema: McapSchema) -> int:
        sid = self._schemas.get(schema.name)
        if sid is None:
            sid = self._schemas[schema.name] = self._writer.register_schema(
                schema.name, schema.encoding, schema.data
            )
        return sid

    def _channel(self, key: str, encoding: str) -> int:
        cid = self._channels.get((key, encoding))
        if cid is not None:
            return cid
        mime, schema_name = split_encoding(encoding)
        schema = mcap_schema_for(schema_name, self._registry) if schema_name else None
        if schema is not None:
            cid = self._writer.register_channel(
                key, schema.message_encoding, self._schema_id(schema), {"zenoh_encoding": encoding}
            )
        else:
            message_encoding = "json" if mime in ("application/json", "text/json") else mime
            cid = self._writer.register_channel(key, message_encoding, 0, {"zenoh_encoding": encoding})
        self._channels[(key, encoding)] = cid
        return cid

    def write(self, sample: RawSample) -> None:
        """Append one sample."""
        if self.closed:
            raise ValueError(f"{self.path} is closed")
        cid = self._channel(sample.key, sample.encoding)
        seq = self._sequence.get(cid, 0)
        self._sequence[cid] = seq + 1
        self._writer.add_message(
            channel_id=cid,
            log_time=sample.recv_ns,
            data=sample.payload,
            publish_time=sample.source_ns if sample.source_ns is not None else sample.recv_ns,
            sequence=seq & 0xFFFF_FFFF,
        )
        self.messages += 1

    def write_many(self, samples: Iterable[RawSample]) -> None:
        for s in samples:
            self.write(s)

    def flush(self) -> None:
        """Write the open chunk (compressed) and flush the file."""
        if not self.closed:
            self._writer.flush()

    def close(self) -> None:
        """Write the summary (indexes, statistics) and close the file; idempotent."""
        if self.closed:
            return
        self.closed = True
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def __enter__(self) -> McapSink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Recorder:
    """Records every sample matching ``key`` (e.g. ``loci/<robot>/**``) into ``sink``.

    Create it in the event loop; ``await recorder.run()`` until :meth:`stop` (or
    cancellation); what was queued is written before it returns. The sink stays open (the
    caller closes it, which writes the summary).

    Args:
        capacity: samples queued between Zenoh and the writer; a full queue makes Zenoh's
            thread wait up to ``wait_timeout`` s, then drops (counted in ``stats``).
        flush_interval: seconds between chunk flushes (what a crash can lose at most).
    """

    def __init__(
        self,
        session: zenoh.Session,
        sink: McapSink,
        key: str,
        *,
        capacity: int = 4096,
        wait_timeout: float = 0.5,
        flush_interval: float = 1.0,
        stats: BusStats | None = None,
    ) -> None:
        if not flush_interval > 0:
            raise ValueError(f"flush_interval must be > 0 seconds, got {flush_interval}")
        self.sink = sink
        self.flush_interval = flush_interval
        self.subscription: Subscription[RawSample] = Subscription(
            session,
            key,
            _identity,
            policy=Policy.WAIT,
            capacity=capacity,
            wait_timeout=wait_timeout,
            stats=stats,
            name=f"record:{key}",
        )

    @property
    def stats(self) -> dict[str, int]:
        return self.subscription.stats.snapshot()

    def stop(self) -> None:
        """Stop receiving; :meth:`run` writes what is queued and returns."""
        self.subscription.close()

    async def run(self) -> None:
        sub = self.subscription
        loop = asyncio.get_running_loop()
        # one worker thread: every sink call runs there, in order, never two at once
        worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mcap-writer")
        last_flush = time.monotonic()
        try:
            while True:
                timeout = max(0.0, last_flush + self.flush_interval - time.monotonic())
                try:
                    batch = await asyncio.wait_for(sub.recv_batch(256), timeout)
                except TimeoutError:
                    batch = []
                except BusClosed:
                    break
                if batch:
                    await loop.run_in_executor(worker, self.sink.write_many, batch)
                if time.monotonic() - last_flush >= self.flush_interval:
                    await loop.run_in_executor(worker, self.sink.flush)
                    last_flush = time.monotonic()
        finally:
            sub.close()
            rest: list[RawSample] = []
            while (item := sub.try_recv()) is not None:
                rest.append(item)
            tail = [worker.submit(self.sink.write_many, rest), worker.submit(self.sink.flush)]
            # waits for a write still running if the task was cancelled mid-batch
            worker.shutdown(wait=True)
            for f in tail:
                if f.exception() is not None:
                    log.error(
                        "%s: writing the end of the recording failed: %s", self.sink.path, f.exception()
                    )


def _identity(sample: RawSample) -> RawSample:
    return sample


def recording_metadata(robot: str, **extra: Any) -> dict[str, str]:
    """The ``loci`` metadata record of a recording: robot name and free-form strings."""
    return {"robot": robot, **{k: str(v) for k, v in extra.items()}}
