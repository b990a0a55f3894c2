"""Logging a repeated problem once in full, then as counts.

A bad message that arrives 200 times a second must not write 200 tracebacks a second into
the robot's journal (a flood of malformed messages once logged 569 in 3 s).
:class:`RateLimitedLog` logs the first occurrence of each kind of problem with its traceback,
counts the repeats, and writes at most one line per ``period`` saying how many were not
logged. The kind is a key the caller chooses plus, for an exception, its type: a new kind
of failure in the same place gets its own traceback.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["RateLimitedLog"]


@dataclass
class _Kind:
    total: int = 0
    unreported: int = 0
    last: float = -float("inf")


class RateLimitedLog:
    """Logs each kind of problem in full once, then at most once per ``period`` with counts.

    Thread-safe (Zenoh callbacks call it from their own threads).

    Args:
        logger: where the lines go.
        period: seconds between two lines of the same kind.
        level: the level of the lines.
        clock: monotonic seconds (tests pass their own).
    """

    def __init__(
        self,
        logger: logging.Logger,
        period: float = 10.0,
        *,
        level: int = logging.ERROR,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not period >= 0:
            raise ValueError(f"period must be >= 0 seconds, got {period}")
        self.logger = logger
        self.period = float(period)
        self.level = level
        self._clock = clock
        self._lock = threading.Lock()
        self._kinds: dict[tuple[str, str], _Kind] = {}

    def __call__(
        self, key: str, msg: str, *args: Any, exc: BaseException | None = None, level: int | None = None
    ) -> bool:
        """Log ``msg % args`` for the kind ``(key, type(exc))`` unless it was logged within
        ``period``; the first line of a kind carries ``exc``'s traceback, later ones say how
        many occurrences were not logged. Returns whether a line was written."""
        kind_key = (key, type(exc).__qualname__ if exc is not None else "")
        now = self._clock()
        with self._lock:
            kind = self._kinds.setdefault(kind_key, _Kind())
            kind.total += 1
            first = kind.total == 1
            if not first and now - kind.last < self.period:
                kind.unreported += 1
                return False
            skipped, kind.unreported, kind.last, total = kind.unreported, 0, now, kind.total
        if first:
            self.logger.log(level or self.level, msg, *args, exc_info=exc)
        else:
            suffix = f" ({total} times in all, {skipped} not logged since the last line)"
            text = msg % args if args else msg
            if exc is not None:
                text += f" [{type(exc).__name__}: {exc}]"
            self.logger.log(level or self.level, "%s%s", text, suffix)
        return True

    def count(self, key: str, exc_type: type[BaseException] | None = None) -> int:
        """How often the kind occurred (logged or not)."""
        with self._lock:
            kind = self._kinds.get((key, exc_type.__qualname__ if exc_type is not None else ""))
            return kind.total if kind else 0

    def counts(self) -> dict[str, int]:
        """Occurrences by key (all exception types together)."""
        out: dict[str, int] = {}
        with self._lock:
            for (key, _), kind in self._kinds.items():
                out[key] = out.get(key, 0) + kind.total
        return out
