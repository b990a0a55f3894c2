"""The conceptual map as an asyncio service: one owner thread, debounced reasoning, cached snapshot.

owlready2's world may only be touched by one thread and HermiT costs a JVM start (≈0.5–1.4 s)
per reasoning, so:

* every call on the map runs on one worker thread (:meth:`ConceptualService.submit`);
* a change asks for reasoning, which waits ``debounce`` seconds to gather more changes, runs
  off the event loop, and runs again once if changes came in while it ran — many changes, few
  reasonings;
* :meth:`ConceptualService.snapshot` and :meth:`ConceptualService.resolve` answer at once from
  the last snapshot (refreshed after each change and each reasoning); they never wait for Java;
* a change is committed to the SQLite file before :meth:`ConceptualService.submit` returns
  (durable before acknowledged: the robot says "ok" to a fact only once a kill cannot lose
  it; reasoning, which may take a second, is not waited for).
"""

from __future__ import annotations

import asyncio
import copy
import logging
from collections.abc import Awaitable, Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, TypeVar

from knowledge.conceptual import ConceptualMap, InconsistentKnowledge, Resolution, resolve_words
from knowledge.conceptual.lexicon import Lexicon
from knowledge.topology.areas import AreaEvent

log = logging.getLogger(__name__)
T = TypeVar("T")


