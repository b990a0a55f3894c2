"""A device driver on a thread of its own: its reading and stamping never wait for the caller.

The agent processes each scan on its event loop; a scan that takes long (a first compilation,
a map update, a busy machine) must not stop the laser's serial line from being read, or the
scans that wait in the port's buffer are read late, stamped late and paired with the wrong
odometry (issue 24). :class:`ThreadedSource` runs an asyncio driver (``start()``, ``close()``,
``async for item in driver``: :class:`~drivers.sick.driver.LMS2xx` is one) on its own thread
with its own event loop; what it yields reaches the caller's loop through a bounded queue.

The queue holds ``capacity`` items (about seven seconds of an LMS 2xx's scans by default): a
caller that falls behind gets every item, in order, later; only a caller more than
``capacity`` items behind loses the oldest, counted in ``dropped``. The driver's own
``stats`` and ``info`` are read through (plain counters, safe to read from the caller's
thread).
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import contextlib
import logging
import threading
from collections.abc import AsyncIterator, Coroutine
from typing import Any, Generic, Protocol, TypeVar

from knowledge.errors import DeviceError

__all__ = ["ThreadedSource"]

log = logging.getLogger(__name__)

T = TypeVar("T")
T_co = TypeVar("T_co", covariant=True)


class Source(Protocol[T_co]):
    """What :class:`ThreadedSource` runs: an asyncio driver that yields items."""

    async def start(self) -> None: ...

    async def close(self) -> None: ...

    def __aiter__(self) -> AsyncIterator[T_co]: ...


class ThreadedSource(Generic[T]):
    """``driver`` on a thread of its own (see the module docstring).

    Args:
        driver: the asyncio driver (not started).
        capacity: items kept for a caller that falls behind.
        name: the thread's name.
    """

    def __init__(self, driver: Source[T], *, capacity: int = 256, name: str = "device") -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1 item, got {capacity}")
        self.driver = driver
        self.capacity = capacity
        self.name = name
        #: items pushed out of the full queue (the caller was more than ``capacity`` behind)
        self.dropped = 0
        self._items: collections.deque[T] = collections.deque()
        self._wake: asyncio.Event | None = None
        self._caller: asyncio.AbstractEventLoop | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._pump: concurrent.futures.Future[None] | None = None
        self._ended = False
        self._error: BaseException | None = None
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ lifecycle
    async def start(self) -> None:
        """Start the thread and the driver on it; returns when the driver has started.

        Raises:
            whatever the driver's ``start()`` raised (the thread is stopped again).
        """
        if self._thread is not None:
            raise DeviceError(f"{self.name}: already started")
        self._caller = asyncio.get_running_loop()
        self._wake = asyncio.Event()
        ready = threading.Event()

        def run() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            asyncio.set_event_loop(loop)
            ready.set()
            try:
                loop.run_forever()
            finally:
                with contextlib.suppress(Exception):
                    loop.run_until_complete(loop.shutdown_asyncgens())
                loop.close()

        self._thread = threading.Thread(target=run, name=self.name, daemon=True)
        self._thread.start()
        await asyncio.to_thread(ready.wait)
        try:
            await self._on_thread(self.driver.start())
        except BaseException:
            await self._stop_thread()
            raise
        assert self._loop is not None
        self._pump = asyncio.run_coroutine_threadsafe(self._forward(), self._loop)

    async def close(self) -> None:
        """Close the driver on its thread (it stops its device), then stop the thread."""
        if self._thread is None:
            return
        try:
            if self._loop is not None and self._loop.is_running():
                try:
                    await self._on_thread(self.driver.close())
                except Exception as exc:
                    log.warning("%s: closing the driver: %s", self.name, exc)
                if self._pump is not None:
                    self._pump.cancel()
        finally:
            await self._stop_thread()
            self._end()

    async def _stop_thread(self) -> None:
        loop, thread = self._loop, self._thread
        if loop is not None and loop.is_running():
            loop.call_soon_threadsafe(loop.stop)
        if thread is not None:
            await asyncio.to_thread(thread.join, 5.0)
        self._thread = None

    async def _on_thread(self, coro: Coroutine[Any, Any, Any]) -> Any:
        assert self._loop is not None
        return await asyncio.wrap_future(asyncio.run_coroutine_threadsafe(coro, self._loop))

    # ------------------------------------------------------------------ items
    async def _forward(self) -> None:
        """On the driver's thread: every item to the caller's queue."""
        try:
            async for item in self.driver:
                self._put(item)
        except asyncio.CancelledError:
            raise
        except BaseException as exc:  # the driver failed: the caller hears of it
            self._error = exc
        finally:
            caller = self._caller
            if caller is not None and not caller.is_closed():
                with contextlib.suppress(RuntimeError):
                    caller.call_soon_threadsafe(self._end)

    def _put(self, item: T) -> None:
        with self._lock:
            if len(self._items) >= self.capacity:
                self._items.popleft()
                self.dropped += 1
            self._items.append(item)
        caller, wake = self._caller, self._wake
        if caller is not None and wake is not None and not caller.is_closed():
            with contextlib.suppress(RuntimeError):
                caller.call_soon_threadsafe(wake.set)

    def _end(self) -> None:
        self._ended = True
        if self._wake is not None:
            self._wake.set()

    @property
    def waiting(self) -> int:
        """Items read and not yet taken."""
        with self._lock:
            return len(self._items)

    async def recv(self) -> T:
        """The next item, in order.

        Raises:
            DeviceError: the driver ended (closed, or failed: the cause is chained).
        """
        assert self._wake is not None, "start() first"
        while True:
            with self._lock:
                if self._items:
                    return self._items.popleft()
            if self._ended:
                if self._error is not None:
                    raise DeviceError(f"{self.name}: {self._error}") from self._error
                raise DeviceError(f"{self.name}: closed")
            self._wake.clear()
            with self._lock:
                if self._items:
                    continue
            await self._wake.wait()

    async def __aiter__(self) -> AsyncIterator[T]:
        """Items until the driver ends (a failure is raised)."""
        while True:
            try:
                yield await self.recv()
            except DeviceError:
                if self._ended and self._error is None:
                    return
                raise

    # ------------------------------------------------------------------ read through
    @property
    def stats(self) -> Any:
        return getattr(self.driver, "stats", None)

    @property
    def info(self) -> Any:
        return getattr(self.driver, "info", None)
