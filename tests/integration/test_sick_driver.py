"""Contract tests of the LMS 2xx driver: the same tests for the virtual LMS and real hardware.

Every test runs against the virtual LMS on a real pseudo-terminal. Set ``LOCI_LMS_PORT``
(e.g. ``/dev/ttyUSB0``) to run them against a real scanner as well; tests that need to
inject faults or know the scene skip there.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import pty
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.messages import LaserScan
from drivers.sick.constants import Mode, Reply
from drivers.sick.driver import LMS2xx
from drivers.sim.lms import Faults, VirtualLMS
from knowledge.errors import DeviceError, DeviceTimeout, ProtocolError
from knowledge.metric.grid import OccupancyGrid
from sim.lms_world import LmsWorld

HW_PORT = os.environ.get("LOCI_LMS_PORT")

# A 6 m x 4 m room: free cells inside a one-cell wall, 5 cm cells, map origin at (0, 0).
RES = 0.05
ROOM = (RES, RES, RES + 6.0, RES + 4.0)  # x0, y0, x1, y1 of the free space (wall faces)
POSE = (2.05, 1.55, 0.3)


def room_grid() -> OccupancyGrid:
    occ = np.ones((82, 122), dtype=bool)
    occ[1:-1, 1:-1] = False
    return OccupancyGrid.from_masks(occ, RES, name="room")


def expected_ranges(scan: LaserScan, pose: tuple[float, float, float] = POSE) -> np.ndarray:
    """Distance from ``pose`` to the room's wall faces along each beam, computed analytically."""
    x, y, th = pose
    a = th + scan.angles
    c, s = np.cos(a), np.sin(a)
    x0, y0, x1, y1 = ROOM
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(c > 1e-12, (x1 - x) / c, np.where(c < -1e-12, (x0 - x) / c, np.inf))
        ty = np.where(s > 1e-12, (y1 - y) / s, np.where(s < -1e-12, (y0 - y) / s, np.inf))
    return np.minimum(tx, ty)


@dataclass
class Rig:
    """A scanner to test against: the virtual LMS (``sim`` set) or real hardware."""

    port: str
    sim: VirtualLMS | None
    fast: dict[str, Any]

    def need_sim(self) -> VirtualLMS:
        if self.sim is None:
            pytest.skip("needs the virtual LMS (fault injection or a known scene)")
        return self.sim

    def driver(self, **kw: Any) -> LMS2xx:
        return LMS2xx(self.port, **{**self.fast, **kw})


# Quick timeouts: the virtual LMS answers at once. Real hardware keeps the driver's defaults.
# stall_timeout is generous: a loaded CI machine can starve the virtual scanner's thread for a
# while; the silent-line test sets its own short one
FAST_SIM = {"settle": 0.02, "probe_timeout": 0.15, "probe_retries": 0, "timeout": 0.5, "stall_timeout": 2.0}


@pytest.fixture
def make_sim(tmp_path: Any) -> Iterator[Callable[..., VirtualLMS]]:
    sims: list[VirtualLMS] = []

    def make(**kw: Any) -> VirtualLMS:
        world = LmsWorld(room_grid(), POSE, noise_std=0.0)
        sim = VirtualLMS(world, link=tmp_path / f"lms{len(sims)}", units="mm", **kw)
        sim.start()
        sims.append(sim)
        return sim

    yield make
    for s in sims:
        s.stop()


@pytest.fixture(params=["virtual", "hardware"])
def rig(request: pytest.FixtureRequest, make_sim: Callable[..., VirtualLMS]) -> Rig:
    if request.param == "hardware":
        if not HW_PORT:
            pytest.skip("set LOCI_LMS_PORT=/dev/ttyUSB0 to run the contract tests against a real LMS")
        return Rig(HW_PORT, None, {})
    sim = make_sim()
    return Rig(str(sim.link), sim, FAST_SIM)


async def collect(lms: LMS2xx, seconds: float) -> list[LaserScan]:
    out: list[LaserScan] = []
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        try:
            out.append(await lms.recv(timeout=left))
        except DeviceTimeout:
            break
    return out


async def fresh_scan(lms: LMS2xx, seconds: float) -> LaserScan:
    """The first scan measured after now (older ones may still wait in the queue)."""
    deadline = time.monotonic() + seconds
    while True:
        scan = await lms.recv(timeout=max(0.1, deadline - time.monotonic()))
        if scan.stamp > time.time() - 0.1:
            return scan


async def until(cond: Callable[[], bool], seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what}: not within {seconds} s")
        await asyncio.sleep(0.01)


