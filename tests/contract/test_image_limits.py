"""drivers.camera.jpeg: an image's size is read from its header, and a frame larger than the
camera's is refused before anything is decoded (issue 18, failure 2)."""

from __future__ import annotations

import struct

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.camera.jpeg import decode_image, image_header
from knowledge.errors import ProtocolError

W, H = 640, 480


def encoded(ext: str, width: int, height: int, **params: int) -> bytes:
    img = np.random.default_rng(0).integers(0, 255, (height, width, 3), np.uint8)
    flags = [v for kv in params.items() for v in (getattr(cv2, kv[0]), kv[1])]
    ok, buf = cv2.imencode(ext, img, flags)
    assert ok
    return buf.tobytes()


def claiming(data: bytes, width: int, height: int) -> bytes:
    """``data`` (a JPEG or PNG) with its header changed to claim ``width`` x ``height``."""
    out = bytearray(data)
    if out[:4] == b"\x89PNG":
        out[16:24] = struct.pack(">II", width, height)
    else:
        sof = next(i for i in range(len(out) - 1) if out[i] == 0xFF and out[i + 1] in (0xC0, 0xC2))
        out[sof + 5 : sof + 9] = struct.pack(">HH", height, width)
    return bytes(out)


@pytest.mark.parametrize(
    ("ext", "params", "fmt"),
    [(".jpg", {}, "jpeg"), (".jpg", {"IMWRITE_JPEG_PROGRESSIVE": 1}, "jpeg"), (".png", {}, "png")],
    ids=["baseline-jpeg", "progressive-jpeg", "png"],
)
def test_header_gives_the_size_without_decoding(ext: str, params: dict[str, int], fmt: str) -> None:
    data = encoded(ext, 320, 200, **params)
    assert tuple(image_header(data)) == (fmt, 320, 200)
    img = decode_image(data, max_width=W, max_height=H)
    assert img.shape == (200, 320, 3) and img.dtype == np.uint8


@pytest.mark.parametrize("size", [(65000, 65000), (20000, 20000), (641, 480), (640, 481), (0, 480)])
@pytest.mark.parametrize("ext", [".jpg", ".png"])
def test_a_header_larger_than_the_camera_is_refused_with_both_sizes(ext: str, size: tuple[int, int]) -> None:
    # failure 2: 65,000 x 65,000 made cv2.imdecode raise (the agent exited); 20,000 x 20,000
    # took 7.9 s (memory to 2.6 GB)
    data = claiming(encoded(ext, 64, 48), *size)
    with pytest.raises(ProtocolError, match=rf"header says {size[0]} x {size[1]} pixels"):
        decode_image(data, max_width=W, max_height=H)


def test_a_camera_on_its_side_and_an_exact_fit_pass() -> None:
    assert decode_image(encoded(".jpg", 480, 640), max_width=W, max_height=H).shape == (640, 480, 3)
    assert decode_image(encoded(".jpg", W, H), max_width=W, max_height=H).shape == (H, W, 3)


def test_too_many_bytes_other_formats_and_cut_headers_are_refused() -> None:
    data = encoded(".jpg", 64, 48)
    with pytest.raises(ProtocolError, match=r"image of \d+ bytes; this camera's frames have at most 100"):
        decode_image(data, max_width=W, max_height=H, max_bytes=100)
    for other in (".bmp", ".tiff", ".webp"):
        with pytest.raises(ProtocolError, match="not a JPEG or PNG"):
            decode_image(encoded(other, 64, 48), max_width=W, max_height=H)
    # a header that claims less than the data holds: decoded to the header's size, no more
    assert decode_image(claiming(data, 60, 40), max_width=W, max_height=H).shape == (40, 60, 3)
    for cut in (b"", b"\xff\xd8", b"\xff\xd8\xff\xe0\x00\x10JFIF", data[:20], b"\x89PNG\r\n\x1a\n"):
        with pytest.raises(ProtocolError):
            decode_image(cut, max_width=W, max_height=H)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300), st.sampled_from([b"", b"\xff\xd8", b"\x89PNG\r\n\x1a\n\x00\x00\x00\x0dIHDR"]))
def test_any_bytes_give_an_image_or_a_protocol_error(tail: bytes, head: bytes) -> None:
    try:
        img = decode_image(head + tail, max_width=W, max_height=H)
    except ProtocolError:
        return
    assert img.ndim == 3 and img.shape[0] <= H and img.shape[1] <= W
