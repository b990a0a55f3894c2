"""Place classes, their codes in label images, and label-image I/O.

Label images are 8-bit PNGs, one pixel per map cell, in the map image's orientation:

====  =========
code  class
====  =========
0     no label (occupied, unknown, or not classified)
1     room
2     corridor
3     doorway
4     hallway
====  =========

Other codes may be declared by a JSON legend beside the image (``labels.png`` →
``labels.legend.json``: ``{"1": "room", "7": "kitchen"}``). The labelled maps of the IPA
data set use their own grey values (77 room, 115 corridor, 179 doorway), which
:data:`IPA_CODES` translates.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import cv2
import numpy as np

from knowledge.errors import MapError
from knowledge.fileio import atomic_write_text, write_image

NONE = 0
ROOM = 1
CORRIDOR = 2
DOORWAY = 3
HALLWAY = 4

#: The standard label codes and their class names.
CLASS_NAMES: dict[int, str] = {ROOM: "room", CORRIDOR: "corridor", DOORWAY: "doorway", HALLWAY: "hallway"}
#: Class name → code.
CLASS_CODES: dict[str, int] = {name: code for code, name in CLASS_NAMES.items()}

#: Grey values of the IPA labelled maps (../shared/data/ipa/labeled) → standard codes.
IPA_CODES: dict[int, int] = {77: ROOM, 115: CORRIDOR, 179: DOORWAY}

#: BGR colours for overlays (room blue-ish, corridor orange, doorway red, hallway green).
CLASS_COLORS_BGR: dict[int, tuple[int, int, int]] = {
    ROOM: (200, 140, 60),
    CORRIDOR: (40, 170, 250),
    DOORWAY: (40, 40, 220),
    HALLWAY: (90, 190, 90),
}


def legend_path(label_path: str | Path) -> Path:
    """The JSON legend that may sit beside a label image."""
    p = Path(label_path)
    return p.with_name(p.stem + ".legend.json")


def read_legend(label_path: str | Path) -> dict[int, str]:
    """Code → class name for a label image: the standard table, extended by its legend."""
    names = dict(CLASS_NAMES)
    lp = legend_path(label_path)
    if lp.exists():
        try:
            raw = json.loads(lp.read_text())
            names.update({int(k): str(v) for k, v in raw.items()})
        except (ValueError, AttributeError) as exc:
            raise MapError(f'{lp}: a legend must map codes to class names, e.g. {{"7": "kitchen"}}') from exc
    return names


def read_label_image(path: str | Path, codes: Mapping[int, int] | None = None) -> np.ndarray:
    """Read an 8-bit label image as a ``(rows, cols)`` uint8 array of class codes.

    ``codes`` translates grey values to codes (e.g. :data:`IPA_CODES`); grey values not in
    it become 0 (no label). Without ``codes`` the pixel values are the codes.
    """
    p = Path(path)
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise MapError(f"{p}: cannot read label image (missing file or not an image)")
    if img.ndim == 3:
        raise MapError(f"{p}: a label image must be single-channel (8-bit grey), got {img.shape[2]} channels")
    if img.dtype != np.uint8:
        raise MapError(f"{p}: a label image must be 8-bit, got {img.dtype}")
    if codes is None:
        return np.ascontiguousarray(img)
    lut = np.zeros(256, dtype=np.uint8)
    for grey, code in codes.items():
        lut[grey] = code
    return lut[img]


def write_label_image(path: str | Path, labels: np.ndarray, legend: Mapping[int, str] | None = None) -> None:
    """Write class codes as an 8-bit PNG, and a legend JSON if non-standard codes are named."""
    p = Path(path)
    arr = np.asarray(labels)
    if arr.ndim != 2:
        raise ValueError(f"labels must be a 2-D array of codes, got shape {arr.shape}")
    if arr.size and (arr.min() < 0 or arr.max() > 255):
        raise ValueError("label codes must lie in 0..255")
    write_image(p, arr.astype(np.uint8))
    if legend:
        extra = {str(k): v for k, v in legend.items() if CLASS_NAMES.get(int(k)) != v}
        if extra:
            atomic_write_text(legend_path(p), json.dumps(extra, indent=2) + "\n")


def overlay(background: np.ndarray, labels: np.ndarray, alpha: float = 0.6) -> np.ndarray:
    """A BGR picture of ``labels`` coloured over a grey ``background`` (map image).

    ``background`` is a ``(rows, cols)`` uint8 grey image; returns ``(rows, cols, 3)`` uint8.
    """
    bg = np.asarray(background)
    if bg.shape != labels.shape:
        raise ValueError(f"background {bg.shape} and labels {labels.shape} differ in shape")
    out = cv2.cvtColor(bg.astype(np.uint8), cv2.COLOR_GRAY2BGR).astype(np.float32)
    for code, colour in CLASS_COLORS_BGR.items():
        m = labels == code
        if m.any():
            out[m] = (1 - alpha) * out[m] + alpha * np.asarray(colour, np.float32)
    return np.clip(out, 0, 255).astype(np.uint8)