def fds_on(path: str | None) -> int:
    """How many of this process's file descriptors are open on ``path`` (e.g. a /dev/pts/N)."""
    n = 0
    for fd in Path("/proc/self/fd").iterdir():
        with contextlib.suppress(OSError):  # closed meanwhile
            n += str(fd.readlink()) == path
    return n


@pytest.fixture
def run() -> Callable[[Any], Any]:
    def runner(coro: Any) -> Any:
        return asyncio.run(asyncio.wait_for(coro, 20.0))

    return runner


# ---------------------------------------------------------------------------- start-up
def test_starts_at_power_up_baud_and_switches_to_the_session_baud(
    rig: Rig, run: Callable[[Any], Any]
) -> None:
    async def go() -> None:
        async with rig.driver(baud=500000) as lms:
            assert lms.info is not None
            assert lms.info.baud == 500000 and lms.baudrate == 500000
            assert lms.info.type_string.startswith("LMS2")
            assert lms.info.units in ("cm", "mm")
            if rig.sim is not None:
                assert lms.info.baud_found == 9600
                assert rig.sim.state().baud == 500000
                assert rig.sim.state().streaming
            scan = await lms.recv(timeout=2.0)
            assert scan.n_beams == 361

    run(go())


def test_finds_a_scanner_left_streaming_at_another_baud(
    make_sim: Callable[..., VirtualLMS], run: Any
) -> None:
    sim = make_sim(initial_baud=38400, initial_mode=Mode.CONTINUOUS)

    async def go() -> None:
        async with LMS2xx(str(sim.link), baud=500000, **FAST_SIM) as lms:  # type: ignore[arg-type]
            assert lms.info is not None and lms.info.baud_found == 38400
            assert sim.state().baud == 500000
            await lms.recv(timeout=2.0)

    run(go())


def test_a_38400_baud_session_carries_fewer_scans(make_sim: Callable[..., VirtualLMS], run: Any) -> None:
    sim = make_sim()

    async def go() -> None:
        async with LMS2xx(str(sim.link), baud=38400, **FAST_SIM) as lms:  # type: ignore[arg-type]
            scans = await collect(lms, 1.0)
        # 732 bytes take 0.19 s at 38400 baud: about 5 scans/s instead of 37.5
        assert 2 <= len(scans) <= 8
        assert sim.state().scans_skipped > 20

    run(go())


def test_silence_gives_a_clear_timeout(run: Any) -> None:
    master, slave = pty.openpty()  # a port with nothing behind it
    try:
        path = os.ttyname(slave)

        async def go() -> None:
            with pytest.raises(
                DeviceTimeout, match=r"no LMS answered on /dev/pts/\d+ at 9600, 500000, 38400, 19200"
            ):
                await LMS2xx(path, probe_timeout=0.05, probe_retries=0).start()

        run(go())
    finally:
        os.close(master)
        os.close(slave)


def test_a_missing_port_is_a_device_error(tmp_path: Any, run: Any) -> None:
    async def go() -> None:
        with pytest.raises(DeviceError, match="cannot open serial port"):
            await LMS2xx(str(tmp_path / "nothing")).start()

    run(go())


# ---------------------------------------------------------------------------- scans
@pytest.mark.parametrize(("angle", "res", "n"), [(180, 1.0, 181), (180, 0.5, 361), (100, 0.25, 401)])
def test_variant_sets_geometry_and_scans_match_the_room(
    rig: Rig, run: Any, angle: int, res: float, n: int
) -> None:
    async def go() -> None:
        async with rig.driver(angle=angle, resolution=res) as lms:
            scans = await collect(lms, 0.3)
        assert scans, "no scan within 0.3 s"
        for scan in scans:
            assert scan.n_beams == n
            assert scan.angle_min == pytest.approx(-math.radians(angle) / 2)
            assert scan.angle_increment == pytest.approx(math.radians(res))
            assert scan.angle_max == pytest.approx(math.radians(angle) / 2)
            assert scan.frame_id == "laser"
        if rig.sim is not None:
            assert (rig.sim.state().angle_deg, rig.sim.state().resolution_cdeg) == (angle, round(res * 100))
            for scan in scans:
                np.testing.assert_allclose(scan.ranges, expected_ranges(scan), atol=0.01)

    run(go())