class ConceptualService:
    """Owns a :class:`ConceptualMap` on one thread and reasons in the background.

    Args:
        path: the SQLite file of the map (None: in memory).
        extra_ontologies: user OWL files (config ``[conceptual] ontologies``).
        java: the Java executable ("" or None: automatic).
        debounce: seconds to wait for more changes before reasoning.
        on_reasoned: called on the event loop with the new snapshot after each reasoning.
        on_error: called on the event loop with a reasoning error (an inconsistency rolled back).
    """

    def __init__(
        self,
        path: Path | None = None,
        extra_ontologies: Sequence[Path] = (),
        java: str | None = None,
        *,
        debounce: float = 0.2,
        on_reasoned: Callable[[dict[str, Any]], None] | None = None,
        on_error: Callable[[Exception], None] | None = None,
    ) -> None:
        if not debounce >= 0:
            raise ValueError(f"debounce must be >= 0 seconds, got {debounce}")
        self.path = path
        self.extra_ontologies = tuple(Path(p) for p in extra_ontologies)
        self.java = java
        self.debounce = float(debounce)
        self.on_reasoned = on_reasoned
        self.on_error = on_error
        self.reasonings = 0
        self.last_error: Exception | None = None
        self._executor: ThreadPoolExecutor | None = None
        self._map: ConceptualMap | None = None
        self._lexicon: Lexicon | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._snapshot: dict[str, Any] = {"version": 0, "reasoned": -1, "areas": {}, "objects": {}}
        self._timer: asyncio.TimerHandle | None = None
        self._running: asyncio.Future[dict[str, Any] | None] | None = None
        self._again = False

    # ---- lifetime ----------------------------------------------------------------------------------

    async def start(self) -> None:
        """Open the map on the owner thread (raises JavaNotFound / ConfigError like the map does)."""
        if self._executor is not None:
            raise RuntimeError("the conceptual service is already started")
        self._loop = asyncio.get_running_loop()
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="conceptual")

        def open_map() -> tuple[ConceptualMap, dict[str, Any]]:
            m = ConceptualMap(self.path, extra_ontologies=self.extra_ontologies, java=self.java or None)
            return m, m.snapshot()

        try:
            m, self._snapshot = await self._loop.run_in_executor(self._executor, open_map)
        except BaseException:
            self._executor.shutdown(wait=False)
            self._executor = None
            raise
        self._map, self._lexicon = m, m.lexicon
        if self._snapshot["reasoned"] < self._snapshot["version"]:
            self.request_reasoning()

    async def close(self) -> None:
        """Finish a running reasoning, save and close the map, stop the thread."""
        if self._executor is None:
            return
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._running is not None:
            await asyncio.gather(self._running, return_exceptions=True)
        executor, m = self._executor, self._map
        self._executor = None
        if m is not None and self._loop is not None:
            await self._loop.run_in_executor(executor, m.close)
        executor.shutdown(wait=True)
        self._map = None

    async def __aenter__(self) -> ConceptualService:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # ---- work on the owner thread ------------------------------------------------------------------

    def submit(self, fn: Callable[[ConceptualMap], T]) -> Awaitable[T]:
        """Run ``fn(map)`` on the owner thread; a change is committed to the file, refreshes the
        snapshot and asks for reasoning (the result comes once the change is committed)."""
        if self._executor is None or self._map is None or self._loop is None:
            raise RuntimeError("the conceptual service is not started")
        m = self._map

        def call() -> tuple[T, dict[str, Any] | None]:
            before = m.version
            out = fn(m)
            if m.version == before:
                return out, None
            m.save()  # committed before anyone is told it is done
            return out, m.snapshot()

        inner = self._loop.run_in_executor(self._executor, call)
        outer: asyncio.Future[T] = self._loop.create_future()

        def done(f: asyncio.Future[tuple[T, dict[str, Any] | None]]) -> None:
            if f.cancelled():
                outer.cancel()
                return
            exc = f.exception()
            if exc is not None:
                if not outer.cancelled():
                    outer.set_exception(exc)
                return
            out, snap = f.result()
            if snap is not None:
                self._snapshot = snap
                self.request_reasoning()
            if not outer.cancelled():
                outer.set_result(out)

        inner.add_done_callback(done)
        return outer

    def apply_area_events(
        self, events: Sequence[AreaEvent], labels: Mapping[int, str | None] | None = None
    ) -> Awaitable[None]:
        """Apply knowledge.topology.areas events (and the current area classes) to the map."""
        events, labels = tuple(events), dict(labels or {})
        return self.submit(lambda m: m.apply_area_events(events, labels))

    # ---- reasoning ---------------------------------------------------------------------------------

    def request_reasoning(self) -> None:
        """Reason within ``debounce`` seconds (changes meanwhile join the same run). Event loop only."""
        if self._executor is None or self._loop is None:
            return
        if self._running is not None:
            self._again = True
        elif self._timer is None:
            self._timer = self._loop.call_later(self.debounce, self._start_reasoning)

    def _start_reasoning(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._executor is None or self._map is None or self._loop is None:
            return
        if self._running is not None:
            self._again = True
            return
        m = self._map

        def work() -> dict[str, Any] | None:
            if m.reasoned_version >= m.version:
                return None
            try:
                m.reason()
            finally:
                m.save()
            return m.snapshot()

        self._again = False
        self._running = self._loop.run_in_executor(self._executor, work)
        self._running.add_done_callback(self._reasoning_done)

    def _reasoning_done(self, f: asyncio.Future[dict[str, Any] | None]) -> None:
        self._running = None
        exc = None if f.cancelled() else f.exception()
        if isinstance(exc, Exception):
            self.last_error = exc
            (log.warning if isinstance(exc, InconsistentKnowledge) else log.error)("conceptual map: %s", exc)
            if self.on_error is not None:
                self.on_error(exc)
            self._refresh_after_error()
        elif not f.cancelled():
            snap = f.result()
            if snap is not None:
                self.reasonings += 1
                self._snapshot = snap
                if self.on_reasoned is not None:
                    self.on_reasoned(copy.deepcopy(snap))
        if self._again:
            self._again = False
            self.request_reasoning()

    def _refresh_after_error(self) -> None:
        if self._executor is None or self._map is None or self._loop is None:
            return
        m = self._map
        fut = self._loop.run_in_executor(self._executor, m.snapshot)

        def set_snapshot(f: asyncio.Future[dict[str, Any]]) -> None:
            if not f.cancelled() and f.exception() is None:
                self._snapshot = f.result()

        fut.add_done_callback(set_snapshot)

    async def flush(self) -> dict[str, Any]:
        """Reason now if anything changed (no debounce), wait for it, and return the snapshot."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        while self._running is not None:
            await asyncio.gather(self._running, return_exceptions=True)
        if self._map is not None and self._snapshot["reasoned"] < self._snapshot["version"]:
            self._start_reasoning()
            if self._running is not None:
                await asyncio.gather(self._running, return_exceptions=True)
        return self.snapshot()

    # ---- answers from the cache --------------------------------------------------------------------

    def snapshot(self) -> dict[str, Any]:
        """The last snapshot (a copy, loci.concepts/1 body); returns at once."""
        return copy.deepcopy(self._snapshot)

    def resolve(self, words: str) -> Resolution:
        """Resolve words against the cached snapshot (see :func:`knowledge.conceptual.resolve_words`)."""
        if self._lexicon is None:
            raise RuntimeError("the conceptual service is not started")
        return resolve_words(self._snapshot, self._lexicon, words)
