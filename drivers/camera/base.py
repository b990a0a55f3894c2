"""The camera base class: a capture thread feeding asyncio through a drop-oldest queue.

Capturing blocks (``VideoCapture.read`` waits for the next frame), so each source runs its
backend in one worker thread of its own: open, read, release all happen there. Frames are
handed to the event loop with ``call_soon_threadsafe`` into a bounded queue that drops the
*oldest* frame when the consumer is slow (sensor data: the newest frame is what matters).

A backend writes three small blocking methods — ``_open``, ``_read``, ``_close`` — and the
base does the rest: time stamps, sequence numbers, pacing, reconnection with back-off,
counters and a clean shutdown. The OpenCV backend (:mod:`drivers.camera.opencv`) and the
virtual camera (:mod:`drivers.sim.camera`) plug in here.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
import time
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.messages import CameraFrame
from knowledge.errors import DeviceError, DeviceTimeout

log = logging.getLogger(__name__)

#: How long ``close()`` waits for the capture thread (a blocked read returns within a frame).
_JOIN_TIMEOUT = 5.0


@dataclass(frozen=True)
class CameraStats:
    """A snapshot of a source's counters.

    Attributes:
        frames: frames captured and queued.
        drops: frames dropped because the queue was full (the oldest goes).
        reconnects: successful re-openings (a looping file counts one per loop).
        errors: failed reads and failed re-openings.
        last_error: the message of the latest error, or None.
    """

    frames: int = 0
    drops: int = 0
    reconnects: int = 0
    errors: int = 0
    last_error: str | None = None


class CameraSource(ABC):
    """Base class of camera sources: ``start()``, ``await recv(timeout)``, ``async for``, ``close()``.

    Args:
        name: how the device is called in messages (device index, file, URL).
        frame_id: the ``frame_id`` of the frames.
        queue_size: frames kept for a slow consumer; when full the oldest is dropped.
        rate_hz: pace the reads to this rate (None: as fast as the backend delivers).
        reconnect: re-open the device when it fails (or, for a file, when it ends).
        reconnect_delay: first wait before re-opening after a failure, seconds; doubles on
            each failed attempt up to ``max_reconnect_delay``.
        max_reconnects: give up after this many failed attempts in a row (None: never).
        open_timeout: seconds ``start()`` waits for the first open.
    """

    def __init__(
        self,
        name: str,
        *,
        frame_id: str = "camera",
        queue_size: int = 2,
        rate_hz: float | None = None,
        reconnect: bool = True,
        reconnect_delay: float = 0.5,
        max_reconnect_delay: float = 5.0,
        max_reconnects: int | None = None,
        open_timeout: float = 10.0,
    ) -> None:
        if queue_size < 1:
            raise ValueError(f"queue_size must be >= 1 frame, got {queue_size}")
        if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz must be a positive frame rate or None, got {rate_hz}")
        if reconnect_delay < 0 or max_reconnect_delay < reconnect_delay:
            raise ValueError("need 0 <= reconnect_delay <= max_reconnect_delay (seconds)")
        self.name = name
        self.frame_id = frame_id
        self.queue_size = queue_size
        self.rate_hz = rate_hz
        self.reconnect = reconnect
        self.reconnect_delay = reconnect_delay
        self.max_reconnect_delay = max_reconnect_delay
        self.max_reconnects = max_reconnects
        self.open_timeout = open_timeout

        self._frames: deque[CameraFrame] = deque()
        self._wakeup = asyncio.Event()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ended = False
        self._end_error: str | None = None
        self._seq = 0
        self._n_frames = 0
        self._n_drops = 0
        self._n_reconnects = 0
        self._n_errors = 0
        self._last_error: str | None = None

    # ------------------------------------------------------------------ backend interface
    @abstractmethod
    def _open(self) -> None:
        """Open the device (blocking, capture thread). Raise DeviceError when it cannot.

        Any other exception fails ``start()`` at once too, as a DeviceError caused by it.
        """

    @abstractmethod
    def _read(self) -> np.ndarray | None:
        """The next ``(h, w, 3)`` uint8 BGR image (blocking), None at a clean end of stream.

        Raise DeviceError when the device failed.
        """

    @abstractmethod
    def _close(self) -> None:
        """Release the device (capture thread). Must not raise; may be called twice."""

    # ------------------------------------------------------------------ public API
    async def start(self) -> None:
        """Open the device and start capturing.

        Raises:
            DeviceError: the device cannot be opened, or the backend crashed while opening
                it (raised from the backend's exception).
            DeviceTimeout: opening did not finish within ``open_timeout`` seconds.
        """
        if self._thread is not None:
            raise RuntimeError(f"camera {self.name} is already started")
        self._loop = asyncio.get_running_loop()
        opened: asyncio.Future[None] = self._loop.create_future()
        self._thread = threading.Thread(
            target=self._run, args=(opened,), name=f"camera {self.name}", daemon=True
        )
        self._thread.start()
        try:
            await asyncio.wait_for(asyncio.shield(opened), self.open_timeout)
        except TimeoutError as exc:
            await self.close()
            raise DeviceTimeout(
                f"camera {self.name} did not open within {self.open_timeout} s; is the device busy?"
            ) from exc
        except DeviceError:
            await self.close()
            raise

    async def recv(self, timeout: float | None = None) -> CameraFrame:
        """The oldest queued frame, waiting up to ``timeout`` s (None: forever).

        Raises DeviceTimeout when none arrives in time, DeviceError once the source has ended
        (end of file without looping, reconnection given up, or closed) and the queue is empty.
        """
        try:
            frame = await asyncio.wait_for(self._next(), timeout)
        except TimeoutError as exc:
            raise DeviceTimeout(f"no frame from camera {self.name} within {timeout} s") from exc
        if frame is None:
            why = self._end_error or "end of stream"
            raise DeviceError(f"camera {self.name} has ended: {why}")
        return frame

    def __aiter__(self) -> CameraSource:
        return self

    async def __anext__(self) -> CameraFrame:
        frame = await self._next()
        if frame is None:
            if self._end_error is not None:
                raise DeviceError(f"camera {self.name} has ended: {self._end_error}")
            raise StopAsyncIteration
        return frame

    async def close(self) -> None:
        """Stop capturing, join the capture thread and release the device. Idempotent."""
        self._stop.set()
        thread = self._thread
        if thread is not None and thread.is_alive():
            await asyncio.to_thread(thread.join, _JOIN_TIMEOUT)
            if thread.is_alive():
                log.warning("camera %s: capture thread still blocked after %s s", self.name, _JOIN_TIMEOUT)
        self._ended = True
        self._wakeup.set()

    async def __aenter__(self) -> CameraSource:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def stats(self) -> CameraStats:
        """A frozen snapshot of the counters."""
        with self._lock:
            return CameraStats(
                self._n_frames, self._n_drops, self._n_reconnects, self._n_errors, self._last_error
            )

    @property
    def ended(self) -> bool:
        """True once no more frames will come (queued ones may still be read)."""
        return self._ended

    # ------------------------------------------------------------------ event-loop side
    async def _next(self) -> CameraFrame | None:
        while not self._frames:
            if self._ended:
                return None
            self._wakeup.clear()
            await self._wakeup.wait()
        return self._frames.popleft()

    def _deliver(self, frame: CameraFrame) -> None:
        if self._ended:
            return
        with self._lock:
            if len(self._frames) >= self.queue_size:
                self._frames.popleft()
                self._n_drops += 1
            self._n_frames += 1
        self._frames.append(frame)
        self._wakeup.set()

    def _finish(self, error: str | None) -> None:
        self._ended = True
        self._end_error = error
        self._wakeup.set()

    def _call_loop(self, fn: Callable[..., object], *args: object) -> bool:
        loop = self._loop
        if loop is None or loop.is_closed():
            return False
        try:
            loop.call_soon_threadsafe(fn, *args)
        except RuntimeError:  # the loop closed under us
            return False
        return True

    # ------------------------------------------------------------------ capture thread
    def _note_error(self, msg: str) -> None:
        with self._lock:
            self._n_errors += 1
            self._last_error = msg
        log.warning("camera %s: %s", self.name, msg)

    def _run(self, opened: asyncio.Future[None]) -> None:
        error: str | None = None
        try:
            try:
                self._open()
            except Exception as exc:  # start() must fail now, not after open_timeout
                failure = exc if isinstance(exc, DeviceError) else _open_crash(self.name, exc)
                error = str(failure)
                self._call_loop(_set_exception, opened, failure)
                return
            self._call_loop(_set_result, opened)
            error = self._capture_loop()
        except Exception as exc:  # a backend bug must not kill the thread silently
            log.exception("camera %s: capture thread failed", self.name)
            error = f"{type(exc).__name__}: {exc}"
        finally:
            self._close()
            self._call_loop(self._finish, error)

    def _capture_loop(self) -> str | None:
        """Read until stopped; returns why the stream ended (None: clean end or stop)."""
        next_due = time.monotonic()
        while not self._stop.is_set():
            try:
                image = self._read()
            except DeviceError as exc:
                self._note_error(str(exc))
                if not self.reconnect:
                    return str(exc)
                failure = self._reopen(self.reconnect_delay)
                if failure is not None:
                    return failure
                next_due = time.monotonic()
                continue
            if image is None:
                if not self.reconnect:
                    return None
                failure = self._reopen(0.0)
                if failure is not None:
                    return failure
                continue
            stamp = time.time()
            frame = CameraFrame(stamp=stamp, seq=self._seq, frame_id=self.frame_id, image=image)
            self._seq += 1
            if not self._call_loop(self._deliver, frame):
                return "event loop closed"
            if self.rate_hz is not None:
                period = 1.0 / self.rate_hz
                next_due += period
                now = time.monotonic()
                if next_due < now - period:  # fell behind by more than a frame: don't burst
                    next_due = now
                self._stop.wait(max(0.0, next_due - now))
        return None

    def _reopen(self, first_delay: float) -> str | None:
        """Close and re-open with back-off; None on success, else why we gave up."""
        self._close()
        delay = first_delay
        attempts = 0
        while not self._stop.wait(delay):
            try:
                self._open()
            except DeviceError as exc:
                attempts += 1
                self._note_error(f"reconnect failed: {exc}")
                if self.max_reconnects is not None and attempts >= self.max_reconnects:
                    return f"gave up after {attempts} failed reconnects: {exc}"
                delay = min(max(delay * 2.0, self.reconnect_delay), self.max_reconnect_delay)
                continue
            with self._lock:
                self._n_reconnects += 1
            return None
        return None


def _open_crash(name: str, exc: Exception) -> DeviceError:
    """The DeviceError that ``start()`` raises for a backend that crashed while opening."""
    kind = type(exc)
    module = "" if kind.__module__ == "builtins" else f"{kind.__module__}."
    err = DeviceError(
        f"camera {name} could not be opened: the backend failed with {module}{kind.__name__}: {exc}"
    )
    err.__cause__ = exc  # as ``raise ... from exc`` would, across the thread boundary
    return err


def _set_result(fut: asyncio.Future[None]) -> None:
    if not fut.done():
        fut.set_result(None)


def _set_exception(fut: asyncio.Future[None], exc: BaseException) -> None:
    if not fut.done():
        fut.set_exception(exc)
