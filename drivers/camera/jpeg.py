"""JPEG compression of camera frames for publishing, and decoding back.

Frames from the bus are decoded with limits (:func:`decode_image`): the image's size is read
from its header first (:func:`image_header`, JPEG or PNG, nothing else), and a frame larger
than the camera makes, in pixels or bytes, is refused before OpenCV allocates anything (a
JPEG header claiming 65,000 x 65,000 pixels once stopped the agent, and one claiming
20,000 x 20,000 held the event loop for 7.9 s and took memory from 316 MB to 2.6 GB).
"""

from __future__ import annotations

import dataclasses
import struct
from typing import NamedTuple

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


class ImageHeader(NamedTuple):
    """What an image's header says: its format (``"jpeg"``, ``"png"``) and size in pixels."""

    format: str
    width: int
    height: int


# JPEG start-of-frame markers (baseline, progressive, lossless, arithmetic...): not C4 (DHT),
# C8 (JPG), CC (DAC)
_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
# markers without a length field: TEM, RST0-7, SOI
_STANDALONE = frozenset([0x01, *range(0xD0, 0xD8), 0xD8])
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def image_header(data: bytes) -> ImageHeader:
    """The format and size of a JPEG or PNG image, read from its header without decoding.

    Raises:
        ProtocolError: neither a JPEG nor a PNG, or a header that is cut short or malformed.
    """
    if data[:8] == _PNG_SIGNATURE:
        if len(data) < 24 or data[12:16] != b"IHDR":
            raise ProtocolError("PNG image without its IHDR header")
        width, height = struct.unpack(">II", data[16:24])
        return ImageHeader("png", width, height)
    if data[:2] != b"\xff\xd8":
        raise ProtocolError(f"not a JPEG or PNG image (starts with {data[:4].hex() or 'nothing'})")
    pos, end = 2, len(data)
    while pos < end:
        if data[pos] != 0xFF:
            raise ProtocolError(f"JPEG: no marker at byte {pos}")
        while pos < end and data[pos] == 0xFF:  # fill bytes
            pos += 1
        if pos >= end:
            break
        marker = data[pos]
        pos += 1
        if marker in _STANDALONE:
            continue
        if marker in (0xD9, 0xDA):  # end of image, start of scan: no frame header came first
            break
        if pos + 2 > end:
            break
        (length,) = struct.unpack(">H", data[pos : pos + 2])
        if length < 2:
            raise ProtocolError(f"JPEG: segment length {length} at byte {pos}")
        if marker in _SOF:
            if pos + 7 > end:
                break
            height, width = struct.unpack(">HH", data[pos + 3 : pos + 7])
            return ImageHeader("jpeg", width, height)
        pos += length
    raise ProtocolError(f"JPEG: no frame header (size) in its {len(data)} bytes")


def decode_image(data: bytes, *, max_width: int, max_height: int, max_bytes: int | None = None) -> np.ndarray:
    """A ``(h, w, 3)`` uint8 BGR image from JPEG or PNG bytes no larger than the limits.

    The header is checked before anything is decoded: more than ``max_width`` x
    ``max_height`` pixels (either way round: a camera may be mounted on its side), more
    than ``max_bytes`` bytes (default: 4 bytes a pixel plus 64 KiB), an empty size or another
    format is refused. Takes milliseconds for a camera-sized image: call it off the event loop.

    Raises:
        ProtocolError: what is wrong, with the numbers.
    """
    limit = max_bytes if max_bytes is not None else 4 * max_width * max_height + 65536
    if not data:
        raise ProtocolError("empty image payload")
    if len(data) > limit:
        raise ProtocolError(f"image of {len(data)} bytes; this camera's frames have at most {limit}")
    head = image_header(bytes(data))
    w, h = head.width, head.height
    if w < 1 or h < 1:
        raise ProtocolError(f"{head.format.upper()} header says {w} x {h} pixels")
    fits = (w <= max_width and h <= max_height) or (w <= max_height and h <= max_width)
    if not fits:
        raise ProtocolError(
            f"{head.format.upper()} header says {w} x {h} pixels; this camera's frames have at most "
            f"{max_width} x {max_height}"
        )
    img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise ProtocolError(f"not a decodable {head.format.upper()} image ({len(data)} bytes)")
    if img.shape[:2] != (h, w):  # the header lied (a second frame header, a DNL marker)
        raise ProtocolError(f"image decodes to {img.shape[1]} x {img.shape[0]}, its header said {w} x {h}")
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
