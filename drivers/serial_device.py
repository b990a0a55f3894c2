"""Base class of request/reply devices on a serial line, with reconnection.

A port is named as pyserial's ``serial_for_url`` understands it: a device (``/dev/ttyUSB0``,
``/dev/pts/7``, a udev symlink) or a URL (``socket://host:port`` for a serial server,
``loop://`` for a loop-back). The line runs as an asyncio transport of
``pyserial-asyncio-fast``; bytes arrive in :meth:`SerialDevice._data_received` on the event
loop.

The base does what every such device needs and a backend should not rewrite:

* :meth:`request` — the public request/reply call: serialised, one timeout per attempt,
  retries on timeout or refusal, and errors that say what was asked, on which port and at
  which baud rate. A backend writes only :meth:`_request_once` (send, then await *its*
  reply) — the python-can ``send``/``_send_internal`` split.
* the connection: open by name/URL, change the baud rate, notice a lost line (read errors,
  end of file, the device node gone, or silence while data is expected), re-open by name
  with exponential back-off and re-run :meth:`_initialise`, count it. A reply the backend
  cannot decode (:class:`~knowledge.errors.ProtocolError`) during initialisation is a device
  problem like silence: :meth:`start` raises it as :class:`~knowledge.errors.DeviceError`,
  a reconnection retries with back-off. Nothing a reconnection meets stops the background
  task (an unexpected error is logged with its traceback and retried too).
* a clean :meth:`close`: the backend's :meth:`_shutdown` first (best effort, any error is
  logged), then the port, always; no task is left running.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from knowledge.errors import DeviceError, DeviceTimeout, ProtocolError

log = logging.getLogger(__name__)

Req = TypeVar("Req")
Rep = TypeVar("Rep")


class Refused(DeviceError):
    """The device answered a request with a refusal (e.g. NAK); the request may be retried."""


class LinkLost(DeviceError):
    """The serial line went away while waiting for an answer."""


class _LineProtocol(asyncio.Protocol):
    """Forwards the transport's callbacks to the device, tagged with the link they belong to."""

    def __init__(self, device: SerialDevice[Any, Any], link_id: int) -> None:
        self._device = device
        self._link_id = link_id
        self.closed = asyncio.Event()

    def data_received(self, data: bytes) -> None:
        self._device._on_bytes(self._link_id, data)

    def connection_lost(self, exc: Exception | None) -> None:
        self.closed.set()
        self._device._on_connection_lost(self._link_id, exc)


@dataclass
class _Link:
    link_id: int
    transport: asyncio.Transport
    protocol: _LineProtocol
    baudrate: int


