"""A driver on its own thread keeps reading while the caller's loop is busy (drivers.threaded)."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import AsyncIterator

import numpy as np
import pytest

from drivers.threaded import ThreadedSource
from knowledge.errors import DeviceError


class Ticker:
    """Yields (its thread, the time it read the item) every ``period`` seconds."""

    def __init__(self, period: float = 0.01, fail_start: bool = False, stop_after: int | None = None) -> None:
        self.period = period
        self.fail_start = fail_start
        self.stop_after = stop_after
        self.started = self.closed = False

    async def start(self) -> None:
        if self.fail_start:
            raise DeviceError("no scanner answers")
        self.started = True

    async def close(self) -> None:
        self.closed = True

    async def __aiter__(self) -> AsyncIterator[tuple[str, float]]:
        n = 0
        while not self.closed:
            await asyncio.sleep(self.period)
            n += 1
            yield threading.current_thread().name, time.monotonic()
            if self.stop_after is not None and n >= self.stop_after:
                return


def test_reading_goes_on_while_the_callers_loop_stands_still() -> None:
    async def run() -> tuple[list[tuple[str, float]], ThreadedSource[tuple[str, float]]]:
        src = ThreadedSource(Ticker(), name="ticker")
        await src.start()
        got = [await src.recv()]
        time.sleep(0.3)  # the caller's loop is blocked (a long scan)
        while len(got) < 40:
            got.append(await src.recv())
        await src.close()
        return got, src

    got, src = asyncio.run(run())
    assert {name for name, _ in got} == {"ticker"}
    read = np.array([t for _, t in got])
    assert np.all(np.diff(read) > 0.004)  # read one by one as they came, not in a burst afterwards
    assert src.dropped == 0
    assert src.driver.closed  # type: ignore[attr-defined]


def test_a_caller_more_than_capacity_behind_loses_the_oldest_counted() -> None:
    async def run() -> tuple[list[tuple[str, float]], int]:
        src = ThreadedSource(Ticker(0.002), capacity=5)
        await src.start()
        time.sleep(0.2)
        got = [await src.recv() for _ in range(5)]
        await src.close()
        return got, src.dropped

    got, dropped = asyncio.run(run())
    assert dropped > 20
    read = [t for _, t in got]
    assert read == sorted(read)


def test_a_failed_start_raises_and_stops_the_thread() -> None:
    async def run() -> None:
        src = ThreadedSource(Ticker(fail_start=True), name="bad")
        with pytest.raises(DeviceError, match="no scanner"):
            await src.start()

    before = threading.active_count()
    asyncio.run(run())
    assert threading.active_count() == before


def test_the_end_of_the_driver_ends_the_iteration() -> None:
    async def run() -> int:
        src = ThreadedSource(Ticker(0.001, stop_after=7))
        await src.start()
        n = 0
        async for _ in src:
            n += 1
        await src.close()
        return n

    assert asyncio.run(run()) == 7
