"""The one place where Zenoh's callback threads meet the asyncio event loop.

A :class:`Subscription` declares a Zenoh subscriber whose callback (on a Zenoh-owned
thread) copies the sample out of Zenoh (:class:`RawSample`), decodes and validates it there,
and puts the result in a bounded queue; the event loop is woken with
``loop.call_soon_threadsafe`` (at most one wake-up pending per subscription, so a stalled
loop does not pile up callbacks). The bound is enforced on the thread side, so memory stays
bounded even when the loop stops consuming. What a full queue does is the stream's
:class:`~agent.bus.keys.Policy`:

``DROP_OLDEST`` (sensor data)
    The oldest queued item is dropped and counted; the callback never waits.

``WAIT`` (commands)
    The callback waits on a condition variable for the consumer to make room, for at most
    ``wait_timeout`` seconds (default 1 s). Zenoh 1.x runs Python callbacks on one Python
    thread per subscriber, fed by a bounded channel from Zenoh's network threads, so a
    callback that waited forever would end up blocking the whole session. After a timeout
    the new item is dropped and counted, and the subscription is marked congested: while the
    queue stays full, further items are dropped at once (counted) instead of waiting again,
    so a stalled consumer costs one timeout, not one per message. Publishers of these
    streams use Zenoh's blocking congestion control, so nothing is lost on the way.

A sample that does not decode (bad bytes, malformed JSON, wrong schema, wrong types) is
logged (rate-limited) and counted as ``invalid``, never queued and never raised into the
loop. Counters live in :class:`StreamStats`, one per stream, collected in a
:class:`BusStats` that the diagnostics publish.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import zenoh

from agent.bus.codecs import Codec, codec_for, split_encoding
from agent.bus.keys import STREAMS, Policy, stream_key
from agent.ratelog import RateLimitedLog
from knowledge.errors import ProtocolError

T = TypeVar("T")
log = logging.getLogger(__name__)

_COUNTERS = ("received", "delivered", "dropped", "invalid", "published")


@dataclass(frozen=True, slots=True)
class RawSample:
    """A sample copied out of Zenoh.

    Attributes:
        key: the concrete key expression it was published on.
        payload: the payload bytes.
        encoding: the Zenoh encoding string (``application/protobuf;foxglove.LaserScan``).
        recv_ns: when the callback ran, nanoseconds since the Unix epoch (wall clock).
        source_ns: the publisher's Zenoh timestamp in ns since the epoch, if it stamped one.
    """

    key: str
    payload: bytes
    encoding: str
    recv_ns: int
    source_ns: int | None = None

    @classmethod
    def from_zenoh(cls, sample: zenoh.Sample) -> RawSample:
        ts = sample.timestamp
        source_ns = None
        if ts is not None:
            source_ns = int(ts.get_time().timestamp() * 1e9)
        return cls(
            key=str(sample.key_expr),
            payload=sample.payload.to_bytes(),
            encoding=str(sample.encoding),
            recv_ns=time.time_ns(),
            source_ns=source_ns,
        )


class StreamStats:
    """Thread-safe counters of one stream: received, delivered, dropped, invalid, published."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._lock = threading.Lock()
        self._counts = dict.fromkeys(_COUNTERS, 0)
        self.queued = 0

    def add(self, counter: str, n: int = 1) -> None:
        with self._lock:
            self._counts[counter] += n

    def count(self, counter: str) -> int:
        with self._lock:
            return self._counts[counter]

    @property
    def received(self) -> int:
        """Samples that arrived (valid or not)."""
        return self.count("received")

    @property
    def delivered(self) -> int:
        """Items handed to the consumer."""
        return self.count("delivered")

    @property
    def dropped(self) -> int:
        """Items dropped because the queue was full (see :class:`~agent.bus.keys.Policy`)."""
        return self.count("dropped")

    @property
    def invalid(self) -> int:
        """Samples that did not decode or validate (never delivered)."""
        return self.count("invalid")

    @property
    def published(self) -> int:
        """Messages this process published on the stream."""
        return self.count("published")

    def snapshot(self) -> dict[str, int]:
        with self._lock:
            return {**self._counts, "queued": self.queued}


