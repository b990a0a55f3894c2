"""Scans keep the time they were measured when the host reads them late (issue 24).

The virtual LMS on a real pseudo-terminal sees a world whose every range says when it was
measured (a range growing 1 m per second, in millimetres); the real driver reads it on an
event loop that then stands still for a second — as the agent's did while a kernel compiled
— and reads the backlog at once. With the scanner's real-time index the backlog's scans are
stamped when they were measured; without it, they cannot be placed in time and are dropped,
counted, and no scan leaves the driver with a wrong stamp.
"""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

from drivers.sick.driver import LMS2xx
from drivers.sim.lms import VirtualLMS

#: the range grows 1 m per second of the scanner's clock, from 1 m, every 6 s
SLOPE, LOW, SPAN = 1.0, 1.0, 6.0
P = 1 / 37.5


class Clockwork:
    """A world whose ranges tell the (epoch) time they were measured, modulo SPAN seconds."""

    def __init__(self) -> None:
        self.lms: VirtualLMS | None = None
        self.origin = time.time()

    def ranges(self, t: float, *, n_beams: int, fov: float, max_range: float) -> np.ndarray:
        assert self.lms is not None
        epoch = self.lms.epoch(t)
        return np.full(n_beams, LOW + SLOPE * ((epoch - self.origin) % SPAN), dtype=np.float32)


def measured(scan_range: float, stamp: float, origin: float) -> float:
    """The measurement time a range says, on the lap of the sawtooth nearest ``stamp``."""
    phase = (scan_range - LOW) / SLOPE
    lap = round((stamp - origin - phase) / SPAN)
    return origin + lap * SPAN + phase


async def _read(lms: LMS2xx, seconds: float, freeze_after: float, freeze: float) -> list[tuple[float, float]]:
    """(stamp, range) of the scans read for ``seconds``; the loop blocks ``freeze`` s once."""
    out: list[tuple[float, float]] = []
    t0 = time.monotonic()
    frozen = False
    while time.monotonic() - t0 < seconds:
        scan = await lms.recv(timeout=2.0)
        out.append((scan.stamp, float(np.median(scan.ranges))))
        if not frozen and time.monotonic() - t0 > freeze_after:
            frozen = True
            time.sleep(freeze)  # the event loop stands still: the line is not read
    return out


@pytest.mark.parametrize("index", [True, False], ids=["with-index", "without-index"])
def test_a_backlog_read_late_keeps_its_measurement_times(index: bool) -> None:
    world = Clockwork()
    sim = VirtualLMS(world, units="mm", realtime_index=index, pace=True)
    world.lms = sim
    sim.start()
    try:

        async def run() -> tuple[list[tuple[float, float]], LMS2xx]:
            lms = LMS2xx(str(sim.link), settle=0.02, probe_timeout=0.15, probe_retries=0, stall_timeout=3.0)
            await lms.start()
            try:
                return await _read(lms, 3.5, 1.0, 1.0), lms
            finally:
                await lms.close()

        scans, lms = asyncio.run(run())
    finally:
        sim.stop()
    stats = lms.stats
    stamps = np.array([s for s, _ in scans])
    errors = np.array([s - measured(r, s, world.origin) for s, r in scans])
    assert np.all(np.diff(stamps) > 0)
    assert len(scans) > 50
    # every scan leaves the driver stamped within a period of when it was measured
    assert np.abs(errors).max() < P, (np.abs(errors).max(), stats)
    if index:
        assert stats.restamped >= 10, stats  # the backlog: read up to a second late
        assert stats.stale == 0
    else:
        assert stats.stale >= 10, stats  # the backlog could not be placed: dropped, counted
        assert stats.restamped == 0
