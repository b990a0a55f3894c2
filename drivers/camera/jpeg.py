"""JPEG compression of camera frames for publishing, and decoding back."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from drivers.messages import CameraFrame
from knowledge.errors import ProtocolError


def encode_jpeg(image: np.ndarray, quality: int = 85) -> bytes:
    """JPEG bytes of a ``(h, w, 3)`` BGR or ``(h, w)`` grey uint8 image; ``quality`` in 1..100."""
    if not 1 <= int(quality) <= 100:
        raise ValueError(f"JPEG quality must be 1..100, got {quality}")
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
        raise ValueError(f"encode_jpeg needs a uint8 (h, w) or (h, w, 3) image, got {img.dtype} {img.shape}")
    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(img), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError(f"OpenCV could not JPEG-encode an image of shape {img.shape}")
    return buf.tobytes()


def decode_jpeg(data: bytes) -> np.ndarray:
    """A ``(h, w, 3)`` uint8 BGR image from JPEG bytes. Raises ProtocolError on bad data."""
    if not data:
        raise ProtocolError("empty JPEG payload")
    img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise ProtocolError(f"not a decodable JPEG image ({len(data)} bytes)")
    return np.asarray(img)


def compress_frame(frame: CameraFrame, quality: int = 85, *, keep_image: bool = False) -> CameraFrame:
    """The frame with its JPEG bytes filled in (and its raw image dropped unless ``keep_image``)."""
    if frame.image is None:
        return frame
    jpeg = encode_jpeg(frame.image, quality)
    return dataclasses.replace(frame, jpeg=jpeg, image=frame.image if keep_image else None)


def decompress_frame(frame: CameraFrame) -> CameraFrame:
    """The frame with its raw image decoded from the JPEG bytes (a no-op if it has an image)."""
    if frame.image is not None:
        return frame
    assert frame.jpeg is not None  # CameraFrame guarantees one of the two
    return dataclasses.replace(frame, image=decode_jpeg(frame.jpeg))
