"""Regions of a label image, the region graph and the heuristic correction (book Sect. 4.7).

A *region* is a maximal set of 8-connected cells (4-connected on request) that carry the
same non-zero label code. The *region graph* joins two regions when a cell of one is an
8-neighbour (4-neighbour) of a cell of the other. Every region gets the properties of the
book: label, area, centroid, and the major and minor axes of its ellipse as vectors.

Conventions:

* Region ids are ``1..n``, grouped by label code (ascending) and in raster order of their
  first cell within a label. Id 0 is "no region" (label 0: walls, unknown, unlabelled).
* Cell coordinates are ``(row, col)`` indices as in :class:`~knowledge.metric.grid.OccupancyGrid`
  (row 0 at the top of the map image); world coordinates are the grid's ``(x, y)`` in metres.
* The ellipse is the one with the region's second moments, taking each cell as a full
  ``resolution × resolution`` square (the centre moments plus 1/12 cell² per axis, so a
  ``w × h`` rectangle has variances ``w²/12`` and ``h²/12``). Its semi-axes are twice the
  standard deviations along the principal directions; ``major_axis`` and ``minor_axis`` are
  vectors of those lengths, the major one pointing to ``x > 0`` (or ``+y`` when vertical), the
  minor one 90° counter-clockwise from it.
* The shared border of two regions A and B is ``resolution × ½(a + b)``, with ``a`` the number of
  cells of A that have a neighbour in B and ``b`` the same from B's side: a straight border
  of ``n`` cells measures ``n × resolution``, and regions touching only at a corner still get
  one cell's length.

Heuristic correction (:func:`correct_regions`): a place region (any label but doorway, i.e.
room, corridor, hallway) whose area does not exceed ``place_min_area_m2``, and a doorway region
whose area does not exceed ``doorway_min_area_m2`` or that has fewer than
``doorway_min_neighbours`` neighbour regions, is a classification error. It takes the label of the neighbour with which it shares the longest
border (ties: the larger neighbour, then the lower id), which merges it into that neighbour.
Within one round only regions whose chosen neighbour is not itself marked change (the smallest
marked region goes alone if every marked region points at another marked one); the regions
and the graph are then recomputed and the rounds repeat until nothing is marked. A marked
region without any neighbour (e.g. a small room closed by walls) cannot take a label from
anyone and is kept.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from knowledge.labels import DOORWAY
from knowledge.metric.grid import OccupancyGrid

_OFFSETS8 = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
_OFFSETS4 = ((-1, 0), (0, -1), (0, 1), (1, 0))


@dataclass(frozen=True)
class Region:
    """One region of the topological map.

    Attributes:
        id: region id (the pixel value in the region-id image).
        label: label code of its cells.
        cells: number of cells.
        area_m2: area in m².
        centroid_cell: mean ``(row, col)`` index of its cells (``grid.cell_to_world`` of it is
            the world centroid).
        centroid: world ``(x, y)`` in metres.
        major_axis, minor_axis: world vectors ``(x, y)`` in metres: the ellipse's semi-axes.
        major_axis_cells, minor_axis_cells: the same semi-axes as ``(drow, dcol)`` in cells.
        bbox: ``(row0, col0, row1, col1)``, half-open, in cells.
    """

    id: int
    label: int
    cells: int
    area_m2: float
    centroid_cell: tuple[float, float]
    centroid: tuple[float, float]
    major_axis: tuple[float, float]
    minor_axis: tuple[float, float]
    major_axis_cells: tuple[float, float]
    minor_axis_cells: tuple[float, float]
    bbox: tuple[int, int, int, int]

    @property
    def elongation(self) -> float:
        """Major over minor semi-axis length (≥ 1)."""
        return math.hypot(*self.major_axis) / max(math.hypot(*self.minor_axis), 1e-12)

    @property
    def orientation(self) -> float:
        """Angle of the major axis in the world frame, radians in ``(-π/2, π/2]``."""
        return math.atan2(self.major_axis[1], self.major_axis[0])


@dataclass(frozen=True)
class Edge:
    """Two touching regions (``a < b``) and the length of their shared border."""

    a: int
    b: int
    border_m: float
    border_cells: float


@dataclass(frozen=True, eq=False)
class RegionGraph:
    """Regions of a label image and which of them touch.

    Attributes:
        ids: ``(rows, cols)`` int32 region ids, 0 where there is no region.
        regions: the regions; ``regions[i].id == i + 1``.
        edges: touching pairs, sorted by ``(a, b)``.
        resolution: cell side in metres.
        connectivity: 8 or 4.
    """

    ids: np.ndarray
    regions: tuple[Region, ...]
    edges: tuple[Edge, ...]
    resolution: float
    connectivity: int = 8

    def region(self, region_id: int) -> Region:
        """The region with this id."""
        if not 1 <= region_id <= len(self.regions):
            raise KeyError(f"no region {region_id} (ids run from 1 to {len(self.regions)})")
        return self.regions[region_id - 1]

    def neighbours(self, region_id: int) -> dict[int, float]:
        """Neighbour id → shared border in metres."""
        out: dict[int, float] = {}
        for e in self.edges:
            if e.a == region_id:
                out[e.b] = e.border_m
            elif e.b == region_id:
                out[e.a] = e.border_m
        return out

    def labels(self) -> np.ndarray:
        """``(rows, cols)`` uint8 label image rebuilt from the regions."""
        lut = np.zeros(len(self.regions) + 1, dtype=np.uint8)
        lut[1:] = [r.label for r in self.regions]
        return lut[self.ids]


# ---------------------------------------------------------------------- extraction
def label_regions(labels: np.ndarray, connectivity: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Connected components of each non-zero label code.

    Returns:
        ``(ids, region_labels)``: ``(rows, cols)`` int32 ids (0 = none) and ``(n + 1,)``
        label code of each id (``region_labels[0] = 0``).
    """
    lab = _check_labels(labels)
    structure = _structure(connectivity)
    ids = np.zeros(lab.shape, dtype=np.int32)
    region_labels = [0]
    for code in np.unique(lab):
        if code == 0:
            continue
        comp, n = ndimage.label(lab == code, structure=structure)
        mask = comp > 0
        ids[mask] = comp[mask] + (len(region_labels) - 1)
        region_labels.extend([int(code)] * int(n))
    return ids, np.asarray(region_labels, dtype=np.int64)