class BusStats:
    """The :class:`StreamStats` of a process, by stream name (created on first use)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._streams: dict[str, StreamStats] = {}

    def stream(self, name: str) -> StreamStats:
        with self._lock:
            st = self._streams.get(name)
            if st is None:
                st = self._streams[name] = StreamStats(name)
            return st

    def snapshot(self) -> dict[str, dict[str, int]]:
        with self._lock:
            streams = list(self._streams.values())
        return {s.name: s.snapshot() for s in streams}


class BusClosed(Exception):
    """The subscription was closed (raised by :meth:`Subscription.recv`)."""


class Subscription(Generic[T]):
    """A Zenoh subscriber whose decoded samples are awaited in the event loop.

    Create it in the loop's thread (it binds to the running loop). ``async for item in sub``
    yields items until :meth:`close`.

    Args:
        session: an open Zenoh session.
        key: the key expression (wildcards allowed).
        decode: turns a :class:`RawSample` into the item, on Zenoh's thread; raises
            :class:`ProtocolError` (or ``ValueError``) for an invalid sample.
        policy: what a full queue does (see the module docstring).
        capacity: the queue's bound (>= 1).
        wait_timeout: ``WAIT`` only: longest time a callback waits for room, seconds.
        stats: where the counters go (a fresh :class:`BusStats` if None).
        name: the counters' name (default: the key expression).
    """

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        decode: Callable[[RawSample], T],
        *,
        policy: Policy = Policy.DROP_OLDEST,
        capacity: int = 16,
        wait_timeout: float = 1.0,
        stats: BusStats | None = None,
        name: str | None = None,
        loop: asyncio.AbstractEventLoop | None = None,
    ) -> None:
        if capacity < 1:
            raise ValueError(f"a subscription queue needs capacity >= 1, got {capacity}")
        if not wait_timeout > 0:
            raise ValueError(f"wait_timeout must be > 0 seconds, got {wait_timeout}")
        self.key = key
        self.policy = policy
        self.capacity = capacity
        self.wait_timeout = wait_timeout
        self.stats = (stats or BusStats()).stream(name or key)
        self._decode = decode
        self._loop = loop or asyncio.get_running_loop()
        self._cond = threading.Condition(threading.Lock())
        self._items: collections.deque[T] = collections.deque()
        self._waiter: asyncio.Future[None] | None = None
        self._wake_pending = False
        self._congested = False
        self._closed = False
        self._log = RateLimitedLog(log, level=logging.WARNING)
        self._sub = session.declare_subscriber(key, self._on_sample)

    # ---- Zenoh's thread ------------------------------------------------------------------

    def _on_sample(self, sample: zenoh.Sample) -> None:
        if self._closed or sample.kind != zenoh.SampleKind.PUT:
            return
        self.stats.add("received")
        try:
            item = self._decode(RawSample.from_zenoh(sample))
        except (ProtocolError, ValueError) as exc:
            self.stats.add("invalid")
            self._log("invalid", "%s: dropped an invalid message: %s", self.stats.name, exc)
            return
        except Exception as exc:  # a decoder bug: logged in full once per kind, then counted
            self.stats.add("invalid")
            self._log(
                "decode",
                "%s: decoding a message failed unexpectedly",
                self.stats.name,
                exc=exc,
                level=logging.ERROR,
            )
            return
        self._offer(item)

    def _offer(self, item: T) -> None:
        wake = False
        with self._cond:
            if self._closed:
                return
            if len(self._items) >= self.capacity:
                if self.policy is Policy.DROP_OLDEST:
                    self._items.popleft()
                    self.stats.add("dropped")
                else:
                    if not self._congested:
                        self._cond.wait_for(
                            lambda: self._closed or len(self._items) < self.capacity, self.wait_timeout
                        )
                    if self._closed:
                        return
                    if len(self._items) >= self.capacity:
                        self._congested = True
                        self.stats.add("dropped")
                        self._log(
                            "stalled",
                            "%s: the consumer is stalled (queue of %d full); dropping new messages",
                            self.stats.name,
                            self.capacity,
                        )
                        return
            self._congested = False
            self._items.append(item)
            self.stats.queued = len(self._items)
            if self._waiter is not None and not self._wake_pending:
                self._wake_pending = wake = True
        if wake:
            try:
                self._loop.call_soon_threadsafe(self._wake)
            except RuntimeError:  # the loop is closed: nobody will read any more
                self._closed = True

    # ---- the loop's thread ---------------------------------------------------------------

    def _wake(self) -> None:
        with self._cond:
            self._wake_pending = False
            waiter, self._waiter = self._waiter, None
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def _pop(self, max_items: int) -> list[T]:
        """Take up to ``max_items`` (caller holds the lock)."""
        n = min(max_items, len(self._items))
        out = [self._items.popleft() for _ in range(n)]
        if n:
            self.stats.queued = len(self._items)
            self.stats.add("delivered", n)
            if self.policy is Policy.WAIT:
                self._cond.notify(n)
        return out

    async def recv_batch(self, max_items: int = 64) -> list[T]:
        """Wait for at least one item, return up to ``max_items`` (oldest first).

        Raises:
            BusClosed: the subscription is closed and empty.
        """
        while True:
            with self._cond:
                items = self._pop(max_items)
                if items:
                    return items
                if self._closed:
                    raise BusClosed(self.key)
                if self._waiter is None or self._waiter.done():
                    self._waiter = self._loop.create_future()
                waiter = self._waiter
            await waiter

    async def recv(self) -> T:
        """Wait for the next item (raises :class:`BusClosed` once closed and empty)."""
        return (await self.recv_batch(1))[0]

    def try_recv(self) -> T | None:
        """The next item if one is queued, else None (never waits)."""
        with self._cond:
            items = self._pop(1)
        return items[0] if items else None

    def __aiter__(self) -> Subscription[T]:
        return self

    async def __anext__(self) -> T:
        try:
            return await self.recv()
        except BusClosed:
            raise StopAsyncIteration from None

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Undeclare the subscriber and wake every waiter; queued items can still be read."""
        with self._cond:
            if self._closed:
                return
            self._closed = True
            self._cond.notify_all()
            waiter, self._waiter = self._waiter, None
        with contextlib.suppress(zenoh.ZError):  # the session is already closed
            self._sub.undeclare()
        if waiter is not None and not waiter.done():
            if _in_loop(self._loop):
                waiter.set_result(None)
            else:
                with contextlib.suppress(RuntimeError):  # the loop is closed
                    self._loop.call_soon_threadsafe(_set_if_pending, waiter)

    def __enter__(self) -> Subscription[T]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _in_loop(loop: asyncio.AbstractEventLoop) -> bool:
    try:
        return asyncio.get_running_loop() is loop
    except RuntimeError:
        return False


