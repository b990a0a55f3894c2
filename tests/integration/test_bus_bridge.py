"""The thread → asyncio bridge: per-stream policies, counted drops, invalid messages, closing."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable, Coroutine
from typing import Any

import zenoh

from agent.bus.bridge import (
    BusClosed,
    BusStats,
    Publisher,
    RawSample,
    Subscription,
    subscribe,
    subscribe_stream,
)
from agent.bus.codecs import Codec
from agent.bus.diagnostics import diagnostics_message
from agent.bus.keys import Policy
from agent.bus.schemas import SCHEMAS
from agent.bus.testing import session_pair, settle
from knowledge.errors import ProtocolError


def _decode_int(data: bytes) -> int:
    try:
        return int(data)
    except ValueError as exc:
        raise ProtocolError(f"not an integer: {data[:20]!r}") from exc


INT = Codec("loci.test-int/1", "json", lambda i: str(i).encode(), _decode_int)


def run(coro: Coroutine[Any, Any, Any], timeout: float = 20.0) -> Any:
    return asyncio.run(asyncio.wait_for(coro, timeout))


async def until(predicate: Callable[[], bool], timeout: float = 5.0) -> float:
    t0 = time.monotonic()
    while not predicate():
        assert time.monotonic() - t0 < timeout, "condition not met in time"
        await asyncio.sleep(0.002)
    return time.monotonic() - t0


def test_drop_oldest_keeps_the_newest_and_counts_the_rest() -> None:
    async def main() -> tuple[list[int], dict[str, int]]:
        with session_pair() as (a, b):
            sub = subscribe(b, "loci/t/scan", INT, policy=Policy.DROP_OLDEST, capacity=5)
            pub = Publisher(a, "loci/t/scan", INT, policy=Policy.WAIT)  # blocking send: none lost on the way
            settle(a, b)
            for i in range(100):
                pub.put(i)
            await until(lambda: sub.stats.received == 100)  # the consumer was busy elsewhere
            items = []
            while (x := sub.try_recv()) is not None:
                items.append(x)
            sub.close()
            return items, sub.stats.snapshot()

    items, stats = run(main())
    assert items == [95, 96, 97, 98, 99]
    assert stats["dropped"] == 95 and stats["delivered"] == 5 and stats["queued"] == 0


def test_wait_policy_delivers_every_command_to_a_slow_consumer() -> None:
    async def main() -> tuple[list[int], dict[str, int]]:
        with session_pair() as (a, b):
            sub = subscribe(b, "loci/t/cmd", INT, policy=Policy.WAIT, capacity=2, wait_timeout=5.0)
            pub = Publisher(a, "loci/t/cmd", INT, policy=Policy.WAIT)
            settle(a, b)
            for i in range(20):
                pub.put(i)
            got = []
            async for x in sub:
                got.append(x)
                await asyncio.sleep(0.01)  # slower than the publisher
                if len(got) == 20:
                    break
            sub.close()
            return got, sub.stats.snapshot()

    got, stats = run(main())
    assert got == list(range(20))
    assert stats["dropped"] == 0 and stats["delivered"] == 20


def test_wait_policy_gives_up_on_a_stalled_consumer_without_blocking_zenoh() -> None:
    """A consumer that never reads costs one ``wait_timeout``, then new commands drop at once."""
    wait = 0.5

    async def main() -> tuple[float, list[int], dict[str, int], int]:
        with session_pair() as (a, b):
            sub = subscribe(b, "loci/t/cmd", INT, policy=Policy.WAIT, capacity=2, wait_timeout=wait)
            other = subscribe(b, "loci/t/other", INT)  # another stream of the same session
            pub = Publisher(a, "loci/t/cmd", INT, policy=Policy.WAIT)
            pub_other = Publisher(a, "loci/t/other", INT)
            settle(a, b)
            t0 = time.monotonic()
            for i in range(10):
                pub.put(i)
            await until(lambda: sub.stats.received == 10)
            elapsed = time.monotonic() - t0
            pub_other.put(7)
            other_value = await other.recv()  # the session still delivers
            kept = [await sub.recv(), await sub.recv()]
            pub.put(10)  # room again: accepted without waiting
            kept.append(await sub.recv())
            sub.close()
            other.close()
            return elapsed, kept, sub.stats.snapshot(), other_value

    elapsed, kept, stats, other_value = run(main())
    assert kept == [0, 1, 10]  # WAIT keeps the oldest and drops the new ones
    assert stats["dropped"] == 8 and stats["received"] == 11
    assert other_value == 7
    assert elapsed < 4 * wait  # one timeout, not eight (which would be 8 * wait)


def test_invalid_messages_are_counted_never_delivered_and_never_raise() -> None:
    place = {"schema": "loci.place/1", "stamp": 1.0, "label": "room", "probabilities": {"room": 1.0}}
    bad: list[tuple[bytes, str]] = [
        (b"{oops", "application/json;loci.place/1"),  # malformed JSON
        (
            json.dumps({**place, "schema": "loci.graph/1"}).encode(),
            "application/json;loci.place/1",
        ),  # wrong schema
        (json.dumps({**place, "label": 3}).encode(), "application/json;loci.place/1"),  # wrong type
        (json.dumps(place).encode(), "application/json;loci.areas/1"),  # encoding names another schema
        (json.dumps({**place, "probabilities": {"room": 2.0}}).encode(), "application/json"),  # out of range
    ]

    async def main() -> tuple[dict[str, Any], dict[str, int], bool]:
        stats = BusStats()
        with session_pair() as (a, b):
            sub = subscribe_stream(b, "rosie", "place", stats=stats)
            settle(a, b)
            for payload, encoding in bad:
                a.put("loci/rosie/place", payload, encoding=zenoh.Encoding(encoding))
            a.put("loci/rosie/place", json.dumps(place).encode(), encoding=zenoh.Encoding("application/json"))
            got = await sub.recv()
            await until(lambda: sub.stats.received == len(bad) + 1)
            empty = sub.try_recv() is None
            sub.close()
            return got, stats.snapshot()["place"], empty

    got, counts, empty = run(main())
    assert got == place and empty
    assert counts["invalid"] == len(bad) and counts["delivered"] == 1
    diag = diagnostics_message_for(counts)
    SCHEMAS.validate(diag)


def diagnostics_message_for(counts: dict[str, int]) -> dict[str, Any]:
    stats = BusStats()
    for name in ("received", "delivered", "dropped", "invalid"):
        stats.stream("place").add(name, counts[name])
    msg = diagnostics_message(stats, "rosie", started=time.time() - 5, extra={"p99_ms": 1.2})
    assert msg["streams"]["place"]["invalid"] == counts["invalid"]
    assert msg["uptime"] >= 5
    return msg


def test_closing_wakes_the_consumer() -> None:
    async def main() -> tuple[list[int], bool]:
        with session_pair() as (_, b):
            sub: Subscription[RawSample] = Subscription(b, "loci/t/**", lambda s: s)
            got: list[int] = []

            async def consume() -> None:
                async for _ in sub:
                    got.append(1)

            task = asyncio.create_task(consume())
            await asyncio.sleep(0.05)
            sub.close()
            await asyncio.wait_for(task, 2.0)
            try:
                await sub.recv()
            except BusClosed:
                closed = True
            else:
                closed = False
            return got, closed

    got, closed = run(main())
    assert got == [] and closed
