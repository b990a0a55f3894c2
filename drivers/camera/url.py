"""Cameras named by a string, the way pyserial opens ports by URL.

=================================  ===========================================================
``0``, ``2``                       device index (``?width=640&height=480&fps=30``)
``/dev/video0``                    device path
``file:///data/run.avi``           video file (``?loop=1&realtime=0``); a plain path also works
``rtsp://``, ``http(s)://``, ...   network stream, handed to OpenCV unchanged (query included)
``sim://``                         the virtual camera (``?width=&height=&fov=&rate=``); needs
                                   ``world=`` and ``pose=`` keyword arguments
=================================  ===========================================================

Options common to every kind: ``rate`` (Hz), ``queue`` (frames), ``reconnect`` (0/1),
``reconnect_delay`` (s), ``frame_id``. Unknown options are an error that names them.
Keyword arguments to :func:`open_camera` override the URL's options.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal
from urllib.parse import parse_qsl, unquote, urlsplit

from drivers.camera.base import CameraSource
from knowledge.errors import ConfigError

CameraKind = Literal["device", "file", "stream", "sim"]

_STREAM_SCHEMES = frozenset({"rtsp", "rtsps", "rtmp", "http", "https", "udp", "tcp", "srt"})


def _bool(v: str) -> bool:
    low = v.strip().lower()
    if low in ("1", "true", "yes", "on"):
        return True
    if low in ("0", "false", "no", "off"):
        return False
    raise ValueError(f"expected a boolean (1/0, true/false), got {v!r}")


_COMMON: dict[str, tuple[str, Callable[[str], Any]]] = {
    "rate": ("rate_hz", float),
    "queue": ("queue_size", int),
    "reconnect": ("reconnect", _bool),
    "reconnect_delay": ("reconnect_delay", float),
    "frame_id": ("frame_id", str),
}
_BY_KIND: dict[str, dict[str, tuple[str, Callable[[str], Any]]]] = {
    "device": {"width": ("width", int), "height": ("height", int), "fps": ("fps", float)},
    "file": {"loop": ("loop", _bool), "realtime": ("realtime", _bool)},
    "stream": {},
    "sim": {
        "width": ("width", int),
        "height": ("height", int),
        "fov": ("hfov_deg", float),
        "noise": ("noise_sigma", float),
        "blur": ("blur_sigma", float),
        "seed": ("seed", int),
    },
}
#: Backends by kind, imported when first used.
_BACKENDS: dict[str, str] = {
    "device": "drivers.camera.opencv:OpenCVCamera",
    "file": "drivers.camera.opencv:OpenCVCamera",
    "stream": "drivers.camera.opencv:OpenCVCamera",
    "sim": "sim.camera_view:camera_source",
}


@dataclass(frozen=True)
class CameraSpec:
    """A parsed camera name: its kind, the target OpenCV gets, and the typed options."""

    kind: CameraKind
    target: int | str
    options: Mapping[str, Any] = field(default_factory=dict)


def parse_camera_url(url: str) -> CameraSpec:
    """Parse a camera name (see the module docstring). Raises ConfigError on unknown options."""
    text = url.strip()
    if not text:
        raise ConfigError("empty camera name: give a device index (0), a file path or a URL")
    parts = urlsplit(text)
    scheme = parts.scheme.lower()
    if scheme in _STREAM_SCHEMES:
        return CameraSpec("stream", text, {})
    if scheme == "sim":
        return CameraSpec("sim", "sim", _options("sim", parts.query, text))
    if scheme == "file":
        path = unquote(parts.path)
        if not path:
            raise ConfigError(f"{url}: a file URL needs a path (file:///path/to/video.avi)")
        return CameraSpec("file", path, _options("file", parts.query, text))
    if scheme and len(scheme) > 1:  # one letter would be a Windows drive
        raise ConfigError(
            f"{url}: unknown camera scheme '{scheme}://' (use file://, sim://, rtsp://, http(s)://, "
            "a device index or a path)"
        )
    base, _, query = text.partition("?")
    if base.isdigit():
        return CameraSpec("device", int(base), _options("device", query, text))
    if base.startswith("/dev/"):
        return CameraSpec("device", base, _options("device", query, text))
    return CameraSpec("file", base, _options("file", query, text))


def _options(kind: str, query: str, url: str) -> dict[str, Any]:
    table = {**_COMMON, **_BY_KIND[kind]}
    out: dict[str, Any] = {}
    for key, raw in parse_qsl(query, keep_blank_values=True):
        if key not in table:
            known = ", ".join(sorted(table))
            raise ConfigError(f"{url}: unknown {kind} camera option '{key}' (known: {known})")
        name, conv = table[key]
        try:
            out[name] = conv(raw)
        except ValueError as exc:
            raise ConfigError(f"{url}: option '{key}': {exc}") from exc
    return out


def open_camera(url: str, **kwargs: Any) -> CameraSource:
    """A camera source for ``url`` (not started: ``await src.start()`` or ``async with``).

    Keyword arguments go to the backend and override the URL's options.
    """
    spec = parse_camera_url(url)
    module_name, _, cls_name = _BACKENDS[spec.kind].partition(":")
    cls = getattr(importlib.import_module(module_name), cls_name)
    opts = {**spec.options, **kwargs}
    if spec.kind == "sim":
        source: CameraSource = cls(**opts)
    else:
        source = cls(spec.target, kind=spec.kind, **opts)
    return source
