"""agent.supervisor and agent.ratelog: a failing task is restarted with back-off, and a
repeated failure is logged in full once, then as counts."""

from __future__ import annotations

import asyncio
import itertools
import logging

import pytest

from agent.ratelog import RateLimitedLog
from agent.supervisor import Restarts, supervise

log = logging.getLogger("test.supervisor")


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_first_of_a_kind_has_its_traceback_then_one_line_per_period_with_counts(
    caplog: pytest.LogCaptureFixture,
) -> None:
    clock = Clock()
    ratelog = RateLimitedLog(log, period=10.0, clock=clock)
    with caplog.at_level(logging.INFO, logger="test.supervisor"):
        for i in range(569):  # the flood of failure 6, in 3 s
            clock.t = i * 3.0 / 569
            try:
                raise RuntimeError(f"bad message {i}")
            except RuntimeError as exc:
                ratelog("decode", "decoding failed: %s", exc, exc=exc)
        assert len(caplog.records) == 1 and caplog.records[0].exc_info is not None
        # another kind in the same place: its own traceback at once
        ratelog("decode", "decoding failed", exc=KeyError("x"))
        assert len(caplog.records) == 2 and caplog.records[1].exc_info is not None
        clock.t = 12.0
        assert ratelog("decode", "decoding failed: %s", "again", exc=RuntimeError("again"))
    last = caplog.records[-1]
    assert last.exc_info is None
    assert "570 times in all, 568 not logged" in last.getMessage()
    assert ratelog.count("decode", RuntimeError) == 570 and ratelog.counts() == {"decode": 571}


def test_a_failing_task_is_restarted_with_doubling_back_off_until_it_succeeds(
    caplog: pytest.LogCaptureFixture,
) -> None:
    starts: list[float] = []

    async def flaky() -> str:
        starts.append(asyncio.get_running_loop().time())
        if len(starts) < 5:
            raise ValueError(f"failure {len(starts)}")
        return "done"

    async def main() -> Restarts:
        restarts = Restarts()
        await asyncio.wait_for(
            supervise("flaky", flaky, restarts=restarts, backoff=0.01, max_backoff=0.04), 5
        )
        return restarts

    with caplog.at_level(logging.ERROR, logger="agent.supervisor"):
        restarts = asyncio.run(main())
    assert restarts.as_dict() == {"flaky": 4} and restarts.total == 4
    gaps = [b - a for a, b in itertools.pairwise(starts)]
    # the back-off doubles up to its bound (lower bounds: a sleep may last longer, never shorter)
    assert all(g >= 0.9 * want for g, want in zip(gaps, (0.01, 0.02, 0.04, 0.04), strict=True)), gaps
    assert caplog.records[0].exc_info is not None  # the first failure with its traceback
    assert "failure 1" in caplog.records[0].getMessage()


def test_a_task_that_may_not_restart_stays_stopped_and_cancellation_goes_through() -> None:
    calls = 0

    async def broken() -> None:
        nonlocal calls
        calls += 1
        raise OSError("disk full")

    async def forever() -> None:
        await asyncio.sleep(3600)

    async def main() -> None:
        restarts = Restarts()
        await supervise("recorder", broken, restarts=restarts, restart=False)
        assert calls == 1 and restarts["recorder"] == 1
        task = asyncio.create_task(supervise("idle", forever, restarts=restarts))
        await asyncio.sleep(0.01)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        assert restarts["idle"] == 0

    asyncio.run(main())


def test_keyboard_interrupt_is_not_swallowed() -> None:
    async def interrupted() -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        asyncio.run(supervise("x", interrupted))