def adjacency(ids: np.ndarray, n: int, connectivity: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which regions touch, and how many border cells each side has.

    Args:
        ids: ``(rows, cols)`` region ids, 0 = none; ``n`` the largest id.

    Returns:
        ``(a, b, cells)``: int arrays of directed pairs ``a → b`` (``a ≠ b``, both ≥ 1) and the
        number of cells of ``a`` with a neighbour in ``b``. Every touching pair appears in both
        directions.
    """
    rows, cols = ids.shape
    flat_keys = []
    for dr, dc in _OFFSETS8 if connectivity == 8 else _OFFSETS4:
        ri = slice(max(0, -dr), rows - max(0, dr))
        ci = slice(max(0, -dc), cols - max(0, dc))
        rj = slice(max(0, dr), rows - max(0, -dr))
        cj = slice(max(0, dc), cols - max(0, -dc))
        a, b = ids[ri, ci], ids[rj, cj]
        m = (a > 0) & (b > 0) & (a != b)
        rr, cc = np.nonzero(m)
        if rr.size:
            cell = (rr.astype(np.int64) + ri.start) * cols + (cc + ci.start)
            flat_keys.append(cell * (n + 1) + b[rr, cc])
    if not flat_keys:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    cell_nbr = np.unique(np.concatenate(flat_keys))  # each (cell, neighbour region) once
    cell, nbr = np.divmod(cell_nbr, n + 1)
    own = ids.ravel()[cell].astype(np.int64)
    pair, cnt = np.unique(own * (n + 1) + nbr, return_counts=True)
    a, b = np.divmod(pair, n + 1)
    return a, b, cnt.astype(np.int64)


def extract_regions(labels: np.ndarray, grid: OccupancyGrid, *, connectivity: int = 8) -> RegionGraph:
    """Regions, their properties and the region graph of a label image on ``grid``.

    Args:
        labels: ``(rows, cols)`` integer label codes, 0 = no label; same shape as the grid.
        grid: gives the resolution and the cell → world transform.
        connectivity: 8 (the book) or 4.
    """
    lab = _check_labels(labels)
    if lab.shape != grid.shape:
        raise ValueError(f"labels {lab.shape} and grid {grid.shape} differ in shape")
    ids, region_labels = label_regions(lab, connectivity)
    n = len(region_labels) - 1
    res = float(grid.resolution)
    if n == 0:
        return RegionGraph(_frozen(ids), (), (), res, connectivity)
    rr, cc = np.nonzero(ids)
    w = ids[rr, cc]
    cnt = np.bincount(w, minlength=n + 1).astype(np.float64)[1:]
    rf, cf = rr.astype(np.float64), cc.astype(np.float64)
    mr = np.bincount(w, rf, n + 1)[1:] / cnt
    mc = np.bincount(w, cf, n + 1)[1:] / cnt
    # central moments relative to each region's mean (per-cell offsets avoid cancellation)
    dr_, dc_ = rf - mr[w - 1], cf - mc[w - 1]
    cov = np.empty((n, 2, 2))
    cov[:, 0, 0] = np.bincount(w, dr_ * dr_, n + 1)[1:] / cnt + 1.0 / 12.0
    cov[:, 1, 1] = np.bincount(w, dc_ * dc_, n + 1)[1:] / cnt + 1.0 / 12.0
    cov[:, 0, 1] = cov[:, 1, 0] = np.bincount(w, dr_ * dc_, n + 1)[1:] / cnt
    centroid_cells = np.stack([mr, mc], axis=1)
    centroid_world = grid.cell_to_world(centroid_cells)
    J = _cell_jacobian(grid)  # world vector = J @ (drow, dcol)
    major_c, minor_c = _principal_axes(cov)  # in cells, (drow, dcol)
    major_w = major_c @ J.T
    minor_w = minor_c @ J.T
    # orient the world vectors: major towards +x (or +y), minor 90° counter-clockwise of it
    flip = (major_w[:, 0] < -1e-12) | ((np.abs(major_w[:, 0]) <= 1e-12) & (major_w[:, 1] < 0))
    major_w[flip] *= -1
    major_c[flip] *= -1
    ccw = np.stack([-major_w[:, 1], major_w[:, 0]], axis=1)
    ccw_len = np.linalg.norm(ccw, axis=1, keepdims=True)
    minor_len = np.linalg.norm(minor_w, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        minor_w = np.where(ccw_len > 0, ccw / ccw_len * minor_len, minor_w)
    minor_c = minor_w @ np.linalg.inv(J).T
    slices = ndimage.find_objects(ids, max_label=n)
    regions = []
    for i in range(n):
        sl = slices[i]
        assert sl is not None
        regions.append(
            Region(
                id=i + 1,
                label=int(region_labels[i + 1]),
                cells=int(cnt[i]),
                area_m2=float(cnt[i] * res * res),
                centroid_cell=(float(mr[i]), float(mc[i])),
                centroid=(float(centroid_world[i, 0]), float(centroid_world[i, 1])),
                major_axis=(float(major_w[i, 0]), float(major_w[i, 1])),
                minor_axis=(float(minor_w[i, 0]), float(minor_w[i, 1])),
                major_axis_cells=(float(major_c[i, 0]), float(major_c[i, 1])),
                minor_axis_cells=(float(minor_c[i, 0]), float(minor_c[i, 1])),
                bbox=(sl[0].start, sl[1].start, sl[0].stop, sl[1].stop),
            )
        )
    edges = _edges(ids, n, res, connectivity)
    return RegionGraph(_frozen(ids), tuple(regions), edges, res, connectivity)


def _edges(ids: np.ndarray, n: int, res: float, connectivity: int) -> tuple[Edge, ...]:
    a, b, cells = adjacency(ids, n, connectivity)
    directed = {(int(x), int(y)): int(c) for x, y, c in zip(a, b, cells, strict=True)}
    out = []
    for (x, y), c in sorted(directed.items()):
        if x < y:
            half = 0.5 * (c + directed.get((y, x), 0))
            out.append(Edge(x, y, half * res, half))
    return tuple(out)


def _principal_axes(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Semi-axes ``2·sqrt(eigenvalue)`` along the eigenvectors of ``(n, 2, 2)`` covariances."""
    vals, vecs = np.linalg.eigh(cov)  # ascending
    vals = np.clip(vals, 0.0, None)
    major = vecs[:, :, 1] * (2.0 * np.sqrt(vals[:, 1]))[:, None]
    minor = vecs[:, :, 0] * (2.0 * np.sqrt(vals[:, 0]))[:, None]
    return major, minor


def _cell_jacobian(grid: OccupancyGrid) -> np.ndarray:
    """``(2, 2)`` matrix taking a ``(drow, dcol)`` cell vector to a world ``(dx, dy)`` in metres."""
    w = grid.cell_to_world(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]))
    return np.stack([w[1] - w[0], w[2] - w[0]], axis=1)


