"""Replay is a reader plus pacing.

:class:`McapMessages` reads a recording front to back with mcap's stream (non-seeking)
reader, which needs no summary or index: a file whose writer crashed is read up to its last
complete record, and :attr:`McapMessages.truncated` says that the end was missing.
(mcap's default seeking reader refuses such a file.) Messages come in file order, which for
our recorder is arrival order.

:class:`Replay` paces them: as fast as possible (``speed=None``), or at recorded speed
(``speed=1.0``; 2.0 is twice as fast), optionally cutting long silences to ``max_gap``
seconds, in the manner of python-can's ``MessageSync``. Iterate it with ``for`` (sleeps
with :func:`time.sleep`) or ``async for`` (sleeps with :func:`asyncio.sleep`).
"""

from __future__ import annotations

import asyncio
import logging
import struct
import time
from collections.abc import AsyncIterator, Callable, Collection, Iterator
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.records import Channel, Footer, Message, Schema
from mcap.stream_reader import StreamReader

from agent.bus.codecs import JSON_ENCODING, PROTOBUF_ENCODING
from knowledge.errors import DataError

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class RecordedMessage:
    """One message of a recording.

    Attributes:
        topic: the channel topic (for our recordings, the Zenoh key expression).
        schema: the schema name (``foxglove.LaserScan``, ``loci.place/1``), ``""`` when none.
        schema_encoding: ``protobuf``, ``jsonschema`` or ``""``.
        message_encoding: ``protobuf``, ``json``, ...
        data: the payload bytes.
        log_time_ns: when the recorder received it, ns since the epoch.
        publish_time_ns: when it was published (the publisher's stamp, else the log time).
        zenoh_encoding: the Zenoh encoding to publish it with again.
    """

    topic: str
    schema: str
    schema_encoding: str
    message_encoding: str
    data: bytes
    log_time_ns: int
    publish_time_ns: int
    zenoh_encoding: str

    @property
    def log_time(self) -> float:
        """:attr:`log_time_ns` in seconds."""
        return self.log_time_ns * 1e-9


def _zenoh_encoding(channel: Channel, schema: Schema | None) -> str:
    known = channel.metadata.get("zenoh_encoding")
    if known:
        return known
    if channel.message_encoding == "protobuf":
        return f"{PROTOBUF_ENCODING};{schema.name}" if schema else PROTOBUF_ENCODING
    if channel.message_encoding == "json":
        return f"{JSON_ENCODING};{schema.name}" if schema else JSON_ENCODING
    return "application/octet-stream"


class McapMessages:
    """The messages of an MCAP file in file order, recovering a truncated file.

    Iterate once. Afterwards :attr:`count` is the number of messages yielded,
    and :attr:`truncated` is True when the file ended before its footer (a crashed writer).

    Raises (while iterating):
        DataError: the file is missing, not an MCAP file, or corrupt before its end.
    """

    def __init__(self, path: str | Path, topics: Collection[str] | None = None) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise DataError(f"{self.path}: no such recording")
        self.topics = set(topics) if topics is not None else None
        self.count = 0
        self.truncated = False

    def __iter__(self) -> Iterator[RecordedMessage]:
        schemas: dict[int, Schema] = {}
        channels: dict[int, tuple[Channel, Schema | None, str]] = {}
        with self.path.open("rb") as f:
            reader = StreamReader(f, skip_magic=False)
            try:
                for record in reader.records:
                    if isinstance(record, Message):
                        known = channels.get(record.channel_id)
                        if known is None:
                            raise DataError(f"{self.path}: message on unknown channel {record.channel_id}")
                        channel, schema, zenc = known
                        if self.topics is not None and channel.topic not in self.topics:
                            continue
                        self.count += 1
                        yield RecordedMessage(
                            topic=channel.topic,
                            schema=schema.name if schema else "",
                            schema_encoding=schema.encoding if schema else "",
                            message_encoding=channel.message_encoding,
                            data=record.data,
                            log_time_ns=record.log_time,
                            publish_time_ns=record.publish_time,
                            zenoh_encoding=zenc,
                        )
                    elif isinstance(record, Schema):
                        schemas[record.id] = record
                    elif isinstance(record, Channel):
                        schema = schemas.get(record.schema_id) if record.schema_id else None
                        if record.schema_id and schema is None:
                            raise DataError(
                                f"{self.path}: channel {record.topic!r} names unknown schema {record.schema_id}"
                            )
                        channels[record.id] = (record, schema, _zenoh_encoding(record, schema))
                    elif isinstance(record, Footer):
                        return
            except InvalidMagic as exc:
                raise DataError(f"{self.path}: not an MCAP file ({exc})") from exc
            except (EndOfFile, struct.error):  # cut inside a record: keep what came before
                self._mark_truncated()
            except McapError as exc:
                raise DataError(f"{self.path}: corrupt MCAP data ({exc})") from exc

    def _mark_truncated(self) -> None:
        self.truncated = True
        log.warning(
            "%s ends without a footer (its writer stopped early); read its %d complete messages",
            self.path,
            self.count,
        )


class Replay:
    """A recording's messages, paced.

    Args:
        path: the MCAP file.
        speed: None = as fast as possible; 1.0 = recorded speed; 2.0 = twice as fast.
        max_gap: longest wait between two messages in recorded seconds (longer silences are
            cut to it); None = keep every gap.
        topics: only these topics (default: all).

    After iterating, :attr:`truncated` and :attr:`count` report what was read.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        speed: float | None = None,
        max_gap: float | None = None,
        topics: Collection[str] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if speed is not None and not speed > 0:
            raise ValueError(
                f"speed must be > 0 (1.0 = recorded speed) or None (as fast as possible), got {speed}"
            )
        if max_gap is not None and not max_gap >= 0:
            raise ValueError(f"max_gap must be >= 0 seconds, got {max_gap}")
        self.messages = McapMessages(path, topics)
        self.speed = speed
        self.max_gap = max_gap
        self._clock = clock

    @property
    def truncated(self) -> bool:
        return self.messages.truncated

    @property
    def count(self) -> int:
        return self.messages.count

    def _schedule(self) -> Iterator[tuple[RecordedMessage, float]]:
        """Each message with the clock time (``clock()``) it is due at."""
        start: float | None = None
        virtual = 0.0
        prev_ns: int | None = None
        for msg in self.messages:
            if start is None:
                start = self._clock()
            elif self.speed is not None and prev_ns is not None:
                gap = max(0.0, (msg.log_time_ns - prev_ns) * 1e-9)
                virtual += gap if self.max_gap is None else min(gap, self.max_gap)
            prev_ns = msg.log_time_ns
            yield msg, start + virtual / (self.speed or 1.0)

    def __iter__(self) -> Iterator[RecordedMessage]:
        for msg, due in self._schedule():
            if self.speed is not None:
                delay = due - self._clock()
                if delay > 0:
                    time.sleep(delay)
            yield msg

    async def __aiter__(self) -> AsyncIterator[RecordedMessage]:
        for msg, due in self._schedule():
            if self.speed is not None:
                delay = due - self._clock()
                if delay > 0:
                    await asyncio.sleep(delay)
            else:
                await asyncio.sleep(0)  # let other tasks run between messages
            yield msg
