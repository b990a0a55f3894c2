"""Pictures of generated buildings: the map with its labels, doors and furniture (for the docs)."""

from __future__ import annotations

import math

import cv2
import numpy as np

from knowledge.labels import overlay
from sim.buildings_model import Building, Furniture


def label_building_png(
    building: Building, *, furniture_outlines: bool = True, annotate: bool = False, scale: int = 1
) -> np.ndarray:
    """A ``(rows·scale, cols·scale, 3)`` uint8 BGR picture of the map with its labels coloured.

    Doors are marked by a dark red bar along the opening, furniture (if
    ``furniture_outlines``) by thin purple outlines of its full size (the grid itself shows
    tables only by their legs). ``annotate`` writes each room's use and the names of the
    tour's items (couch, TV, bucket, charging station); ``scale`` enlarges the picture
    (nearest neighbour) so that small buildings stay legible.
    """
    if scale < 1:
        raise ValueError(f"scale must be a positive integer, got {scale}")
    g = building.grid
    img = overlay(g.to_image(), building.labels)
    if scale > 1:
        img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)

    def px(xy: tuple[float, float]) -> tuple[int, int]:
        r, c = g.world_to_cell_float(np.asarray(xy, dtype=np.float64))
        return (round(float(c) * scale), round(float(r) * scale))

    if furniture_outlines:
        for f in building.furniture:
            a, b = _corners(f)
            p0, p1 = px(a), px(b)
            cv2.rectangle(img, p0, (p1[0] - 1, p1[1] - 1), (150, 60, 150), 1)
    for d in building.doors:
        t = d.orientation + math.pi / 2
        h = d.width / 2
        a = (d.center[0] - h * math.cos(t), d.center[1] - h * math.sin(t))
        b = (d.center[0] + h * math.cos(t), d.center[1] + h * math.sin(t))
        cv2.line(img, px(a), px(b), (20, 20, 140), max(1, scale))
    if annotate:
        font, fs = cv2.FONT_HERSHEY_SIMPLEX, 0.3 * scale
        for r in building.rooms:
            if r.kind == "room" and r.use != "office":
                _text(img, r.use, px(r.center), font, fs, (60, 40, 20))
        named = {"couch": "couch", "tv": "TV", "bucket": "bucket", "charging_station": "charger"}
        for f in building.furniture:
            if f.kind in named:
                _text(img, named[f.kind], px(f.center), font, fs, (20, 20, 160))
    return img


def _text(
    img: np.ndarray, text: str, at: tuple[int, int], font: int, fs: float, colour: tuple[int, int, int]
) -> None:
    (w, h), _ = cv2.getTextSize(text, font, fs, 1)
    org = (at[0] - w // 2, at[1] + h // 2)
    cv2.putText(img, text, org, font, fs, (255, 255, 255), 3, cv2.LINE_AA)
    cv2.putText(img, text, org, font, fs, colour, 1, cv2.LINE_AA)


def _corners(f: Furniture) -> tuple[tuple[float, float], tuple[float, float]]:
    """Top-left and bottom-right world corners of an item's axis-aligned footprint."""
    w, d = f.size
    along_x = math.isclose(abs(math.cos(f.yaw)), 1.0, abs_tol=1e-6)
    hx, hy = (w / 2, d / 2) if along_x else (d / 2, w / 2)
    return (f.center[0] - hx, f.center[1] + hy), (f.center[0] + hx, f.center[1] - hy)
