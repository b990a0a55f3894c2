"""Small file helpers shared by the core: atomic writes of bytes, text and images."""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from pathlib import Path

import cv2
import numpy as np


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically: a temp file in the same folder, fsync, rename.

    A reader sees either the old file or the new one, never a torn one, even if the
    process is killed half-way.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        # mkstemp creates 0600; keep an existing file's mode, else the usual 0644
        try:
            mode = p.stat().st_mode & 0o777
        except FileNotFoundError:
            mode = 0o644
        os.fchmod(fd, mode)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        Path(tmp).replace(p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p


def remove_stale_temps(path: str | Path) -> list[Path]:
    """Remove the temp files :func:`atomic_write_bytes` left beside ``path`` when a process was
    killed half-way through a write (``.<name>.*.tmp``; the file itself is intact). Call it
    before writing ``path`` again; returns what was removed."""
    p = Path(path)
    removed = []
    for tmp in p.parent.glob(f".{p.name}.*.tmp"):
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
            removed.append(tmp)
    return removed


def atomic_write_text(path: str | Path, text: str) -> Path:
    """:func:`atomic_write_bytes` for UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def encode_image(path: str | Path, image: np.ndarray) -> bytes:
    """Encode an image in the format named by ``path``'s suffix (.png, .pgm, .jpg)."""
    ext = Path(path).suffix.lower() or ".png"
    ok, buf = cv2.imencode(ext, np.ascontiguousarray(image))
    if not ok:
        raise ValueError(f"cannot encode a {image.dtype} image of shape {image.shape} as {ext}")
    return buf.tobytes()


def write_image(path: str | Path, image: np.ndarray) -> Path:
    """Write an image atomically (format from the suffix)."""
    return atomic_write_bytes(path, encode_image(path, image))


def file_sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes, read in 1 MiB blocks (hex digits)."""
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
