"""The asyncio driver of a SICK LMS 200/211/221/291 on a serial line.

::

    async with LMS2xx("/dev/ttyUSB0", angle=180, resolution=0.5) as lms:
        print(lms.info)
        async for scan in lms:          # drivers.messages.LaserScan
            ...

Initialisation (also after every reconnect), each step one :meth:`request` with a timeout
and retries:

1. find the scanner's baud rate: 9600 (power-up) first, then the target, then the others
   (38400, 500000, 19200), probing with "output on request" (0x20 0x25), which also stops a
   scanner that is still streaming;
2. switch to the target baud rate (0x20 0x40/0x48; default: 500 kbaud when the port accepts
   it, else 38400) and confirm at the new rate;
3. read status (0x31) and type (0x3A); set the variant (0x3B) if it differs;
4. read the configuration (0x74: units, measuring mode, real-time index);
5. start continuous output (0x20 0x24).

Scans (0xB0) become :class:`~drivers.messages.LaserScan`: ranges in metres (error codes as
:mod:`drivers.sick.telegrams` says), the first beam at ``-angle/2`` on the sensor's x axis,
counter-clockwise. ``stamp`` is when the first beam was measured, on the host's clock
(:class:`~drivers.sick.stamps.ScanClock`): the arrival — the host time of the telegram's last
byte, minus its transmission time (10 bits per byte at the session baud rate), minus the
mirror's sweep over the scan (the turns of an interlaced scan plus the scanned fraction of
the last turn at 75 Hz) — corrected by the scanner's real-time scan index when its
configuration sends one (availability 0x02; set it once with SICK's configuration tool):
then a scan read late, or out of a backlog, keeps the time it was measured. Without the
index a scan read out of a backlog (more bytes waited behind it, or it came less than half a
period after the previous one) cannot be placed in time and is dropped (``stale``). The
scanner's processing latency is unknown and not subtracted. ``seq`` counts scans emitted by
this driver (it continues across reconnects).

Scans go through a bounded queue that drops the oldest scan when the consumer is slow
(``dropped`` counts them). A line that is lost — read error, end of file, device node gone,
or no telegram for ``stall_timeout`` while streaming — is re-opened by name with back-off and
the initialisation runs again, as often as it takes: a failed attempt (silence, a refusal,
a reply that cannot be decoded) is counted and retried. :meth:`close` stops the output,
puts the scanner back to 9600 baud (so the next start finds it where a power-up would) and
closes the port, which it always releases.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import AsyncIterator
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from drivers.messages import LaserScan
from drivers.serial_device import LinkLost, Refused, SerialDevice
from drivers.sick import telegrams as tg
from drivers.sick.codec import Acknowledge, StreamParser, Telegram
from drivers.sick.constants import (
    BAUD_MODES,
    MIRROR_HZ,
    MODE_SWITCH_OK,
    POWER_UP_BAUD,
    UNIT_METRES,
    Mode,
    Reply,
    reply_code,
)
from drivers.sick.stamps import ScanClock
from knowledge.errors import DeviceError, DeviceTimeout, ProtocolError

log = logging.getLogger(__name__)

#: Order in which baud rates are tried after the power-up rate and the target.
PROBE_ORDER = (9600, 38400, 500000, 19200)


@dataclass(frozen=True)
class ScannerInfo:
    """What the scanner said about itself during initialisation."""

    port: str
    type_string: str
    software_version: str
    prom_version: str
    angle_deg: int
    resolution_deg: float
    units: str
    measuring_mode: int
    baud_found: int
    baud: int
    n_beams: int
    scan_rate_hz: float

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class LmsStats:
    """A snapshot of the driver's counters (cumulative over reconnects).

    Attributes:
        telegrams, crc_errors, resyncs, acks, naks: the telegram parser's counters (resyncs
            in bytes skipped).
        scans: scans queued; dropped: scans pushed out of the full queue (oldest first).
        stale: scans dropped because their time could not be told (a backlog read at once
            without the scanner's index, a repeated telegram); restamped: scans stamped from
            the scanner's index more than half a period before they were read.
        bad_scans: 0xB0 telegrams with a good CRC that could not be turned into a scan
            (wrong count for the variant, partial scan, malformed).
        reconnects: successful re-initialisations after a lost line; disconnects: lost lines;
            reconnect_failures: attempts to re-open and re-initialise that failed (each is
            retried with back-off).
        timeouts: request attempts that got no answer; refused: attempts answered with NAK;
            bad_replies: initialisations stopped by a reply with a good CRC that could not be
            decoded (e.g. a status reply too short to hold the variant).
    """

    telegrams: int = 0
    crc_errors: int = 0
    resyncs: int = 0
    acks: int = 0
    naks: int = 0
    scans: int = 0
    dropped: int = 0
    stale: int = 0
    restamped: int = 0
    bad_scans: int = 0
    reconnects: int = 0
    disconnects: int = 0
    reconnect_failures: int = 0
    timeouts: int = 0
    refused: int = 0
    bad_replies: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


@dataclass
class _Pending:
    """The request waiting for its answer: the reply code expected, and whether ACK came."""

    reply: int
    future: asyncio.Future[Telegram]
    acked: bool = False


class LMS2xx(SerialDevice[Telegram, Telegram]):
    """A SICK LMS 2xx streaming :class:`LaserScan` messages.

    Args:
        port: device path or pyserial URL of the scanner's serial line.
        baud: session baud rate (9600, 19200, 38400 or 500000); None: 500000 if the port
            accepts it, else 38400. At 38400 baud a 361-value scan takes 0.19 s on the line,
            so the scan rate drops to about 5 Hz; 500 kbaud carries 37.5/75 Hz.
        angle: scan angle in degrees (180 or 100); None (with ``resolution`` None) keeps the
            scanner's variant.
        resolution: angular resolution in degrees (1, 0.5, or 0.25 with 100°).
        stream: start continuous output (False: initialise only, e.g. to probe).
        frame_id: ``frame_id`` of the scans.
        queue_size: scans kept for a slow consumer before the oldest is dropped.
        timeout: seconds per request attempt (plus the reply's transmission time).
        retries: further attempts per request.
        probe_timeout: seconds per attempt while looking for the scanner's baud rate.
        probe_retries: further attempts per baud rate while looking.
        settle: seconds to wait after a baud change before talking at the new rate.
        reconnect, reconnect_delay, max_reconnect_delay, stall_timeout: see
            :class:`~drivers.serial_device.SerialDevice`.
    """

    def __init__(
        self,
        port: str,
        *,
        baud: int | None = None,
        angle: int | None = 180,
        resolution: float | None = 0.5,
        stream: bool = True,
        frame_id: str = "laser",
        queue_size: int = 4,
        timeout: float = 1.0,
        retries: int = 2,
        probe_timeout: float = 0.5,
        probe_retries: int = 1,
        settle: float = 0.25,
        reconnect: bool = True,
        reconnect_delay: float = 0.2,
        max_reconnect_delay: float = 2.0,
        stall_timeout: float = 1.0,
    ) -> None:
        super().__init__(
            port,
            baudrate=POWER_UP_BAUD,
            timeout=timeout,
            retries=retries,
            reconnect=reconnect,
            reconnect_delay=reconnect_delay,
            max_reconnect_delay=max_reconnect_delay,
            stall_timeout=stall_timeout,
        )
        if baud is not None and baud not in BAUD_MODES:
            raise ValueError(f"baud must be one of {sorted(BAUD_MODES)} (or None for automatic), got {baud}")
        if (angle is None) != (resolution is None):
            raise ValueError("give both angle and resolution, or neither (keep the scanner's variant)")
        self.variant: tuple[int, int] | None = None
        if angle is not None and resolution is not None:
            self.variant = (angle, round(resolution * 100))
            tg.check_variant(*self.variant)
        if queue_size < 1:
            raise ValueError(f"queue_size must be >= 1 scan, got {queue_size}")
        if probe_timeout <= 0 or probe_retries < 0 or settle < 0:
            raise ValueError("need probe_timeout > 0 s, probe_retries >= 0 and settle >= 0 s")
        self.target_baud = baud
        self.stream = stream
        self.frame_id = frame_id
        self.probe_timeout = probe_timeout
        self.probe_retries = probe_retries
        self.settle = settle

        self._parser = StreamParser("reply")
        self._pending: _Pending | None = None
        self._queue: asyncio.Queue[LaserScan | None] = asyncio.Queue(maxsize=queue_size)
        self._info: ScannerInfo | None = None
        self._config: tg.ScannerConfig | None = None
        self._session_baud: int | None = None
        self._active: tuple[int, int] = self.variant or (180, 50)  # (angle deg, resolution 1/100 deg)
        self._seq = 0
        self._clock = ScanClock(tg.scan_period_s(*self._active))
        self._n_scans = 0
        self._n_dropped = 0
        self._n_bad = 0
        self._closed = False

    # ------------------------------------------------------------------ public API
    @property
    def info(self) -> ScannerInfo | None:
        """What the scanner reported at the last initialisation (None before the first)."""
        return self._info

    @property
    def stats(self) -> LmsStats:
        p = self._parser.stats
        return LmsStats(
            telegrams=p.telegrams,
            crc_errors=p.crc_errors,
            resyncs=p.resyncs,
            acks=p.acks,
            naks=p.naks,
            scans=self._n_scans,
            dropped=self._n_dropped,
            stale=self._clock.stats.stale,
            restamped=self._clock.stats.restamped,
            bad_scans=self._n_bad,
            reconnects=self._n_reconnects,
            disconnects=self._n_disconnects,
            reconnect_failures=self._n_failed_reconnects,
            timeouts=self._n_timeouts,
            refused=self._n_refused,
            bad_replies=self._n_bad_replies,
        )

    async def start(self) -> None:
        """Open the port, initialise the scanner and start streaming (a driver starts once).

        Raises:
            DeviceError: the port cannot be opened, or the scanner refuses a setting.
            DeviceTimeout: no scanner answers at any baud rate.
        """
        if self._closed:
            raise DeviceError(f"{self.port}: this LMS driver was closed; create a new one")
        await super().start()

    async def __aenter__(self) -> LMS2xx:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def recv(self, timeout: float | None = None) -> LaserScan:
        """The next scan.

        Raises:
            DeviceTimeout: none arrived within ``timeout`` seconds.
            DeviceError: the driver was closed.
        """
        if self._closed and self._queue.empty():
            raise DeviceError(f"{self.port}: the LMS driver is closed")
        try:
            scan = await asyncio.wait_for(self._queue.get(), timeout)
        except TimeoutError:
            raise DeviceTimeout(f"no scan from the LMS on {self.port} within {timeout:g} s") from None
        if scan is None:
            raise DeviceError(f"{self.port}: the LMS driver is closed")
        return scan

    async def __aiter__(self) -> AsyncIterator[LaserScan]:
        """Scans until the driver is closed."""
        while True:
            try:
                yield await self.recv()
            except DeviceError:
                if self._closed:
                    return
                raise

    async def close(self) -> None:
        """Stop the output, put the scanner back to 9600 baud (best effort), close the port."""
        try:
            await super().close()
        finally:
            self._closed = True
            if self._queue.full():
                self._queue.get_nowait()
            self._queue.put_nowait(None)

    # ------------------------------------------------------------------ requests
    async def _request_once(self, request: Telegram) -> Telegram:
        pending = _Pending(reply_code(request.command), asyncio.get_running_loop().create_future())
        self._pending = pending
        try:
            self.write(request.encode())
            return await pending.future
        finally:
            if self._pending is pending:
                self._pending = None

    async def _ask(
        self, request: Telegram, what: str, *, reply_bytes: int = 16, probe: bool = False
    ) -> Telegram:
        """:meth:`request` with the timeout stretched by the line time of request and reply."""
        baud = self.baudrate or POWER_UP_BAUD
        line = (len(request) + 1 + reply_bytes) * 10 / baud
        if probe:
            return await self.request(
                request, what=what, timeout=self.probe_timeout + line, retries=self.probe_retries
            )
        return await self.request(request, what=what, timeout=self.timeout + line)

    async def _switch_mode(self, mode: int, what: str, *, probe: bool = False) -> None:
        reply = await self._ask(tg.switch_mode(mode), what, reply_bytes=9, probe=probe)
        result = tg.decode_mode_reply(reply)
        if result != MODE_SWITCH_OK:
            raise DeviceError(self._describe(f"the scanner refused {what} (0xA0 result {result})"))

    # ------------------------------------------------------------------ line events
    def _data_received(self, data: bytes, t: float) -> None:
        events = self._parser.feed(data)
        # a scan followed by more bytes in this read waited in the port's buffer
        last = max((i for i, e in enumerate(events) if not isinstance(e, Acknowledge)), default=-1)
        held = self._parser.pending > 0
        for i, event in enumerate(events):
            pending = self._pending
            if pending is not None and pending.future.done():
                pending = None
            if isinstance(event, Acknowledge):
                # the answer to a request is ACK or NAK, then the reply: a NAK after the ACK
                # can only be a stray byte (garbage on the line)
                if pending is not None and not pending.acked:
                    if event is Acknowledge.ACK:
                        pending.acked = True
                    else:
                        pending.future.set_exception(Refused("the scanner answered NAK"))
                continue
            if pending is not None and event.command == pending.reply:
                pending.future.set_result(event)
            elif event.command == Reply.VALUES and self.expect_data:
                self._on_values(event, t, buffered=i < last or held)

    def _on_link_lost(self) -> None:
        self._parser.reset()
        if self._pending is not None and not self._pending.future.done():
            self._pending.future.set_exception(LinkLost(f"{self.port}: the line was lost"))

    def _on_values(self, t: Telegram, t_rx: float, *, buffered: bool = False) -> None:
        cfg, info, baud = self._config, self._info, self._session_baud
        if cfg is None or info is None or baud is None:
            return
        try:
            mv = tg.MeasuredValues.decode(t, realtime_index=cfg.realtime_index)
            if mv.partial or mv.values.size != info.n_beams:
                raise ProtocolError(
                    f"expected {info.n_beams} values of a complete scan, got {mv.values.size}"
                )
            ranges, intensities = tg.values_to_ranges(mv.values, cfg.units, cfg.measuring_mode)
        except ProtocolError as exc:
            self._n_bad += 1
            log.debug("%s: dropped a 0xB0 telegram: %s", self.port, exc)
            return
        angle, res = self._active
        turns = tg.scan_revolutions(angle, res)
        sweep = (turns - 1 + angle / 360.0) / MIRROR_HZ
        stamp = self._clock.stamp(t_rx - len(t) * 10.0 / baud - sweep, mv.realtime_index, buffered=buffered)
        if stamp is None:  # out of a backlog with no index to place it in time: counted
            log.debug("%s: dropped a scan read out of a backlog (its time is unknown)", self.port)
            return
        self._seq += 1
        scan = LaserScan(
            stamp=stamp,
            seq=self._seq,
            frame_id=self.frame_id,
            angle_min=tg.angle_min_rad(angle),
            angle_increment=math.radians(res / 100.0),
            range_max=tg.range_max_m(cfg.units, cfg.measuring_mode),
            ranges=ranges,
            intensities=intensities,
            range_min=UNIT_METRES[cfg.units],
            scan_time=turns / MIRROR_HZ,
        )
        if self._queue.full():
            self._queue.get_nowait()
            self._n_dropped += 1
        self._queue.put_nowait(scan)
        self._n_scans += 1

    # ------------------------------------------------------------------ initialisation
    def _use_baud(self, baud: int) -> None:
        self.set_baudrate(baud)
        self._parser.reset()

    async def _find_baud(self, target: int) -> int:
        order = [POWER_UP_BAUD, target, *PROBE_ORDER]
        candidates = [b for i, b in enumerate(order) if b not in order[:i] and self.port_accepts(b)]
        for baud in candidates:
            self._use_baud(baud)
            try:
                await self._switch_mode(Mode.ON_REQUEST, "output on request", probe=True)
            except LinkLost:
                raise
            except (DeviceTimeout, DeviceError):  # silence, or a stray NAK in the garbage
                continue
            log.info("%s: the scanner answers at %d baud", self.port, baud)
            return baud
        tried = ", ".join(str(b) for b in candidates)
        raise DeviceTimeout(
            f"no LMS answered on {self.port} at {tried} baud; check the cable, the scanner's power "
            "and the port name (is it the scanner's serial adapter?)"
        )

    async def _initialise(self) -> None:
        self.expect_data = False
        self._parser.reset()
        if self.target_baud is not None:
            target = self.target_baud
            if not self.port_accepts(target):
                raise DeviceError(f"{self.port} cannot run at {target} baud; choose another baud rate")
        else:
            target = 500000 if self.port_accepts(500000) else 38400
        found = await self._find_baud(target)
        if found != target:
            await self._switch_mode(BAUD_MODES[target], f"a change to {target} baud")
            self._use_baud(target)
            await asyncio.sleep(self.settle)
            try:
                await self._switch_mode(Mode.ON_REQUEST, f"output on request at {target} baud", probe=True)
            except DeviceTimeout as exc:
                raise DeviceError(
                    f"the LMS on {self.port} accepted {target} baud but does not answer at that rate "
                    "(does the adapter support it?)"
                ) from exc
        self._session_baud = target
        status = tg.ScannerStatus.decode(await self._ask(tg.request_status(), "the status", reply_bytes=160))
        type_string = tg.decode_type_reply(
            await self._ask(tg.request_type(), "the scanner type", reply_bytes=40)
        )
        angle, res = self.variant or (status.angle_deg, status.resolution_cdeg)
        if (status.angle_deg, status.resolution_cdeg) != (angle, res):
            reply = tg.VariantReply.decode(
                await self._ask(tg.set_variant(angle, res), "the variant", reply_bytes=14)
            )
            if not reply.ok or (reply.angle_deg, reply.resolution_cdeg) != (angle, res):
                raise DeviceError(
                    f"the LMS on {self.port} refused the {angle}°/{res / 100:g}° variant "
                    f"(it runs {reply.angle_deg}°/{reply.resolution_cdeg / 100:g}°)"
                )
        try:
            tg.check_variant(angle, res)
        except ValueError as exc:
            raise DeviceError(
                f"the LMS on {self.port} reports a variant this driver cannot read: {exc}"
            ) from exc
        self._active = (angle, res)
        self._clock.reset(tg.scan_period_s(angle, res))
        cfg = tg.ScannerConfig.decode(
            await self._ask(tg.request_config(), "the configuration", reply_bytes=44)
        )
        try:
            tg.range_mask(cfg.measuring_mode)
            unit = cfg.unit_metres
        except ProtocolError as exc:
            raise DeviceError(
                f"the LMS on {self.port} is configured in a way this driver cannot read: {exc}"
            ) from exc
        self._config = cfg
        self._info = ScannerInfo(
            port=self.port,
            type_string=type_string,
            software_version=status.software_version,
            prom_version=status.prom_version,
            angle_deg=angle,
            resolution_deg=res / 100.0,
            units="mm" if unit == 0.001 else "cm",
            measuring_mode=cfg.measuring_mode,
            baud_found=found,
            baud=target,
            n_beams=tg.n_values(angle, res),
            scan_rate_hz=1.0 / tg.scan_period_s(angle, res),
        )
        if self.stream:
            self.expect_data = True
            try:
                await self._switch_mode(Mode.CONTINUOUS, "continuous output")
            except BaseException:
                self.expect_data = False
                raise
        log.info(
            "%s: %s %s, %d°/%g°, %s, %d baud%s",
            self.port,
            type_string,
            status.software_version,
            angle,
            res / 100,
            self._info.units,
            target,
            ", streaming" if self.stream else "",
        )

    async def _shutdown(self) -> None:
        self.expect_data = False
        if self._link is None:
            return
        await self._switch_mode(Mode.ON_REQUEST, "output on request", probe=True)
        if self.baudrate != POWER_UP_BAUD:
            with contextlib.suppress(DeviceTimeout):
                await self._switch_mode(Mode.BAUD_9600, "a change back to 9600 baud", probe=True)
            self._use_baud(POWER_UP_BAUD)


def summarise(scan: LaserScan) -> dict[str, float | int]:
    """Range summary of one scan: min/mean/max of the valid ranges (metres) and the invalid count."""
    r = scan.ranges
    valid = r >= max(scan.range_min, 1e-9)
    v = r[valid]
    return {
        "n_beams": int(r.size),
        "invalid": int(r.size - v.size),
        "min": float(v.min()) if v.size else float("nan"),
        "mean": float(np.mean(v)) if v.size else float("nan"),
        "max": float(v.max()) if v.size else float("nan"),
    }
