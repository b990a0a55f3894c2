"""A virtual SICK LMS 2xx on a pseudo-terminal: the same bytes as the real scanner.

The scanner side of a pty (``os.openpty``) is served by one background thread — not an
asyncio task, so it keeps real time whatever the event loop under test is doing, and
``loci sim lms`` needs no loop at all; tests talk to it through thread-safe calls
(:meth:`VirtualLMS.unplug`, :meth:`VirtualLMS.set_faults`, ...). The host
side is published under a stable path — a symlink (``link``) to ``/dev/pts/N`` — so a driver
opens it like ``/dev/ttyUSB0``. Unplugging closes the pty and removes the link (the device
node vanishes, the host's reads fail); plugging back in opens a new pty behind the same link.

What it emulates:

* power-up at 9600 baud in "output on request" mode, 180°/0.5° (configurable);
* ACK, then the reply, for 0x10 reset (0x91, then 0x90 ready), 0x20 mode switch
  (installation with password, continuous 0x24, on request 0x25, baud 0x40/0x41/0x42/0x48 —
  the reply goes out at the old rate, then the scanner changes), 0x30 measured values,
  0x31 status, 0x32 errors (none), 0x3A type, 0x3B variant (refused while streaming),
  0x74 configuration; NAK for unknown commands and for telegrams with a bad CRC;
* the baud rate as a real line sees it: the host's termios speed (``tcgetattr`` on the
  pty) is compared with the scanner's; when they differ the scanner ignores what it
  receives and the host receives garbage instead of the scanner's bytes;
* line time: every telegram occupies the line for 10 bits per byte at the current rate;
  in continuous mode a scan is sent every ``1/rate`` s (37.5 Hz for 0.5°, 75 Hz for 1° by
  default) unless the line is still busy, in which case that scan is skipped — as the
  scanner does at 38400 baud;
* faults for tests (:class:`Faults`): garbage bytes between telegrams, flipped bits,
  truncated telegrams, short replies with a good checksum (which only the reply's decoder
  can reject), silence (a broken wire), unplug/replug (with or without a power cycle).

Not emulated: configuration writes (0x77) and the other operating modes (mean values,
partial scans, sub-ranges, fields), real-time scan indices, reflector bits, the status
fields nobody reads (zeros in its 152-byte 0xB1; the layout of the used fields follows
sicktoolbox), the scanner's own reply latency.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import queue
import select
import shutil
import tempfile
import termios
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from drivers.sick import telegrams as tg
from drivers.sick.codec import StreamParser, Telegram
from drivers.sick.constants import (
    ACK,
    AVAILABILITY_REALTIME_INDEX,
    BAUD_MODES,
    INSTALLATION_PASSWORD,
    MIRROR_HZ,
    MODE_BAUDS,
    MODE_SWITCH_BAD_PASSWORD,
    MODE_SWITCH_NOT_POSSIBLE,
    MODE_SWITCH_OK,
    NAK,
    POWER_UP_BAUD,
    REPLY_FLAG,
    Command,
    MeasuringMode,
    Mode,
    Reply,
    Units,
)


class RangeSource(Protocol):
    """What the virtual scanner measures: the ranges of a scan taken at time ``t`` (seconds
    since the scanner started), ``max_range`` where a beam hits nothing
    (:class:`sim.lms_world.LmsWorld` sees a simulated world with walking people)."""

    def ranges(self, t: float, *, n_beams: int, fov: float, max_range: float) -> np.ndarray:
        """``(n_beams,)`` float32 metres over ``fov`` radians centred on the sensor's heading."""
        ...


log = logging.getLogger(__name__)

#: Seconds of missed scans a starved serving thread still sends when it wakes (older ones
#: are skipped, as a receive buffer would have overflowed).
MAX_CATCH_UP = 2.0

#: termios speed constant → baud rate.
_TERMIOS_BAUDS: dict[int, int] = {
    getattr(termios, f"B{b}"): b
    for b in (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 500000)
}


