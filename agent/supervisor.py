"""Keeping the agent's tasks alive: a task that fails is logged, counted and restarted.

One bad message once stopped the robot: the dialogue task raised, and the agent re-raised
the task's failure and exited. Under :func:`supervise` a task's exception is logged (the
first of its kind with the traceback, then counts: :class:`~agent.ratelog.RateLimitedLog`),
counted in :class:`Restarts`, and the task is started again after a back-off that doubles
from ``backoff`` up to ``max_backoff`` seconds, and falls back to ``backoff`` once a run
lasted ``healthy_after`` seconds. Cancellation and ``KeyboardInterrupt``/``SystemExit`` go
through; a task that returns is over (the agent decides what that means).
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Awaitable, Callable
from typing import Any

from agent.ratelog import RateLimitedLog

__all__ = ["Restarts", "supervise"]

log = logging.getLogger(__name__)


class Restarts:
    """How often each supervised task failed (thread-safe counters, by task name)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: dict[str, int] = {}

    def add(self, name: str) -> int:
        with self._lock:
            self._counts[name] = self._counts.get(name, 0) + 1
            return self._counts[name]

    def __getitem__(self, name: str) -> int:
        with self._lock:
            return self._counts.get(name, 0)

    def as_dict(self) -> dict[str, int]:
        with self._lock:
            return dict(self._counts)

    @property
    def total(self) -> int:
        with self._lock:
            return sum(self._counts.values())


async def supervise(
    name: str,
    start: Callable[[], Awaitable[Any]],
    *,
    restarts: Restarts | None = None,
    restart: bool = True,
    backoff: float = 0.1,
    max_backoff: float = 5.0,
    healthy_after: float = 30.0,
    ratelog: RateLimitedLog | None = None,
) -> None:
    """Run ``await start()`` until it returns; restart it after each failure.

    Args:
        name: the task's name (in the log and the counters).
        start: makes a fresh coroutine of the task each time.
        restarts: where failures are counted.
        restart: False: a failure is logged and counted, and the task stays stopped.
        backoff: seconds before the first restart (doubling, up to ``max_backoff``).
        healthy_after: a run that lasted this long resets the back-off.
        ratelog: the rate-limited log to use (default: one for this task).
    """
    if not 0 < backoff <= max_backoff:
        raise ValueError(f"need 0 < backoff <= max_backoff, got {backoff} and {max_backoff}")
    ratelog = ratelog or RateLimitedLog(log)
    loop = asyncio.get_running_loop()
    delay = backoff
    while True:
        began = loop.time()
        try:
            await start()
            return
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            n = restarts.add(name) if restarts is not None else 0
            if loop.time() - began >= healthy_after:
                delay = backoff
            then = f"restarting it in {delay:.1f} s" if restart else "it stays stopped"
            ratelog(name, "the %s task failed (%d so far): %s; %s", name, n, exc, then, exc=exc)
            if not restart:
                return
        await asyncio.sleep(delay)
        delay = min(2.0 * delay, max_backoff)
