"""Label and region images other tools can open: a map_server YAML beside each, a legend on pictures.

A label image (:mod:`knowledge.labels`) has one pixel per cell of the map it was made from,
in the same orientation, so the map's resolution and origin place it in the world as well.
:func:`label_map_yaml` is the ROS ``map_server`` description of such an image with
``mode: raw``: map_server then reads each pixel value as the cell's value (0 no label,
1 room, 2 corridor, 3 doorway, 4 hallway), so the label codes arrive unchanged in the
``nav_msgs/OccupancyGrid`` it publishes, and RViz or Foxglove draw them as a map layer over
the occupancy map. (In ``raw`` mode map_server takes values above 100 as unknown, so a
16-bit region image loaded this way shows its first 100 region ids only.)
:func:`write_label_map` writes a label image with its YAML (and its legend, if it names
codes of its own).

:func:`with_legend` adds a strip under a coloured picture naming each class colour used.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import cv2
import numpy as np
import yaml

from knowledge.fileio import atomic_write_text
from knowledge.labels import CLASS_COLORS_BGR, CLASS_NAMES, write_label_image

#: Pixels of one legend row.
LEGEND_ROW = 26


def yaml_path(image_path: str | Path) -> Path:
    """The YAML that describes ``image_path``: ``labels.png`` → ``labels.yaml``."""
    return Path(image_path).with_suffix(".yaml")


def label_map_yaml(
    image_name: str,
    resolution: float,
    origin: tuple[float, float, float],
    *,
    legend: Mapping[int, str] | None = None,
    regions: bool = False,
) -> str:
    """The map_server YAML of a label (or region) image of a map with ``resolution`` (metres
    per cell) and ``origin`` (x, y, yaw of its lower-left corner), ``mode: raw``.

    ``legend`` (code → class name) is written as a comment, which map_server ignores;
    ``regions``: the image holds region ids, not class codes (said in the comment).
    """
    meta = {
        "image": image_name,
        "mode": "raw",
        "resolution": float(resolution),
        "origin": [float(v) for v in origin],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    if regions:
        lines = [
            "# region ids (0 no region), read unchanged by map_server (mode raw); ids above 100 read as unknown"
        ]
    else:
        names = dict(CLASS_NAMES) | dict(legend or {})
        lines = [
            "# label codes, read unchanged by map_server (mode raw)",
            "# " + ", ".join(f"{c} {n}" for c, n in sorted(names.items())) + "; 0 no label",
        ]
    return "\n".join(lines) + "\n" + yaml.safe_dump(meta, sort_keys=False)


def write_label_map(
    image_path: str | Path,
    labels: np.ndarray,
    resolution: float,
    origin: tuple[float, float, float],
    legend: Mapping[int, str] | None = None,
) -> Path:
    """Write ``labels`` (``(rows, cols)`` codes of a map with ``resolution`` and ``origin``)
    as an 8-bit PNG, the legend JSON beside it if ``legend`` names codes other than the
    standard ones, and its map_server YAML (:func:`label_map_yaml`, :func:`yaml_path`);
    each file atomically. Returns the YAML's path."""
    write_label_image(image_path, labels, legend)
    text = label_map_yaml(Path(image_path).name, resolution, origin, legend=legend)
    return atomic_write_text(yaml_path(image_path), text)


def legend_entries(
    labels: np.ndarray, names: Mapping[int, str] | None = None
) -> list[tuple[str, tuple[int, int, int]]]:
    """``(class name, BGR colour)`` of each coloured class present in ``labels``, by code."""
    table = dict(CLASS_NAMES) | dict(names or {})
    present = {int(c) for c in np.unique(np.asarray(labels))}
    return [(table.get(c, str(c)), CLASS_COLORS_BGR[c]) for c in sorted(CLASS_COLORS_BGR) if c in present]


def with_legend(picture: np.ndarray, entries: list[tuple[str, tuple[int, int, int]]]) -> np.ndarray:
    """``picture`` (BGR uint8) with a white strip below naming each ``(name, BGR colour)``.

    Entries wrap onto as many rows as the picture's width needs; no entries: the picture as is.
    """
    pic: np.ndarray = np.asarray(picture, dtype=np.uint8)
    if pic.ndim == 2:
        pic = cv2.cvtColor(pic, cv2.COLOR_GRAY2BGR)
    if not entries:
        return pic
    width = max(pic.shape[1], 160)
    font, scale, thick = cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1
    placed: list[tuple[int, int, str, tuple[int, int, int]]] = []
    x, row = 8, 0
    for name, colour in entries:
        (tw, _), _ = cv2.getTextSize(name, font, scale, thick)
        need = 18 + 6 + tw + 16
        if x + need > width and x > 8:
            x, row = 8, row + 1
        placed.append((x, row, name, colour))
        x += need
    strip = np.full((LEGEND_ROW * (row + 1) + 4, width, 3), 255, np.uint8)
    for x0, r, name, colour in placed:
        y0 = 4 + r * LEGEND_ROW
        cv2.rectangle(strip, (x0, y0 + 3), (x0 + 18, y0 + 19), tuple(int(c) for c in colour), -1)
        cv2.rectangle(strip, (x0, y0 + 3), (x0 + 18, y0 + 19), (60, 60, 60), 1)
        cv2.putText(strip, name, (x0 + 24, y0 + 17), font, scale, (30, 30, 30), thick, cv2.LINE_AA)
    out = np.full((pic.shape[0] + strip.shape[0], width, 3), 255, np.uint8)
    out[: pic.shape[0], : pic.shape[1]] = pic
    out[pic.shape[0] :] = strip
    return out
