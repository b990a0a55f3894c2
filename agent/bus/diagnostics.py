"""The bus counters as a ``loci.diagnostics/1`` message, published periodically."""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Mapping
from typing import Any

from agent.bus.bridge import BusStats, Publisher

log = logging.getLogger(__name__)


def diagnostics_message(
    stats: BusStats, robot: str, *, started: float | None = None, extra: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """A ``loci.diagnostics/1`` message from the counters.

    ``started`` (epoch seconds) adds the uptime; ``extra`` is free-form (e.g. latencies).
    """
    now = time.time()
    msg: dict[str, Any] = {
        "schema": "loci.diagnostics/1",
        "stamp": now,
        "robot": robot,
        "streams": stats.snapshot(),
    }
    if started is not None:
        msg["uptime"] = max(0.0, now - started)
    if extra:
        msg["extra"] = dict(extra)
    return msg


async def publish_diagnostics(
    publisher: Publisher[dict[str, Any]],
    stats: BusStats,
    robot: str,
    *,
    period: float = 1.0,
    extra: Callable[[], Mapping[str, Any]] | None = None,
) -> None:
    """Publish the counters every ``period`` seconds until cancelled."""
    if not period > 0:
        raise ValueError(f"the diagnostics period must be > 0 seconds, got {period}")
    started = time.time()
    while True:
        await asyncio.sleep(period)
        try:
            publisher.put(
                diagnostics_message(stats, robot, started=started, extra=extra() if extra else None)
            )
        except ValueError:
            log.exception("publishing diagnostics failed")
