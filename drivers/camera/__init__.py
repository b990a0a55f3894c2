"""Camera frames as an async source: OpenCV devices, files and streams, and the virtual camera.

``open_camera("0")``, ``open_camera("file:///run.avi?loop=1")``, ``open_camera("rtsp://...")``
give a :class:`CameraSource`; ``async with src: async for frame in src: ...``.
"""

from drivers.camera.base import CameraSource, CameraStats
from drivers.camera.jpeg import compress_frame, decode_jpeg, decompress_frame, encode_jpeg
from drivers.camera.opencv import OpenCVCamera
from drivers.camera.url import CameraSpec, open_camera, parse_camera_url

__all__ = [
    "CameraSource",
    "CameraSpec",
    "CameraStats",
    "OpenCVCamera",
    "compress_frame",
    "decode_jpeg",
    "decompress_frame",
    "encode_jpeg",
    "open_camera",
    "parse_camera_url",
]