class SerialDevice(ABC, Generic[Req, Rep]):
    """A request/reply device on a serial port, re-opened by name when the line is lost.

    Args:
        port: device path or pyserial URL.
        baudrate: the rate the port is opened at (the device's power-up rate).
        timeout: seconds to wait for the answer to one attempt of a request.
        retries: further attempts after a timeout or refusal.
        reconnect: re-open the port and re-initialise when the line is lost.
        reconnect_delay: first wait before re-opening, seconds; doubles per failure up to
            ``max_reconnect_delay``.
        stall_timeout: while :attr:`expect_data` is set, this many seconds without a byte
            count as a lost line (a pulled cable on an adapter that stays plugged in).
    """

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = 9600,
        timeout: float = 1.0,
        retries: int = 2,
        reconnect: bool = True,
        reconnect_delay: float = 0.2,
        max_reconnect_delay: float = 2.0,
        stall_timeout: float = 1.0,
    ) -> None:
        if not port:
            raise ValueError(
                "a serial device needs a port name or URL (e.g. /dev/ttyUSB0 or socket://host:4001)"
            )
        if timeout <= 0 or retries < 0:
            raise ValueError(f"need timeout > 0 s and retries >= 0, got {timeout} and {retries}")
        if not 0 < reconnect_delay <= max_reconnect_delay:
            raise ValueError("need 0 < reconnect_delay <= max_reconnect_delay (seconds)")
        if stall_timeout <= 0:
            raise ValueError(f"stall_timeout must be > 0 seconds, got {stall_timeout}")
        self.port = port
        self.initial_baudrate = baudrate
        self.timeout = timeout
        self.retries = retries
        self.reconnect = reconnect
        self.reconnect_delay = reconnect_delay
        self.max_reconnect_delay = max_reconnect_delay
        self.stall_timeout = stall_timeout
        #: Set by the backend while it expects a steady flow of bytes (the stall watchdog runs).
        self.expect_data = False

        self._link: _Link | None = None
        self._next_link_id = 0
        self._lost = asyncio.Event()
        self._closing = False
        self._request_lock = asyncio.Lock()
        self._supervisor: asyncio.Task[None] | None = None
        self._last_bytes = time.monotonic()
        self._n_reconnects = 0
        self._n_disconnects = 0
        self._n_timeouts = 0
        self._n_refused = 0
        self._n_bad_replies = 0
        self._n_failed_reconnects = 0
        self._last_error: str | None = None
        self._dying: list[_LineProtocol] = []

    # ------------------------------------------------------------------ backend interface
    @abstractmethod
    def _data_received(self, data: bytes, t: float) -> None:
        """Bytes from the line (event loop); ``t`` is the host time they arrived (Unix s)."""

    @abstractmethod
    async def _request_once(self, request: Req) -> Rep:
        """Send ``request`` once and return its answer; raise :class:`Refused` on a refusal.

        Timeouts are the caller's business (:meth:`request` cancels this coroutine).
        """

    @abstractmethod
    async def _initialise(self) -> None:
        """Bring the device up on the freshly opened line (runs again after each reconnect).

        Raise DeviceError/DeviceTimeout when the device misbehaves or is silent; a
        ProtocolError from decoding a reply is treated the same way.
        """

    async def _shutdown(self) -> None:
        """Put the device to rest before the port closes (best effort; errors are logged)."""

    def _on_link_lost(self) -> None:
        """Called when the line goes away: fail pending requests, reset parsers."""

    def _describe(self, what: str) -> str:
        """``what`` with the port and baud rate, for error messages."""
        baud = f" at {self._link.baudrate} baud" if self._link else ""
        return f"{what} on {self.port}{baud}"

    # ------------------------------------------------------------------ public API
    @property
    def connected(self) -> bool:
        return self._link is not None

    @property
    def baudrate(self) -> int | None:
        """The host side's current baud rate, or None when not connected."""
        return self._link.baudrate if self._link else None

    async def start(self) -> None:
        """Open the port and initialise the device; then keep it connected in the background.

        Raises:
            DeviceError: the port cannot be opened or the device misbehaves (including a
                reply that cannot be decoded).
            DeviceTimeout: the device does not answer.
        """
        if self._supervisor is not None:
            raise DeviceError(f"{self.port}: already started")
        self._closing = False
        try:
            await self._connect()
        except BaseException:
            await self._close_link()
            raise
        self._supervisor = asyncio.get_running_loop().create_task(
            self._supervise(), name=f"serial-supervisor {self.port}"
        )

    async def close(self) -> None:
        """Shut the device down (best effort), close the port and stop the background task.

        The port is closed whatever happens on the way; errors of the shutdown or of a
        background task that died are logged, not raised.
        """
        self._closing = True
        try:
            await self._stop_supervisor()
            if self._link is not None:
                try:
                    await self._shutdown()
                except Exception as exc:  # best effort: the port must close regardless
                    log.warning("%s: shutdown incomplete: %s", self.port, exc)
        finally:
            await self._close_link()
            for protocol in self._dying:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(protocol.closed.wait(), 2.0)
            self._dying.clear()

    async def _stop_supervisor(self) -> None:
        task, self._supervisor = self._supervisor, None
        if task is None:
            return
        task.cancel()
        await asyncio.wait([task])  # never raises the task's own exception
        if not task.cancelled() and task.exception() is not None:
            exc = task.exception()
            log.error("%s: the reconnection task had stopped: %r", self.port, exc, exc_info=exc)

    async def request(
        self, request: Req, *, what: str, timeout: float | None = None, retries: int | None = None
    ) -> Rep:
        """Send ``request`` and return the answer, with a timeout per attempt and retries.

        Args:
            what: what is being asked, for error messages ("the status", "a baud change").

        Raises:
            DeviceTimeout: no answer after all attempts.
            DeviceError: the device refused every attempt, or the line is down.
        """
        t = self.timeout if timeout is None else timeout
        n = 1 + (self.retries if retries is None else retries)
        refused = 0
        async with self._request_lock:
            for attempt in range(1, n + 1):
                if self._link is None:
                    raise LinkLost(self._describe(f"cannot ask for {what}: the port is not open"))
                try:
                    return await asyncio.wait_for(self._request_once(request), t)
                except TimeoutError:
                    self._n_timeouts += 1
                    log.debug("%s: attempt %d/%d timed out", self._describe(what), attempt, n)
                except Refused as exc:
                    self._n_refused += 1
                    refused += 1
                    log.debug("%s: attempt %d/%d refused: %s", self._describe(what), attempt, n, exc)
        if refused == n:
            raise DeviceError(self._describe(f"the device refused {what} {n} times"))
        raise DeviceTimeout(
            self._describe(f"no answer to {what} within {t:g} s after {n} attempts")
            + "; check the cable, the power and the port name"
        )

    # ------------------------------------------------------------------ line handling
    def _on_bytes(self, link_id: int, data: bytes) -> None:
        if self._link is None or link_id != self._link.link_id:
            return
        self._last_bytes = time.monotonic()
        self._data_received(data, time.time())

    def _on_connection_lost(self, link_id: int, exc: Exception | None) -> None:
        if self._link is None or link_id != self._link.link_id:
            return
        self._link_lost(f"{exc}" if exc else "the port closed")

    def _link_lost(self, reason: str) -> None:
        link = self._link
        if link is None:
            return
        self._link = None
        self.expect_data = False
        self._n_disconnects += 1
        self._last_error = reason
        if not self._closing:
            log.warning("%s: line lost: %s", self.port, reason)
        if not link.transport.is_closing():
            link.transport.abort()
        self._dying.append(link.protocol)
        self._on_link_lost()
        self._lost.set()

    async def _open_link(self, baudrate: int) -> None:
        """Open the port at ``baudrate`` (replacing any open link)."""
        import serial
        import serial_asyncio_fast

        await self._close_link()
        link_id = self._next_link_id
        self._next_link_id += 1
        protocol = _LineProtocol(self, link_id)
        loop = asyncio.get_running_loop()
        try:
            transport, _ = await serial_asyncio_fast.create_serial_connection(
                loop, lambda: protocol, self.port, baudrate=baudrate
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceError(f"cannot open serial port {self.port}: {exc}") from exc
        self._link = _Link(link_id, transport, protocol, baudrate)
        self._lost.clear()
        self._last_bytes = time.monotonic()

    def port_accepts(self, baudrate: int) -> bool:
        """Whether the open port can be set to ``baudrate`` (the current rate is kept)."""
        link = self._require_link()
        ser = link.transport.get_extra_info("serial")
        if ser is None:
            return True
        old = ser.baudrate
        try:
            ser.baudrate = baudrate
        except (ValueError, OSError) as exc:
            log.debug("%s does not accept %d baud: %s", self.port, baudrate, exc)
            return False
        finally:
            with contextlib.suppress(ValueError, OSError):
                ser.baudrate = old
        return True

    def set_baudrate(self, baudrate: int) -> None:
        """Change the host side's baud rate."""
        link = self._require_link()
        ser = link.transport.get_extra_info("serial")
        if ser is not None:
            try:
                ser.baudrate = baudrate
            except (ValueError, OSError) as exc:
                raise DeviceError(f"{self.port} cannot run at {baudrate} baud: {exc}") from exc
        link.baudrate = baudrate

    def write(self, data: bytes) -> None:
        """Queue bytes for the line."""
        self._require_link().transport.write(data)

    def _require_link(self) -> _Link:
        if self._link is None:
            raise LinkLost(f"{self.port}: the port is not open")
        return self._link

    async def _close_link(self) -> None:
        link = self._link
        self._link = None
        self.expect_data = False
        if link is None:
            return
        if not link.transport.is_closing():
            link.transport.close()
        try:
            await asyncio.wait_for(link.protocol.closed.wait(), 2.0)
        except TimeoutError:
            link.transport.abort()
            log.warning("%s: the port did not close within 2 s; aborted", self.port)

    async def _connect(self) -> None:
        await self._open_link(self.initial_baudrate)
        try:
            await self._initialise()
        except ProtocolError as exc:
            self._n_bad_replies += 1
            raise DeviceError(
                self._describe(f"the device sent a reply that cannot be decoded ({exc})")
                + "; is it the right device, and is the line clean?"
            ) from exc

    async def _supervise(self) -> None:
        """Watch the line; when it is lost, re-open by name with back-off and re-initialise."""
        while not self._closing:
            await self._wait_lost_or_stalled()
            if self._closing or not self.reconnect:
                return
            delay = self.reconnect_delay
            while not self._closing:
                await asyncio.sleep(delay)
                try:
                    await self._connect()
                except Exception as exc:
                    self._n_failed_reconnects += 1
                    self._last_error = str(exc)
                    delay = min(2 * delay, self.max_reconnect_delay)
                    if isinstance(exc, DeviceError | DeviceTimeout | OSError):
                        log.info("%s: reconnecting failed (%s); next try in %.1f s", self.port, exc, delay)
                    else:  # a bug, not the device: loud, but the driver keeps trying
                        log.exception("%s: reconnecting failed; next try in %.1f s", self.port, delay)
                    await self._close_link()
                    continue
                self._n_reconnects += 1
                log.warning("%s: reconnected (%d reconnects so far)", self.port, self._n_reconnects)
                break

    async def _wait_lost_or_stalled(self) -> None:
        while not self._lost.is_set():
            step = min(0.1, self.stall_timeout / 4)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._lost.wait(), step)
            if self.expect_data and self._link is not None:
                silent = time.monotonic() - self._last_bytes
                if silent > self.stall_timeout:
                    self._link_lost(f"no data for {silent:.1f} s")
