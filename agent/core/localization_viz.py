"""Pictures for localization: trajectories over a map, particle clouds over a map.

Pure drawing on numpy images with OpenCV; the caller writes the files.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import cv2
import numpy as np

from knowledge.metric.grid import OccupancyGrid

__all__ = ["map_canvas", "particles_picture", "trajectory_picture"]

Colour = tuple[int, int, int]
_FONT = cv2.FONT_HERSHEY_SIMPLEX


def map_canvas(grid: OccupancyGrid, scale: float) -> np.ndarray:
    """The map as a BGR image (free white, occupied black, unknown light grey), scaled."""
    grey = np.full(grid.shape, 215, dtype=np.uint8)
    grey[grid.free] = 255
    grey[grid.occupied] = 30
    bgr = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    return np.asarray(cv2.resize(bgr, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA))


def _px(grid: OccupancyGrid, xy: np.ndarray, scale: float) -> np.ndarray:
    rc = grid.world_to_cell_float(np.asarray(xy, dtype=np.float64)[:, :2])
    return np.round(np.column_stack([rc[:, 1], rc[:, 0]]) * scale).astype(np.int32)


def trajectory_picture(
    grid: OccupancyGrid,
    paths: Mapping[str, tuple[np.ndarray, Colour]],
    title: str,
    *,
    scale: float = 0.5,
) -> np.ndarray:
    """The map with each named path ``(N, 3)`` (world frame) drawn as a polyline, a legend and a title."""
    img = map_canvas(grid, scale)
    for poses, colour in paths.values():
        if len(poses) > 1:
            cv2.polylines(img, [_px(grid, poses, scale)], False, colour, 2, cv2.LINE_AA)
    band = np.full((34 + 24 * len(paths), img.shape[1], 3), 255, dtype=np.uint8)
    cv2.putText(band, title, (8, 24), _FONT, 0.55, (20, 20, 20), 1, cv2.LINE_AA)
    for k, (name, (_, colour)) in enumerate(paths.items()):
        y = 50 + 24 * k
        cv2.line(band, (10, y - 5), (40, y - 5), colour, 3)
        cv2.putText(band, name, (50, y), _FONT, 0.5, (20, 20, 20), 1, cv2.LINE_AA)
    return np.vstack([band, img])


def particles_picture(
    grid: OccupancyGrid,
    panels: Sequence[tuple[str, np.ndarray, np.ndarray | None]],
    *,
    scale: float = 0.25,
    columns: int = 4,
) -> np.ndarray:
    """Panels of particle clouds: ``(caption, (N, 3) world particles, (3,) true pose or None)``;
    particles blue dots, the true pose a red circle with its heading."""
    tiles = []
    for caption, particles, truth in panels:
        img = map_canvas(grid, scale)
        for x, y in _px(grid, particles, scale):
            if 0 <= y < img.shape[0] and 0 <= x < img.shape[1]:
                cv2.circle(img, (int(x), int(y)), 1, (210, 80, 0), -1)
        if truth is not None:
            c = _px(grid, truth[None, :], scale)[0]
            tip = _px(
                grid, (truth[:2] + 1.5 * np.array([np.cos(truth[2]), np.sin(truth[2])]))[None, :], scale
            )[0]
            cv2.circle(img, (int(c[0]), int(c[1])), 7, (30, 30, 220), 2, cv2.LINE_AA)
            cv2.line(img, (int(c[0]), int(c[1])), (int(tip[0]), int(tip[1])), (30, 30, 220), 2, cv2.LINE_AA)
        band = np.full((26, img.shape[1], 3), 255, dtype=np.uint8)
        cv2.putText(band, caption, (6, 18), _FONT, 0.42, (20, 20, 20), 1, cv2.LINE_AA)
        tiles.append(np.vstack([band, img]))
    rows = []
    for k in range(0, len(tiles), columns):
        row = tiles[k : k + columns]
        while len(row) < columns:
            row.append(np.full_like(tiles[0], 255))
        rows.append(np.hstack([np.pad(t, ((2, 2), (2, 2), (0, 0)), constant_values=160) for t in row]))
    return np.vstack(rows)