@dataclass(frozen=True)
class Faults:
    """Line faults the virtual LMS injects into what it sends (probabilities per telegram).

    Attributes:
        garbage: chance of random bytes (1–``garbage_max`` of them) before a telegram.
        bitflip: chance of one flipped bit somewhere in a telegram.
        truncate: chance that a telegram is cut short (its tail never sent).
        garbage_max: most garbage bytes in one burst.
        mute: send nothing at all (a broken transmit wire; the scanner still listens).
        short_replies: reply codes whose telegrams go out with only the first three quarters
            of their data, framed with a correct checksum (a firmware fault, or another
            device answering). A short 0xB1 status (114 of 152 bytes) passes the parser's
            length check and fails the decoder; replies cut below their plausible length
            are dropped by the parser (the request times out).
    """

    garbage: float = 0.0
    bitflip: float = 0.0
    truncate: float = 0.0
    garbage_max: int = 40
    mute: bool = False
    short_replies: frozenset[int] = frozenset()

    def __post_init__(self) -> None:
        for name in ("garbage", "bitflip", "truncate"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"Faults.{name} is a probability in [0, 1], got {p}")
        if self.garbage_max < 1:
            raise ValueError("Faults.garbage_max must be >= 1 byte")
        if not all(0 <= int(c) <= 0xFF for c in self.short_replies):
            raise ValueError(f"Faults.short_replies holds reply codes (bytes), got {set(self.short_replies)}")
        object.__setattr__(self, "short_replies", frozenset(int(c) for c in self.short_replies))


@dataclass(frozen=True)
class SimState:
    """A snapshot of the virtual scanner."""

    plugged: bool
    baud: int
    mode: int
    angle_deg: int
    resolution_cdeg: int
    units: int
    streaming: bool
    scans_sent: int
    scans_skipped: int
    requests: int
    naks_sent: int
    garbage_received: int
    short_replies_sent: int
    pts: str | None