@pytest.mark.parametrize(("res", "hz"), [(1.0, 75.0), (0.5, 37.5)])
def test_continuous_scans_arrive_at_the_scanner_rate(rig: Rig, run: Any, res: float, hz: float) -> None:
    async def go() -> tuple[list[LaserScan], int]:
        async with rig.driver(angle=180, resolution=res) as lms:
            await lms.recv(timeout=2.0)
            sent0 = rig.sim.state().scans_sent if rig.sim else 0
            scans = await collect(lms, 1.0)
            sent = (rig.sim.state().scans_sent - sent0) if rig.sim else len(scans)
            return scans, sent

    scans, sent = run(go())
    assert len(scans) <= 1.1 * hz + 1
    if rig.sim is None:
        assert len(scans) >= 0.9 * hz
    else:
        # the virtual scanner keeps real time as well as a shared machine lets it; the
        # driver must deliver every scan it sent (one may be on the line at either end)
        assert sent >= 0.6 * hz
        assert len(scans) >= sent - 2
    seqs = [s.seq for s in scans]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    stamps = np.array([s.stamp for s in scans])
    assert np.all(np.diff(stamps) > 0)
    assert abs(stamps[-1] - time.time()) < 1.0
    assert scans[0].scan_time == pytest.approx(1.0 / hz)


# ---------------------------------------------------------------------------- faults
@pytest.mark.parametrize("power_cycle", [False, True])
def test_unplug_and_replug_reconnects_and_scans_resume(rig: Rig, run: Any, power_cycle: bool) -> None:
    sim = rig.need_sim()

    async def go() -> None:
        async with rig.driver() as lms:
            before = await lms.recv(timeout=2.0)
            sim.unplug()
            await asyncio.sleep(0.4)
            assert not sim.link.exists()
            sim.replug(power_cycle=power_cycle)
            scan = await fresh_scan(lms, 5.0)
            assert scan.seq > before.seq
            assert lms.stats.reconnects == 1 and lms.stats.disconnects == 1
            assert sim.state().baud == 500000 and sim.state().streaming
            np.testing.assert_allclose(scan.ranges, expected_ranges(scan), atol=0.01)

    run(go())


def test_a_malformed_reply_during_a_reconnect_is_retried_and_scans_resume(rig: Rig, run: Any) -> None:
    sim = rig.need_sim()

    async def go() -> None:
        tasks = asyncio.all_tasks()
        lms = rig.driver()
        await lms.start()
        try:
            first = await lms.recv(timeout=2.0)
            # the status reply (0xB1) comes back with a good CRC but too short to decode
            sim.set_faults(Faults(short_replies=frozenset({Reply.STATUS})))
            sim.unplug()
            await asyncio.sleep(0.3)
            sim.replug()
            await until(lambda: sim.state().short_replies_sent >= 1, 5.0, "a short status reply sent")
            sim.set_faults(Faults())
            scan = await fresh_scan(lms, 5.0)
            assert scan.seq > first.seq
            np.testing.assert_allclose(scan.ranges, expected_ranges(scan), atol=0.01)
            stats = lms.stats
            assert stats.bad_replies >= 1 and stats.reconnect_failures >= 1
            assert stats.reconnects == 1 and stats.disconnects == 1
        finally:
            await lms.close()  # must neither raise nor leave the port open
        assert not lms.connected and asyncio.all_tasks() == tasks
        assert fds_on(sim.pts) == 1  # only the virtual scanner's own end of the pty
        await asyncio.sleep(0.1)
        assert sim.state().baud == 9600 and not sim.state().streaming

    run(go())


def test_a_malformed_reply_at_start_is_a_device_error_and_frees_the_port(
    make_sim: Callable[..., VirtualLMS], run: Any
) -> None:
    sim = make_sim(faults=Faults(short_replies=frozenset({Reply.STATUS})))

    async def go() -> None:
        lms = LMS2xx(str(sim.link), **FAST_SIM)  # type: ignore[arg-type]
        with pytest.raises(DeviceError, match=r"cannot be decoded \(0xB1 reply too short") as err:
            await lms.start()
        assert isinstance(err.value.__cause__, ProtocolError)
        assert lms.stats.bad_replies == 1 and not lms.connected
        assert fds_on(sim.pts) == 1

    run(go())