def _structure(connectivity: int) -> np.ndarray:
    if connectivity == 8:
        return np.ones((3, 3), dtype=bool)
    if connectivity == 4:
        return ndimage.generate_binary_structure(2, 1)
    raise ValueError(f"connectivity must be 8 or 4, got {connectivity}")


def _check_labels(labels: np.ndarray) -> np.ndarray:
    lab = np.asarray(labels)
    if lab.ndim != 2:
        raise ValueError(f"labels must be a 2-D array of label codes, got shape {lab.shape}")
    if not np.issubdtype(lab.dtype, np.integer):
        raise ValueError(f"labels must be integer codes, got dtype {lab.dtype}")
    if lab.size and lab.min() < 0:
        raise ValueError("label codes must be non-negative (0 = no label)")
    return lab


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


# ---------------------------------------------------------------------- correction
@dataclass(frozen=True)
class CorrectionThresholds:
    """Thresholds of the heuristic region correction (book Sect. 4.7; defaults are the book's).

    Attributes:
        place_min_area_m2: rooms, corridors, hallways (every label not in ``doorway_codes``)
            of at most this area are errors.
        doorway_min_area_m2: doorways of at most this area are errors.
        doorway_min_neighbours: doorways with fewer neighbour regions are errors (2: a doorway
            must join two places).
        doorway_codes: the label codes treated as doorways.
    """

    place_min_area_m2: float = 1.0
    doorway_min_area_m2: float = 0.1
    doorway_min_neighbours: int = 2
    doorway_codes: tuple[int, ...] = (DOORWAY,)

    def __post_init__(self) -> None:
        for name in ("place_min_area_m2", "doorway_min_area_m2"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a non-negative area in m², got {v}")
        if self.doorway_min_neighbours < 0:
            raise ValueError(f"doorway_min_neighbours must be >= 0, got {self.doorway_min_neighbours}")
        object.__setattr__(self, "doorway_codes", tuple(int(c) for c in self.doorway_codes))

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly form."""
        d = asdict(self)
        d["doorway_codes"] = list(self.doorway_codes)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CorrectionThresholds:
        """Inverse of :meth:`to_dict`; unknown keys are an error that names them."""
        known = {"place_min_area_m2", "doorway_min_area_m2", "doorway_min_neighbours", "doorway_codes"}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown correction threshold keys {unknown}; known: {sorted(known)}")
        kw: dict[str, Any] = dict(d)
        if "doorway_codes" in kw:
            kw["doorway_codes"] = tuple(int(c) for c in kw["doorway_codes"])
        return cls(**kw)


@dataclass(frozen=True)
class Merge:
    """One corrected region: it took ``label_to`` from its neighbour with the longest border."""

    round: int
    label_from: int
    label_to: int
    reason: str  # "small place", "small doorway" or "doorway with N neighbours"
    cells: int
    area_m2: float
    centroid_cell: tuple[float, float]


def correct_regions(
    labels: np.ndarray,
    resolution: float,
    thresholds: CorrectionThresholds | None = None,
    *,
    connectivity: int = 8,
    max_rounds: int = 10_000,
) -> tuple[np.ndarray, list[Merge]]:
    """Apply the heuristic region correction (see the module docstring) until nothing changes.

    Args:
        labels: ``(rows, cols)`` integer label codes, 0 = no label (never changed).
        resolution: cell side in metres.
        thresholds: defaults to the book's values.

    Returns:
        ``(corrected, merges)``: the corrected label image (same dtype) and what was merged.
    """
    th = thresholds or CorrectionThresholds()
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"resolution must be a positive number of metres, got {resolution}")
    lab = _check_labels(labels).copy()
    cell_area = resolution * resolution
    door_codes = np.asarray(th.doorway_codes, dtype=np.int64)
    merges: list[Merge] = []
    for rnd in range(1, max_rounds + 1):
        ids, region_labels = label_regions(lab, connectivity)
        n = len(region_labels) - 1
        if n == 0:
            break
        cells = np.bincount(ids.ravel(), minlength=n + 1)
        area = cells * cell_area
        a, b, bcells = adjacency(ids, n, connectivity)
        # symmetric border length per undirected pair; degree per region
        border: dict[tuple[int, int], float] = {}
        for x, y, c in zip(a.tolist(), b.tolist(), bcells.tolist(), strict=True):
            key = (x, y) if x < y else (y, x)
            border[key] = border.get(key, 0.0) + 0.5 * c
        degree = np.bincount(a, minlength=n + 1)
        is_door = np.isin(region_labels, door_codes)
        small_place = ~is_door & (area <= th.place_min_area_m2)
        small_door = is_door & (area <= th.doorway_min_area_m2)
        lonely_door = is_door & (degree < th.doorway_min_neighbours)
        marked = (small_place | small_door | lonely_door) & (degree > 0)
        marked[0] = False
        if not marked.any():
            break
        target = np.zeros(n + 1, dtype=np.int64)
        best: dict[int, tuple[float, int, int]] = {}
        for (x, y), length in border.items():
            for me, other in ((x, y), (y, x)):
                if marked[me]:
                    cand = (length, int(cells[other]), -other)
                    if me not in best or cand > best[me]:
                        best[me] = cand
        for me, (_, _, neg_other) in best.items():
            target[me] = -neg_other
        chosen = [int(i) for i in np.flatnonzero(marked) if not marked[target[i]]]
        if not chosen:
            chosen = [int(min(np.flatnonzero(marked), key=lambda i: (cells[i], i)))]
        new_label = region_labels.copy()
        centroids = _centroids(ids, n)[chosen]
        for i, cen in zip(chosen, centroids, strict=True):
            new_label[i] = region_labels[target[i]]
            if small_door[i]:
                reason = "small doorway"
            elif lonely_door[i]:
                reason = f"doorway with {int(degree[i])} neighbour{'s' if degree[i] != 1 else ''}"
            else:
                reason = "small place"
            merges.append(
                Merge(
                    round=rnd,
                    label_from=int(region_labels[i]),
                    label_to=int(region_labels[target[i]]),
                    reason=reason,
                    cells=int(cells[i]),
                    area_m2=float(area[i]),
                    centroid_cell=(float(cen[0]), float(cen[1])),
                )
            )
        lab = np.where(ids > 0, new_label[ids], lab).astype(lab.dtype)
    return lab, merges


def _centroids(ids: np.ndarray, n: int) -> np.ndarray:
    """``(n + 1, 2)`` mean ``(row, col)`` of every region id (row 0 unused)."""
    rr, cc = np.nonzero(ids)
    w = ids[rr, cc]
    cnt = np.maximum(np.bincount(w, minlength=n + 1), 1)
    return np.stack([np.bincount(w, rr, n + 1) / cnt, np.bincount(w, cc, n + 1) / cnt], axis=1)


def thresholds_from_training(
    label_images: Iterable[np.ndarray],
    resolution: float | Sequence[float],
    *,
    quantile: float = 0.001,
    scale: float = 0.5,
    doorway_codes: tuple[int, ...] = (DOORWAY,),
    doorway_min_neighbours: int = 2,
    connectivity: int = 8,
) -> CorrectionThresholds:
    """Correction thresholds from the true regions of labelled training maps.

    For each group (places: every label but doorway; doorways) the true regions are sorted by
    area and the *area-weighted* ``quantile`` is taken: the size of the region at which the
    smaller regions add up to ``quantile`` of the group's labelled area. The threshold is
    ``scale`` times that. Weighting by area ignores the hundreds of one-cell speckles that hand
    labelling leaves behind (they hold almost no area), so the quantile lands on the smallest
    *real* region; half of it stays safely below every real region. On the IPA labelled maps
    (0.05 m) this gives 1.22 m² for places and 0.11 m² for doorways, the book's 1 m² and 0.1 m².

    ``resolution`` is the cell side in metres of every image, or one value per image.
    """
    if not 0.0 <= quantile < 1.0:
        raise ValueError(f"quantile must lie in [0, 1), got {quantile}")
    if not scale > 0:
        raise ValueError(f"scale must be positive, got {scale}")
    images = list(label_images)
    if isinstance(resolution, (int, float, np.floating, np.integer)):
        resolutions = [float(resolution)] * len(images)
    else:
        resolutions = [float(r) for r in resolution]
        if len(resolutions) != len(images):
            raise ValueError(f"{len(resolutions)} resolutions for {len(images)} label images")
    for res in resolutions:
        if not (math.isfinite(res) and res > 0):
            raise ValueError(f"resolution must be a positive number of metres, got {res}")
    doors = np.asarray(doorway_codes, dtype=np.int64)
    place_areas: list[np.ndarray] = []
    door_areas: list[np.ndarray] = []
    n_images = 0
    for labels, res in zip(images, resolutions, strict=True):
        n_images += 1
        ids, region_labels = label_regions(labels, connectivity)
        areas = np.bincount(ids.ravel(), minlength=len(region_labels))[1:] * res**2
        is_door = np.isin(region_labels[1:], doors)
        place_areas.append(areas[~is_door])
        door_areas.append(areas[is_door])
    if n_images == 0:
        raise ValueError("no training label images given")
    default = CorrectionThresholds()

    def pick(areas: list[np.ndarray], fallback: float) -> float:
        a = np.sort(np.concatenate(areas)) if areas else np.zeros(0)
        if a.size == 0:
            return fallback
        cum = np.cumsum(a) / a.sum()
        return round(float(scale * a[min(int(np.searchsorted(cum, quantile, side="right")), a.size - 1)]), 6)

    return CorrectionThresholds(
        place_min_area_m2=pick(place_areas, default.place_min_area_m2),
        doorway_min_area_m2=pick(door_areas, default.doorway_min_area_m2),
        doorway_min_neighbours=doorway_min_neighbours,
        doorway_codes=tuple(int(c) for c in doorway_codes),
    )
