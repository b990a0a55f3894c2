"""The OpenCV backend: cameras, video/image files and network streams through ``cv2.VideoCapture``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np

from drivers.camera.base import CameraSource
from knowledge.errors import DeviceError

CaptureKind = Literal["device", "file", "stream"]

#: A file whose container does not say its frame rate is paced at this rate (realtime mode).
_DEFAULT_FILE_FPS = 30.0


class OpenCVCamera(CameraSource):
    """A ``cv2.VideoCapture`` source.

    Args:
        target: a device index (``0``), a device path (``/dev/video0``), a file path (video,
            single image or an ``img_%04d.png`` sequence) or a stream URL (``rtsp://...``).
        kind: ``"device"``, ``"file"`` or ``"stream"``; guessed from ``target`` when None.
        loop: for files: start again at the end (counted as a reconnect) instead of ending.
        realtime: for files: deliver frames at the file's frame rate, like a live camera
            (False: as fast as they decode).
        width, height, fps: requested capture size (pixels) and rate (Hz) for devices.
        stream_timeout: seconds OpenCV's FFmpeg backend waits to open or read a stream.
        **kwargs: the :class:`CameraSource` options. ``reconnect`` defaults to ``loop`` for
            files and to True otherwise.
    """

    def __init__(
        self,
        target: int | str | Path,
        *,
        kind: CaptureKind | None = None,
        loop: bool = False,
        realtime: bool = True,
        width: int | None = None,
        height: int | None = None,
        fps: float | None = None,
        stream_timeout: float = 5.0,
        **kwargs: Any,
    ) -> None:
        if isinstance(target, Path):
            target = str(target)
        if kind is None:
            kind = _guess_kind(target)
        if kind == "device" and isinstance(target, str) and target.isdigit():
            target = int(target)
        if kind != "device" and not isinstance(target, str):
            raise ValueError(f"a {kind} camera needs a path or URL, got {target!r}")
        kwargs.setdefault("reconnect", loop if kind == "file" else True)
        kwargs.setdefault("frame_id", "camera")
        super().__init__(str(target), **kwargs)
        self.target = target
        self.kind: CaptureKind = kind
        self.loop = loop
        self.realtime = realtime
        self.width = width
        self.height = height
        self.fps = fps
        self.stream_timeout = stream_timeout
        self._user_rate = self.rate_hz
        self._cap: cv2.VideoCapture | None = None

    def _open(self) -> None:
        if self.kind == "file" and "%" not in str(self.target) and not Path(str(self.target)).is_file():
            raise DeviceError(f"camera file {self.target} does not exist (check the path)")
        if self.kind == "stream":
            ms = int(self.stream_timeout * 1000)
            params = [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, ms, cv2.CAP_PROP_READ_TIMEOUT_MSEC, ms]
            cap = cv2.VideoCapture(str(self.target), cv2.CAP_ANY, params)
        else:
            cap = cv2.VideoCapture(self.target)
        if not cap.isOpened():
            cap.release()
            hint = {
                "device": "is the camera plugged in, is the index right, is another program using it?",
                "file": "is it a video or image format OpenCV can decode?",
                "stream": "is the URL right and the server reachable?",
            }[self.kind]
            raise DeviceError(f"cannot open camera {self.name} ({self.kind}): {hint}")
        if self.kind == "device":
            if self.width:
                cap.set(cv2.CAP_PROP_FRAME_WIDTH, self.width)
            if self.height:
                cap.set(cv2.CAP_PROP_FRAME_HEIGHT, self.height)
            if self.fps:
                cap.set(cv2.CAP_PROP_FPS, self.fps)
        if self.kind == "file" and self.realtime and self._user_rate is None:
            file_fps = cap.get(cv2.CAP_PROP_FPS)
            self.rate_hz = file_fps if math.isfinite(file_fps) and 0 < file_fps <= 1000 else _DEFAULT_FILE_FPS
        self._cap = cap

    def _read(self) -> np.ndarray | None:
        cap = self._cap
        if cap is None:
            raise DeviceError(f"camera {self.name} is not open")
        ok, image = cap.read()
        if not ok or image is None:
            if self.kind == "file":
                return None
            raise DeviceError(
                f"camera {self.name}: reading a frame failed (device unplugged or stream lost?)"
            )
        if image.ndim == 2:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        elif image.shape[2] == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
        return np.asarray(image, dtype=np.uint8)

    def _close(self) -> None:
        cap, self._cap = self._cap, None
        if cap is not None:
            cap.release()


def _guess_kind(target: int | str) -> CaptureKind:
    if isinstance(target, int) or target.isdigit() or target.startswith("/dev/"):
        return "device"
    if "://" in target:
        return "stream"
    return "file"