class VirtualLMS:
    """A virtual LMS 2xx behind a symlink to a pty, served by a background thread.

    Args:
        world: what the scanner sees.
        link: the stable device path to publish (a symlink is created there); None: a fresh
            temporary directory holds ``lms0``.
        rate: scans per second in continuous mode; None: 75 Hz divided by the mirror turns
            per scan of the variant (37.5 Hz for 180°/0.5°).
        angle, resolution: power-up variant (degrees).
        units: ``"cm"`` (factory default, 81.82 m maximum) or ``"mm"`` (8.182 m).
        initial_baud: the rate it starts at (a real scanner powers up at 9600; another value
            emulates a scanner left at another rate by an earlier session).
        initial_mode: operating mode it starts in (e.g. ``Mode.CONTINUOUS``).
        type_string, software_version, prom_version: what it says about itself.
        faults: line faults to inject.
        pace: account line time (10 bits per byte): a scan whose turn comes while the line
            still carries the previous one is skipped, as the scanner does at low baud rates;
            False sends every scan.
        realtime_index: the configuration's availability has "real-time indices" (0x02): each
            0xB0 telegram ends with the scan index byte, counting mirror turns modulo 256
            (scans skipped or lost on the line count too), from which a driver stamps scans
            whatever its own delays (:mod:`drivers.sick.stamps`).
        seed: seed of the fault generator.

    Scans in continuous mode are measured on the scanner's own schedule (every period from
    when streaming started) and each is rendered at its measurement time: the beam sweep's
    start, i.e. the time the last byte leaves the scanner minus the telegram's line time and
    the sweep (what a driver estimates from the arrival time). A serving thread the machine
    starved catches up as hardware would have sent: the missed scans back to back, each
    measured at its own time (at most :data:`MAX_CATCH_UP` seconds of them; older ones are
    skipped and counted).
    """

    def __init__(
        self,
        world: RangeSource,
        *,
        link: str | Path | None = None,
        rate: float | None = None,
        angle: int = 180,
        resolution: float = 0.5,
        units: str = "cm",
        initial_baud: int = POWER_UP_BAUD,
        initial_mode: int = Mode.ON_REQUEST,
        type_string: str = "LMS200;30106",
        software_version: str = "V02.10 ",
        prom_version: str = "V01.30 ",
        faults: Faults | None = None,
        pace: bool = True,
        realtime_index: bool = False,
        seed: int = 0,
    ) -> None:
        if units not in ("cm", "mm"):
            raise ValueError(f"units must be 'cm' or 'mm', got {units!r}")
        if initial_baud not in MODE_BAUDS.values():
            raise ValueError(f"the LMS 2xx runs at 9600, 19200, 38400 or 500000 baud, not {initial_baud}")
        if rate is not None and not (math.isfinite(rate) and 0 < rate <= 100):
            raise ValueError(f"rate must be in (0, 100] scans per second, got {rate}")
        self.world = world
        self.rate = rate
        self.pace = pace
        self.realtime_index = realtime_index
        self.type_string = type_string
        self.software_version = software_version
        self.prom_version = prom_version
        self._power_up = (initial_baud, int(initial_mode), angle, round(resolution * 100))
        tg.check_variant(angle, self._power_up[3])
        self._units = Units.CM if units == "cm" else Units.MM
        self._faults = faults or Faults()
        self._rng = np.random.default_rng(seed)

        self._own_dir: Path | None = None
        self._link = None if link is None else Path(link)
        if self._link is not None and self._link.exists() and not self._link.is_symlink():
            raise ValueError(f"{self._link} exists and is not a symlink; choose another --link path")

        self._master: int | None = None
        self._slave: int | None = None
        self._pts: str | None = None
        self._wake_r = self._wake_w = -1
        self._calls: queue.Queue[tuple[Callable[[], None], threading.Event]] = queue.Queue()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._t0 = time.monotonic()
        self._epoch0 = time.time()
        self._parser = StreamParser("request", address=0)
        self._lock = threading.Lock()  # guards the counters read by state()
        self._reset_state()
        self._scans_sent = 0
        self._scans_skipped = 0
        self._requests = 0
        self._naks = 0
        self._garbage_in = 0
        self._short_sent = 0

    # ------------------------------------------------------------------ lifecycle
    @property
    def link(self) -> Path:
        """The published device path (a symlink to the current ``/dev/pts/N``)."""
        if self._link is None:
            raise RuntimeError("the virtual LMS has no device path before start()")
        return self._link

    def start(self) -> Path:
        """Open the pty, publish the link and start serving; returns the link path."""
        if self._thread is not None:
            raise RuntimeError("the virtual LMS is already running")
        if self._link is None:
            self._own_dir = Path(tempfile.mkdtemp(prefix="loci-lms-"))
            self._link = self._own_dir / "lms0"
        self._wake_r, self._wake_w = os.pipe()
        self._t0 = time.monotonic()
        self._epoch0 = time.time()
        # the first ray cast loads (or compiles) the numba caster, 0.3 s or more: pay it now,
        # not as a silent gap before the first scan (a real scanner streams at once)
        self._scan_telegram(self._t0)
        self._plug()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="virtual-lms", daemon=True)
        self._thread.start()
        return self.link

    def stop(self) -> None:
        """Stop serving, close the pty and remove the link (and its temporary directory)."""
        if self._thread is not None:
            self._stop.set()
            with contextlib.suppress(OSError):
                os.write(self._wake_w, b"x")
            self._thread.join(5.0)
            self._thread = None
        self._unplug()
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._wake_r = self._wake_w = -1
        if self._own_dir is not None:
            shutil.rmtree(self._own_dir, ignore_errors=True)
            self._own_dir = self._link = None

    def __enter__(self) -> VirtualLMS:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def epoch(self, t: float) -> float:
        """Seconds since the scanner started (what :class:`RangeSource` is given) as epoch seconds."""
        return self._epoch0 + t

    @property
    def pts(self) -> str | None:
        """The current ``/dev/pts/N`` behind the link (None while unplugged)."""
        return self._pts

    def state(self) -> SimState:
        with self._lock:
            return SimState(
                plugged=self._master is not None,
                baud=self._baud,
                mode=self._mode,
                angle_deg=self._angle,
                resolution_cdeg=self._res,
                units=self._units,
                streaming=self._mode == Mode.CONTINUOUS and self._master is not None,
                scans_sent=self._scans_sent,
                scans_skipped=self._scans_skipped,
                requests=self._requests,
                naks_sent=self._naks,
                garbage_received=self._garbage_in,
                short_replies_sent=self._short_sent,
                pts=self._pts,
            )

    # ------------------------------------------------------------------ test controls
    def unplug(self) -> None:
        """Pull the cable: close the pty and remove the link."""
        self._call(self._unplug)

    def replug(self, *, power_cycle: bool = False) -> None:
        """Put the cable back: a new pty behind the same link (``power_cycle``: back to power-up state)."""

        def plug() -> None:
            if power_cycle:
                with self._lock:
                    self._reset_state()
            self._plug()

        self._call(plug)

    def set_faults(self, faults: Faults) -> None:
        """Change the injected line faults."""

        def set_() -> None:
            self._faults = faults

        self._call(set_)

    def send_raw(self, data: bytes) -> None:
        """Put arbitrary bytes on the line (as if the scanner sent them)."""
        self._call(lambda: self._write(data))

    def _call(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` in the serving thread (or here when it is not running) and wait for it."""
        if self._thread is None or not self._thread.is_alive():
            fn()
            return
        done = threading.Event()
        self._calls.put((fn, done))
        os.write(self._wake_w, b"x")
        if not done.wait(5.0):
            raise RuntimeError("the virtual LMS thread did not respond within 5 s")

    # ------------------------------------------------------------------ pty handling
    def _reset_state(self) -> None:
        baud, mode, angle, res = self._power_up
        self._baud = baud
        self._mode = mode
        self._angle = angle
        self._res = res
        self._next_scan = time.monotonic()
        self._line_free = 0.0
        self._scan_no = 0  # scans measured since power-up (the real-time index counts their turns)

    def _plug(self) -> None:
        if self._master is not None:
            return
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self._pts = os.ttyname(slave)
        self._parser.reset()
        tmp = self.link.with_name(self.link.name + ".tmp")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        tmp.symlink_to(self._pts)
        tmp.replace(self.link)
        self._next_scan = time.monotonic()
        log.info("virtual LMS plugged in: %s -> %s", self.link, self._pts)

    def _unplug(self) -> None:
        if self._link is not None and self._link.is_symlink():
            with contextlib.suppress(FileNotFoundError):
                self._link.unlink()
        for fd in (self._master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = None
        self._pts = None

    def _host_baud(self) -> int | None:
        """The baud rate the host set on its end of the line (None: unknown)."""
        if self._slave is None:
            return None
        try:
            speed = termios.tcgetattr(self._slave)[5]
        except termios.error:
            return None
        return _TERMIOS_BAUDS.get(int(speed))

    def _write(self, data: bytes) -> None:
        """Put bytes on the line as the host will receive them; account the line time."""
        if self._master is None or not data or self._faults.mute:
            return
        host = self._host_baud()
        out = data
        if host is not None and host != self._baud:
            n = max(1, min(4096, round(len(data) * host / self._baud)))
            out = self._rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        try:
            os.write(self._master, out)
        except BlockingIOError:
            pass  # nobody reads: the bytes are lost, as on a real line
        except OSError as exc:
            log.debug("virtual LMS write failed: %s", exc)
        now = time.monotonic()
        self._line_free = max(now, self._line_free) + len(data) * 10.0 / self._baud

    def _send_telegram(self, t: Telegram) -> None:
        f = self._faults
        if t.command in f.short_replies:
            t = replace(t, data=t.data[: 3 * len(t.data) // 4])
            with self._lock:
                self._short_sent += 1
        raw = bytearray(t.encode())
        rng = self._rng
        prefix = b""
        if f.garbage and rng.random() < f.garbage:
            prefix = rng.integers(0, 256, int(rng.integers(1, f.garbage_max + 1)), dtype=np.uint8).tobytes()
        if f.bitflip and rng.random() < f.bitflip:
            i = int(rng.integers(0, len(raw)))
            raw[i] ^= 1 << int(rng.integers(0, 8))
        if f.truncate and rng.random() < f.truncate:
            raw = raw[: int(rng.integers(1, len(raw)))]
        self._write(prefix + bytes(raw))

    # ------------------------------------------------------------------ serving
    def _run(self) -> None:
        failures = 0
        while not self._stop.is_set():
            try:
                self._serve_once()
                failures = 0
            except Exception:
                failures += 1
                log.exception("virtual LMS: serving failed (%d in a row)", failures)
                if failures >= 10:
                    log.error("virtual LMS: giving up after 10 failures in a row")
                    return
                time.sleep(0.05)

    def _serve_once(self) -> None:
        """Run queued calls, wait for bytes or the next scan, answer, stream."""
        while True:
            try:
                fn, done = self._calls.get_nowait()
            except queue.Empty:
                break
            try:
                fn()
            finally:
                done.set()
        now = time.monotonic()
        streaming = self._mode == Mode.CONTINUOUS and self._master is not None
        wait = max(0.0, min(0.05, self._next_scan - now)) if streaming else 0.05
        fds = [self._wake_r] + ([self._master] if self._master is not None else [])
        try:
            readable, _, _ = select.select(fds, [], [], wait)
        except (OSError, ValueError):
            return
        if self._wake_r in readable:
            with contextlib.suppress(OSError):
                os.read(self._wake_r, 256)
        if self._master is not None and self._master in readable:
            self._receive()
        if self._mode == Mode.CONTINUOUS and self._master is not None:
            self._stream(time.monotonic())

    def _receive(self) -> None:
        assert self._master is not None
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return
        host = self._host_baud()
        if host is not None and host != self._baud:
            with self._lock:
                self._garbage_in += len(data)
            return
        crc_before = self._parser.stats.crc_errors
        events = self._parser.feed(data)
        if self._parser.stats.crc_errors > crc_before:
            self._nak()
        for ev in events:
            if isinstance(ev, Telegram):
                with self._lock:
                    self._requests += 1
                self._handle(ev)

    def _nak(self) -> None:
        with self._lock:
            self._naks += 1
        self._write(bytes([NAK]))

    def _reply(self, t: Telegram) -> None:
        self._write(bytes([ACK]))
        self._send_telegram(t)

    def _handle(self, req: Telegram) -> None:
        cmd = req.command
        if cmd == Command.SWITCH_MODE and req.data:
            self._switch_mode(req)
        elif cmd == Command.REQUEST_VALUES:
            self._reply(self._scan_telegram(time.monotonic()))
        elif cmd == Command.STATUS:
            self._reply(self._status().telegram())
        elif cmd == Command.ERRORS:
            self._reply(tg.errors_reply([]))
        elif cmd == Command.TYPE:
            self._reply(tg.type_reply(self.type_string))
        elif cmd == Command.VARIANT and len(req.data) == 4:
            angle, res = tg.parse_variant_request(req)
            ok = self._mode != Mode.CONTINUOUS
            try:
                tg.check_variant(angle, res)
            except ValueError:
                ok = False
            if ok:
                with self._lock:
                    self._angle, self._res = angle, res
            self._reply(tg.VariantReply(ok, self._angle, self._res).telegram())
        elif cmd == Command.READ_CONFIG:
            self._reply(self._config().telegram())
        elif cmd == Command.RESET:
            self._reply(Telegram(REPLY_FLAG, Reply.RESET, b"", 0))
            with self._lock:
                self._reset_state()
            self._send_telegram(Telegram(REPLY_FLAG, Reply.READY, b"LMS ready", 0))
        else:
            self._nak()

    def _switch_mode(self, req: Telegram) -> None:
        mode = req.data[0]
        new_baud = None
        if mode == Mode.INSTALLATION:
            ok = req.data[1:9] == INSTALLATION_PASSWORD
            result = MODE_SWITCH_OK if ok else MODE_SWITCH_BAD_PASSWORD
        elif mode in (Mode.CONTINUOUS, Mode.ON_REQUEST):
            result = MODE_SWITCH_OK
        elif mode in MODE_BAUDS:
            result, new_baud = MODE_SWITCH_OK, MODE_BAUDS[mode]
        else:
            result = MODE_SWITCH_NOT_POSSIBLE
        if new_baud is None and result == MODE_SWITCH_OK:
            # the new mode holds once the host has the reply (state() must not lag behind it)
            with self._lock:
                if mode == Mode.CONTINUOUS and self._mode != Mode.CONTINUOUS:
                    self._next_scan = time.monotonic()
                self._mode = mode
        self._reply(tg.mode_reply(result))
        if new_baud is not None:
            # the reply goes out at the old rate, then the scanner changes
            with self._lock:
                self._baud = new_baud

    def _status(self) -> tg.ScannerStatus:
        return tg.ScannerStatus(
            software_version=self.software_version,
            operating_mode=self._mode,
            measuring_mode=MeasuringMode.R8_80_FIELDS_AB_DAZZLE,
            angle_deg=self._angle,
            resolution_cdeg=self._res,
            baud_field=int(BAUD_MODES[self._baud]),
            units=self._units,
            prom_version=self.prom_version,
            motor_revolutions=75,
        )

    def _config(self) -> tg.ScannerConfig:
        return replace(
            tg.ScannerConfig(),
            units=self._units,
            measuring_mode=MeasuringMode.R8_80_FIELDS_AB_DAZZLE,
            availability=AVAILABILITY_REALTIME_INDEX if self.realtime_index else 0,
        )

    def _period(self) -> float:
        if self.rate is not None:
            return 1.0 / self.rate
        return tg.scan_period_s(self._angle, self._res)

    def _line_and_sweep(self) -> float:
        """Seconds from the start of a scan's sweep to the last byte of its telegram: the
        sweep (the turns of an interlaced scan) and the telegram's line time."""
        turns = tg.scan_revolutions(self._angle, self._res)
        return (turns - 1 + self._angle / 360.0) / MIRROR_HZ + self._telegram_time()

    def _scan_telegram(self, measured: float) -> Telegram:
        """A 0xB0 telegram of the scan whose sweep started at ``measured`` (monotonic seconds)."""
        n = tg.n_values(self._angle, self._res)
        fov = math.radians(self._angle)
        max_range = tg.range_max_m(self._units)
        ranges = self.world.ranges(measured - self._t0, n_beams=n, fov=fov, max_range=max_range)
        ranges = np.where(ranges >= max_range, np.inf, ranges)  # nothing within range: "> maximum"
        values = tg.ranges_to_values(ranges, self._units)
        index = None
        if self.realtime_index:
            index = (self._scan_no * tg.scan_revolutions(self._angle, self._res)) & 0xFF
        self._scan_no += 1
        return tg.MeasuredValues(values, units=self._units, realtime_index=index).telegram()

    def _stream(self, now: float) -> None:
        """Send the scans whose time has come (see the class docstring)."""
        period = self._period()
        missed = (
            int((now - self._next_scan - MAX_CATCH_UP) // period)
            if now - self._next_scan > MAX_CATCH_UP
            else 0
        )
        if missed > 0:  # starved for long: what is older than MAX_CATCH_UP is gone
            self._next_scan += missed * period
            self._scan_no += missed
            with self._lock:
                self._scans_skipped += missed
        lead = self._line_and_sweep()
        while self._next_scan <= now:
            due = self._next_scan
            self._next_scan += period
            if self.pace and due - self._telegram_time() < self._line_free:
                self._scan_no += 1  # the line still carries the last scan: this one is skipped
                with self._lock:
                    self._scans_skipped += 1
                continue
            self._send_telegram(self._scan_telegram(due - lead))
            self._line_free = due  # the telegram's last byte leaves at its due time
            with self._lock:
                self._scans_sent += 1

    def _telegram_time(self) -> float:
        """Seconds a scan's 0xB0 telegram takes on the line (10 bits per byte)."""
        n = tg.n_values(self._angle, self._res)
        return (10 + 2 * n + (1 if self.realtime_index else 0)) * 10.0 / self._baud