def test_close_releases_the_port_when_the_goodbye_fails_to_decode(
    make_sim: Callable[..., VirtualLMS], run: Any, caplog: pytest.LogCaptureFixture
) -> None:
    sim = make_sim()

    class BadGoodbye(LMS2xx):
        """Its shutdown meets a reply it cannot decode (the parser lets no short 0xA0 through)."""

        async def _shutdown(self) -> None:
            raise ProtocolError("0xA0 reply without its result byte")

    async def go() -> None:
        tasks = asyncio.all_tasks()
        lms = BadGoodbye(str(sim.link), **FAST_SIM)  # type: ignore[arg-type]
        await lms.start()
        await lms.recv(timeout=2.0)
        assert fds_on(sim.pts) == 2  # the host's end and the virtual scanner's
        await lms.close()
        assert not lms.connected and asyncio.all_tasks() == tasks
        assert fds_on(sim.pts) == 1
        with pytest.raises(DeviceError, match="closed"):
            while True:
                await lms.recv(timeout=0.5)

    with caplog.at_level("WARNING", logger="drivers.serial_device"):
        run(go())
    assert "shutdown incomplete: 0xA0 reply without its result byte" in caplog.text


def test_an_unexpected_error_while_reconnecting_does_not_stop_the_driver(
    make_sim: Callable[..., VirtualLMS], run: Any, caplog: pytest.LogCaptureFixture
) -> None:
    sim = make_sim()

    class Flaky(LMS2xx):
        """Its second initialisation fails with an error no device problem would give."""

        calls = 0

        async def _initialise(self) -> None:
            self.calls += 1
            if self.calls == 2:
                raise RuntimeError("a bug in a backend")
            await super()._initialise()

    async def go() -> None:
        lms = Flaky(str(sim.link), **FAST_SIM)  # type: ignore[arg-type]
        async with lms:
            first = await lms.recv(timeout=2.0)
            sim.unplug()
            await asyncio.sleep(0.3)
            sim.replug()
            scan = await fresh_scan(lms, 5.0)
            assert scan.seq > first.seq and lms.calls >= 3
            assert lms.stats.reconnect_failures >= 1 and lms.stats.reconnects == 1

    with caplog.at_level("ERROR", logger="drivers.serial_device"):
        run(go())
    assert "a bug in a backend" in caplog.text


def test_garbage_and_flipped_bits_are_counted_and_never_reach_a_scan(rig: Rig, run: Any) -> None:
    sim = rig.need_sim()

    async def go() -> None:
        async with rig.driver() as lms:
            await lms.recv(timeout=2.0)
            sim.set_faults(Faults(garbage=0.5, bitflip=0.3, truncate=0.1))
            scans = await collect(lms, 1.5)
            stats = lms.stats
        assert len(scans) >= 10
        for scan in scans:  # a corrupted telegram never becomes a scan
            np.testing.assert_allclose(scan.ranges, expected_ranges(scan), atol=0.01)
        assert stats.crc_errors > 0 and stats.resyncs > 0
        assert stats.reconnects == 0

    run(go())


def test_a_silent_line_is_noticed_and_reconnected(rig: Rig, run: Any) -> None:
    sim = rig.need_sim()

    async def go() -> None:
        async with rig.driver(stall_timeout=0.3) as lms:
            await lms.recv(timeout=2.0)
            sim.set_faults(Faults(mute=True))
            await asyncio.sleep(0.8)
            assert lms.stats.disconnects >= 1
            sim.set_faults(Faults())
            deadline = time.monotonic() + 5.0
            while (await lms.recv(timeout=max(0.1, deadline - time.monotonic()))).stamp < time.time() - 0.1:
                pass
            assert lms.stats.reconnects >= 1

    run(go())


# ---------------------------------------------------------------------------- shutdown
def test_clean_shutdown_stops_output_restores_9600_and_leaves_no_task(rig: Rig, run: Any) -> None:
    async def go() -> None:
        before = asyncio.all_tasks()
        lms = rig.driver()
        await lms.start()
        assert len(asyncio.all_tasks()) > len(before)  # the supervisor runs
        await lms.recv(timeout=2.0)
        await lms.close()
        assert not lms.connected
        assert asyncio.all_tasks() == before
        with pytest.raises(DeviceError, match="closed"):
            while True:  # what was queued before closing may still be read
                await lms.recv(timeout=0.5)
        if rig.sim is not None:
            await asyncio.sleep(0.1)
            st = rig.sim.state()
            assert st.baud == 9600 and st.mode == Mode.ON_REQUEST and not st.streaming

    run(go())


def test_async_iteration_ends_when_closed(rig: Rig, run: Any) -> None:
    async def go() -> None:
        lms = rig.driver()
        await lms.start()

        async def consume() -> int:
            n = 0
            async for _ in lms:
                n += 1
            return n

        task = asyncio.create_task(consume())
        await asyncio.sleep(0.3)
        await lms.close()
        assert await asyncio.wait_for(task, 2.0) >= 1

    run(go())