def _set_if_pending(fut: asyncio.Future[None]) -> None:
    if not fut.done():
        fut.set_result(None)


def _schema_checked(codec: Codec[T]) -> Callable[[RawSample], T]:
    def decode(sample: RawSample) -> T:
        _, schema = split_encoding(sample.encoding)
        if schema and schema != codec.schema:
            raise ProtocolError(f"{sample.key}: expected {codec.schema}, the sample says {schema}")
        return codec.decode(sample.payload)

    return decode


def subscribe(
    session: zenoh.Session,
    key: str,
    codec: Codec[T],
    *,
    policy: Policy = Policy.DROP_OLDEST,
    capacity: int = 16,
    wait_timeout: float = 1.0,
    stats: BusStats | None = None,
    name: str | None = None,
) -> Subscription[T]:
    """A :class:`Subscription` decoding with ``codec``.

    A sample whose Zenoh encoding names another schema is invalid; one without a schema in
    its encoding is decoded anyway (JSON payloads still name theirs).
    """
    return Subscription(
        session,
        key,
        _schema_checked(codec),
        policy=policy,
        capacity=capacity,
        wait_timeout=wait_timeout,
        stats=stats,
        name=name,
    )


def subscribe_stream(
    session: zenoh.Session,
    robot: str,
    stream: str,
    *,
    capacity: int | None = None,
    stats: BusStats | None = None,
) -> Subscription[Any]:
    """Subscribe to a stream of :data:`~agent.bus.keys.STREAMS` with its codec and policy.

    ``capacity`` defaults to 4 for ``DROP_OLDEST`` streams (only the newest matters) and 64
    for ``WAIT`` streams. The counters are named after the stream.
    """
    spec = STREAMS[stream]
    cap = capacity or (4 if spec.policy is Policy.DROP_OLDEST else 64)
    return subscribe(
        session,
        stream_key(robot, stream),
        codec_for(spec.schema),
        policy=spec.policy,
        capacity=cap,
        stats=stats,
        name=stream,
    )


class Publisher(Generic[T]):
    """A Zenoh publisher that encodes with a codec and counts what it sends.

    ``DROP_OLDEST`` streams publish with congestion control DROP and ``express`` (no
    batching: lowest latency); ``WAIT`` streams with BLOCK and interactive priority.
    ``put`` may be called from the event loop: it does not wait on the network.
    """

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        codec: Codec[T],
        *,
        policy: Policy = Policy.DROP_OLDEST,
        stats: BusStats | None = None,
        name: str | None = None,
    ) -> None:
        self.key = key
        self.codec = codec
        self.stats = (stats or BusStats()).stream(name or key)
        self._encoding = zenoh.Encoding(codec.zenoh_encoding)
        if policy is Policy.WAIT:
            self._pub = session.declare_publisher(
                key,
                encoding=self._encoding,
                congestion_control=zenoh.CongestionControl.BLOCK,
                priority=zenoh.Priority.INTERACTIVE_HIGH,
            )
        else:
            self._pub = session.declare_publisher(
                key, encoding=self._encoding, congestion_control=zenoh.CongestionControl.DROP, express=True
            )

    def put(self, value: T) -> None:
        """Encode and publish (a bad value raises ``ValueError``/:class:`ProtocolError` here)."""
        self.put_bytes(self.codec.encode(value))

    def put_bytes(self, data: bytes) -> None:
        """Publish bytes already encoded with this publisher's codec."""
        self._pub.put(data)
        self.stats.add("published")

    def close(self) -> None:
        with contextlib.suppress(zenoh.ZError):
            self._pub.undeclare()

    def __enter__(self) -> Publisher[T]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def publish_stream(
    session: zenoh.Session, robot: str, stream: str, *, stats: BusStats | None = None
) -> Publisher[Any]:
    """A :class:`Publisher` for a stream of :data:`~agent.bus.keys.STREAMS` (codec, QoS, name)."""
    spec = STREAMS[stream]
    return Publisher(
        session,
        stream_key(robot, stream),
        codec_for(spec.schema),
        policy=spec.policy,
        stats=stats,
        name=stream,
    )
