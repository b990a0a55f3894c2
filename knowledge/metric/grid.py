"""Occupancy grids: loading ROS map_server maps and plain images, world ↔ cell transforms.

A grid is stored in *image orientation*: row 0 is the top row of the map image, column 0
its left column, exactly as the PNG/PGM file and the label images lie. The world frame is
the ROS one (x right, y up, metres); ``origin`` is the world pose of the *lower-left*
corner of the lower-left cell, as in map_server's YAML. The transforms below do the flip.

Cell states follow ROS ``nav_msgs/OccupancyGrid``: 0 free, 100 occupied, -1 unknown.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml

from knowledge.errors import MapError
from knowledge.fileio import atomic_write_bytes, encode_image

FREE = 0
OCCUPIED = 100
UNKNOWN = -1

#: map_server's defaults.
DEFAULT_OCCUPIED_THRESH = 0.65
DEFAULT_FREE_THRESH = 0.196


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """A 2-D occupancy grid map.

    Attributes:
        state: ``(rows, cols)`` int8 array of cell states (0 free, 100 occupied, -1 unknown),
            row 0 at the top of the map image.
        resolution: cell side in metres.
        origin: world pose ``(x, y, yaw)`` of the lower-left corner of the map (metres, rad).
        name: a label for messages and pictures (usually the file stem).
    """

    state: np.ndarray
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    name: str = "map"

    def __post_init__(self) -> None:
        st = np.asarray(self.state)
        if st.ndim != 2 or st.shape[0] == 0 or st.shape[1] == 0:
            raise MapError(
                f"{self.name}: an occupancy grid must be a non-empty 2-D array, got shape {st.shape}"
            )
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise MapError(
                f"{self.name}: resolution must be a positive number of metres, got {self.resolution}"
            )
        if len(self.origin) != 3 or not all(math.isfinite(v) for v in self.origin):
            raise MapError(f"{self.name}: origin must be (x, y, yaw), got {self.origin}")
        st = np.ascontiguousarray(st, dtype=np.int8)
        bad = ~np.isin(st, (FREE, OCCUPIED, UNKNOWN))
        if bad.any():
            raise MapError(f"{self.name}: cell states must be 0 (free), 100 (occupied) or -1 (unknown)")
        st.setflags(write=False)
        object.__setattr__(self, "state", st)
        object.__setattr__(self, "origin", tuple(float(v) for v in self.origin))

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_masks(
        cls,
        occupied: np.ndarray,
        resolution: float,
        *,
        unknown: np.ndarray | None = None,
        origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
        name: str = "map",
    ) -> OccupancyGrid:
        """A grid from boolean masks (image orientation). Cells in neither mask are free."""
        occ = np.asarray(occupied, dtype=bool)
        st = np.where(occ, OCCUPIED, FREE).astype(np.int8)
        if unknown is not None:
            unk = np.asarray(unknown, dtype=bool)
            if unk.shape != occ.shape:
                raise MapError(f"{name}: occupied {occ.shape} and unknown {unk.shape} masks differ in shape")
            st[unk & ~occ] = UNKNOWN
        return cls(st, resolution, origin, name)

    @classmethod
    def from_image(
        cls,
        path: str | Path,
        resolution: float,
        *,
        origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
        occupied_thresh: float = DEFAULT_OCCUPIED_THRESH,
        free_thresh: float = DEFAULT_FREE_THRESH,
        negate: bool = False,
        name: str | None = None,
    ) -> OccupancyGrid:
        """Load a map image (PNG, PGM, ...) with an explicit resolution, thresholded as map_server does.

        Each pixel's occupancy probability is ``p = (255 - v) / 255`` (``v / 255`` when
        ``negate``), averaged over colour channels; ``p > occupied_thresh`` is occupied,
        ``p < free_thresh`` free, anything between unknown (map_server's trinary mode).
        """
        p = Path(path)
        img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise MapError(f"{p}: cannot read map image (missing file or unsupported format)")
        return cls.from_array(
            img,
            resolution,
            origin=origin,
            occupied_thresh=occupied_thresh,
            free_thresh=free_thresh,
            negate=negate,
            name=name or p.stem,
        )

    @classmethod
    def from_array(
        cls,
        image: np.ndarray,
        resolution: float,
        *,
        origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
        occupied_thresh: float = DEFAULT_OCCUPIED_THRESH,
        free_thresh: float = DEFAULT_FREE_THRESH,
        negate: bool = False,
        name: str = "map",
    ) -> OccupancyGrid:
        """Threshold an image array (grey, BGR or BGRA; 8 or 16 bit) as :meth:`from_image` does."""
        img = np.asarray(image)
        if not 0.0 <= free_thresh <= occupied_thresh <= 1.0:
            raise MapError(
                f"{name}: thresholds must satisfy 0 <= free_thresh <= occupied_thresh <= 1, "
                f"got free_thresh={free_thresh}, occupied_thresh={occupied_thresh}"
            )
        full = float(np.iinfo(img.dtype).max) if np.issubdtype(img.dtype, np.integer) else 1.0
        if img.ndim == 3:
            img = img[..., :3] if img.shape[2] >= 3 else img[..., :1]
            v = img.astype(np.float64).mean(axis=2)
        elif img.ndim == 2:
            v = img.astype(np.float64)
        else:
            raise MapError(f"{name}: a map image must be 2-D (grey) or 3-D (colour), got shape {img.shape}")
        occ_p = v / full if negate else (full - v) / full
        st = np.full(v.shape, UNKNOWN, dtype=np.int8)
        st[occ_p > occupied_thresh] = OCCUPIED
        st[occ_p < free_thresh] = FREE
        return cls(st, resolution, origin, name)

    @classmethod
    def from_yaml(cls, path: str | Path) -> OccupancyGrid:
        """Load a ROS map_server map: the YAML file and the image it names (relative to it).

        Modes: ``trinary`` (the default) and ``scale`` are thresholded alike — a grid here has
        three states, so ``scale``'s in-between probabilities become unknown; ``raw`` reads
        pixel values as occupancy 0–100 (≥ 50 occupied, < 50 free, > 100 unknown), without
        ``negate``, as map_server does.
        """
        p = Path(path)
        try:
            meta = yaml.safe_load(p.read_text())
        except OSError as exc:
            raise MapError(f"{p}: cannot read map YAML: {exc.strerror}") from exc
        except yaml.YAMLError as exc:
            raise MapError(f"{p}: not valid YAML: {exc}") from exc
        if not isinstance(meta, Mapping):
            raise MapError(f"{p}: a map YAML must be a mapping with image, resolution and origin")
        for key in ("image", "resolution"):
            if key not in meta:
                raise MapError(f"{p}: missing key '{key}'")
        mode = meta.get("mode", "trinary")
        if mode not in ("trinary", "scale", "raw"):
            raise MapError(f"{p}: unknown mode '{mode}' (map_server knows trinary, scale and raw)")
        image = Path(str(meta["image"]))
        if not image.is_absolute():
            image = p.parent / image
        origin_raw = meta.get("origin", [0.0, 0.0, 0.0])
        try:
            origin = (float(origin_raw[0]), float(origin_raw[1]), float(origin_raw[2]))
            resolution = float(meta["resolution"])
            occ_t = float(meta.get("occupied_thresh", DEFAULT_OCCUPIED_THRESH))
            free_t = float(meta.get("free_thresh", DEFAULT_FREE_THRESH))
        except (TypeError, ValueError, IndexError) as exc:
            raise MapError(f"{p}: resolution, origin [x, y, yaw] and thresholds must be numbers") from exc
        negate = bool(meta.get("negate", 0))
        if mode == "raw":
            img = cv2.imread(str(image), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise MapError(f"{image}: cannot read map image named by {p}")
            st = np.full(img.shape, UNKNOWN, dtype=np.int8)
            st[img <= 100] = np.where(img[img <= 100] >= 50, OCCUPIED, FREE)
            return cls(st, resolution, origin, p.stem)
        return cls.from_image(
            image,
            resolution,
            origin=origin,
            occupied_thresh=occ_t,
            free_thresh=free_t,
            negate=negate,
            name=p.stem,
        )

    @classmethod
    def load(cls, path: str | Path, resolution: float | None = None) -> OccupancyGrid:
        """Load a ``.yaml`` map_server map, or an image with an explicit ``resolution``."""
        p = Path(path)
        if p.suffix.lower() in (".yaml", ".yml"):
            if resolution is not None:
                grid = cls.from_yaml(p)
                if not math.isclose(grid.resolution, resolution, rel_tol=1e-9):
                    raise MapError(f"{p}: --resolution {resolution} contradicts the YAML's {grid.resolution}")
                return grid
            return cls.from_yaml(p)
        if resolution is None:
            raise MapError(
                f"{p}: an image map needs its resolution in metres per cell (e.g. --resolution 0.05)"
            )
        return cls.from_image(p, resolution)

    # ------------------------------------------------------------------ saving
    def to_image(self) -> np.ndarray:
        """The map as an 8-bit grey image: 254 free, 0 occupied, 205 unknown (map_saver's values)."""
        img = np.full(self.shape, 205, dtype=np.uint8)
        img[self.state == FREE] = 254
        img[self.state == OCCUPIED] = 0
        return img

    def save(self, yaml_path: str | Path) -> Path:
        """Write a map_server map: ``<name>.yaml`` and a PGM beside it (atomically). Returns the YAML path."""
        yp = Path(yaml_path)
        image = yp.with_suffix(".pgm")
        atomic_write_bytes(image, encode_image(image, self.to_image()))
        meta = {
            "image": image.name,
            "resolution": self.resolution,
            "origin": list(self.origin),
            "negate": 0,
            "occupied_thresh": DEFAULT_OCCUPIED_THRESH,
            "free_thresh": DEFAULT_FREE_THRESH,
        }
        atomic_write_bytes(yp, yaml.safe_dump(meta, sort_keys=False).encode())
        return yp

    # ------------------------------------------------------------------ properties
    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)``."""
        return (int(self.state.shape[0]), int(self.state.shape[1]))

    @property
    def free(self) -> np.ndarray:
        """``(rows, cols)`` bool: free cells."""
        return self.state == FREE

    @property
    def occupied(self) -> np.ndarray:
        """``(rows, cols)`` bool: occupied cells."""
        return self.state == OCCUPIED

    @property
    def unknown(self) -> np.ndarray:
        """``(rows, cols)`` bool: unknown cells."""
        return self.state == UNKNOWN

    @property
    def size_m(self) -> tuple[float, float]:
        """Width and height of the map in metres."""
        return (self.shape[1] * self.resolution, self.shape[0] * self.resolution)

    def free_cells(self) -> np.ndarray:
        """``(N, 2)`` int64 ``(row, col)`` of every free cell, in row-major order."""
        return np.argwhere(self.free)

    # ------------------------------------------------------------------ transforms
    def cell_to_world(self, cells: np.ndarray) -> np.ndarray:
        """World ``(x, y)`` in metres of the centres of cells ``(..., 2)`` given as ``(row, col)``."""
        rc = np.asarray(cells, dtype=np.float64)
        rows, _ = self.shape
        # map-frame coordinates of the cell centre (lower-left corner is the origin)
        mx = (rc[..., 1] + 0.5) * self.resolution
        my = (rows - rc[..., 0] - 0.5) * self.resolution
        return self._map_to_world(mx, my)

    def world_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """``(row, col)`` int64 of the cells containing world points ``(..., 2)`` (may be out of bounds).

        The floor of :meth:`world_to_cell_float`, so both agree on points on cell borders.
        """
        return np.floor(self.world_to_cell_float(xy)).astype(np.int64)

    def world_to_cell_float(self, xy: np.ndarray) -> np.ndarray:
        """Continuous ``(row, col)`` of world points: cell ``(r, c)`` spans ``[r, r+1) × [c, c+1)``."""
        p = np.asarray(xy, dtype=np.float64)
        mx, my = self._world_to_map(p[..., 0], p[..., 1])
        rows, _ = self.shape
        return np.stack([rows - my / self.resolution, mx / self.resolution], axis=-1)

    def in_bounds(self, cells: np.ndarray) -> np.ndarray:
        """Bool mask: which ``(row, col)`` lie inside the grid."""
        rc = np.asarray(cells)
        rows, cols = self.shape
        return (rc[..., 0] >= 0) & (rc[..., 0] < rows) & (rc[..., 1] >= 0) & (rc[..., 1] < cols)

    @property
    def yaw(self) -> float:
        """Rotation of the map frame in the world frame (radians)."""
        return self.origin[2]

    def _map_to_world(self, mx: np.ndarray, my: np.ndarray) -> np.ndarray:
        ox, oy, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        return np.stack([ox + c * mx - s * my, oy + s * mx + c * my], axis=-1)

    def _world_to_map(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ox, oy, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        dx, dy = x - ox, y - oy
        return c * dx + s * dy, -s * dx + c * dy

    def __repr__(self) -> str:
        rows, cols = self.shape
        return (
            f"OccupancyGrid(name={self.name!r}, {rows}x{cols} cells at {self.resolution} m, "
            f"{int(self.free.sum())} free, origin={self.origin})"
        )
