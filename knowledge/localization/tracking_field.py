"""The likelihood field of a map built as it goes, kept up to date tile by tile.

A pose tracker that builds its map as it goes (:class:`~knowledge.localization.tracking.PoseTracker`)
matches each scan against the likelihood field of that map: the distance from each cell to
the nearest occupied one, clipped at ``max_distance``, and the scan matcher's score
``exp(−d²/2σ²)`` for each of its ``σ``. Remaking them for a 44 m window around the robot
(880 × 880 cells at 5 cm: a copy of the counts, a distance transform and three score
arrays) took 26–29 ms of CPU at the median on the CSAIL log, every 5.8 scans, sweeping
~20 MB through the caches each time (docs/localization.md has the measurements). :class:`TrackingField` keeps them for the whole map instead and redoes only what a
change can reach: a cell that turns occupied (or stops being occupied) changes the clipped
distances within ``max_distance`` of it and nowhere else. So the field is cut into tiles of
``tile`` × ``tile`` cells; the mapper lists the cells each scan changed
(:meth:`~knowledge.metric.mapping.ScanMapper.take_changes`), those within ``max_distance``
of a tile mark it dirty, and :meth:`TrackingField.update` redoes the distance transform of
each run of dirty tiles (with a border of ``max_distance``, so that every obstacle a tile's
cell can see is in it) and their scores. The result is the field made from scratch, cell for
cell (``tests/unit/test_localization_tracking_field.py``), at the cost of the tiles a scan
reaches (about 19 tiles of 64 × 64 cells per update on CSAIL, 4 ms).

Layout: as :class:`~knowledge.localization.likelihood.LikelihoodField` (map orientation, row
``= y`` index). The arrays cover lattice rows ``[row0, row0 + rows)`` and columns
``[col0, col0 + cols)`` of the mapper (:attr:`~knowledge.metric.mapping.ScanMapper.lattice_origin`),
tile-aligned, and grow by ``grow`` metres when a change falls near their edge: they are
views of larger zeroed memory (``reserve`` metres of room each side), so growing fills in
only the new cells, and only a field that outgrows its room is copied.
"""

from __future__ import annotations

import math

import cv2
import numba
import numpy as np

from knowledge.localization.likelihood import LikelihoodField
from knowledge.localization.scan_matching import MatchField

__all__ = ["TrackingField", "exact_distance_field"]


@numba.njit(cache=True, nogil=True)
def _finish(
    raw: np.ndarray,
    res: float,
    max_distance: float,
    reach: int,
    ks: np.ndarray,
    dist: np.ndarray,
    scores: np.ndarray,
) -> None:
    """From OpenCV's distances ``raw`` (cells) to ``dist`` (metres, exact, clipped) and
    ``scores[s] = exp(ks[s]·dist²)``, all float32.

    OpenCV's precise transform is exact up to float rounding, and that rounding depends on
    the rest of the image (370 came out as 369.99994 in one window, not in another): the
    squared distance, a whole number of cells², is rounded back to it, so that a cell's
    distance depends only on the obstacles within ``reach`` of it."""
    res32 = np.float32(res)
    far = np.float32(max_distance)
    for i in range(raw.shape[0]):
        for j in range(raw.shape[1]):
            v = raw[i, j]
            if v > reach:
                d = far
            else:
                k2 = round(float(v) * float(v))
                d = min(np.float32(math.sqrt(k2)) * res32, far)
            dist[i, j] = d
            for s in range(ks.shape[0]):
                scores[s, i, j] = math.exp(ks[s] * d * d)


def _raw_distances(occupied: np.ndarray) -> np.ndarray:
    src = np.where(occupied, np.uint8(0), np.uint8(255))
    return cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def exact_distance_field(occupied: np.ndarray, resolution: float, max_distance: float) -> np.ndarray:
    """``(rows, cols)`` float32 metres from each cell's centre to the nearest occupied cell's,
    clipped at ``max_distance``: ``float32(√k)·float32(resolution)`` for ``k`` the exact
    squared distance in cells (what :class:`TrackingField` holds; OpenCV's own result,
    :func:`~knowledge.localization.likelihood.distance_field`, can be one float step off and
    differently so in another window)."""
    occ = np.asarray(occupied, dtype=bool)
    reach = math.ceil(max_distance / resolution) + 1
    dist = np.empty(occ.shape, dtype=np.float32)
    scores = np.empty((0, *occ.shape), dtype=np.float32)
    raw = _raw_distances(occ) if occ.any() else np.full(occ.shape, np.inf, dtype=np.float32)
    _finish(raw, float(resolution), float(max_distance), reach, np.zeros(0), dist, scores)
    return dist


@numba.njit(cache=True, nogil=True)
def _apply(
    occupied: np.ndarray,
    free: np.ndarray,
    dirty: np.ndarray,
    changes: np.ndarray,
    row0: int,
    col0: int,
    tile: int,
    reach: int,
) -> None:
    """Set each changed cell's state, in order; a cell whose occupancy flips marks dirty every
    tile within ``reach`` cells of it."""
    ty_n, tx_n = dirty.shape
    for k in range(changes.shape[0]):
        r = changes[k, 0] - row0
        c = changes[k, 1] - col0
        state = changes[k, 2]
        occ = state == 2
        if occ != occupied[r, c]:
            for ty in range(max((r - reach) // tile, 0), min((r + reach) // tile, ty_n - 1) + 1):
                for tx in range(max((c - reach) // tile, 0), min((c + reach) // tile, tx_n - 1) + 1):
                    dirty[ty, tx] = True
        occupied[r, c] = occ
        free[r, c] = state == 1


def _fill_around(arr: np.ndarray, a: int, b: int, rows: int, cols: int, fill: np.ndarray | float) -> None:
    """Set every cell of ``arr`` (in its last two axes) outside rows ``a..a+rows`` and
    columns ``b..b+cols`` to ``fill``."""
    arr[..., :a, :] = fill
    arr[..., a + rows :, :] = fill
    arr[..., a : a + rows, :b] = fill
    arr[..., a : a + rows, b + cols :] = fill


def _placed(
    old: np.ndarray, shape: tuple[int, int], a: int, b: int, fill: np.ndarray | float | bool
) -> np.ndarray:
    """A new array of ``shape`` (in its last two axes) holding ``old`` at row ``a``, column
    ``b`` and ``fill`` around it."""
    rows, cols = old.shape[-2:]
    new = np.empty((*old.shape[:-2], *shape), dtype=old.dtype)
    _fill_around(new, a, b, rows, cols, fill)
    new[..., a : a + rows, b : b + cols] = old
    return new


class TrackingField:
    """A likelihood field of a growing map and its score arrays, updated where the map changed.

    Args:
        lattice_origin: world ``(x, y)`` of lattice cell ``(0, 0)``'s lower-left corner.
        resolution: metres per cell.
        max_distance: metres, where distances are clipped.
        sigmas: metres, the matcher's ``σ`` (one score array each).
        tile: cells per tile side.
        grow: metres the field grows by beyond a change that falls outside it.
        reserve: metres of room kept around the field in its memory, each side (at least
            half the field's size: the memory doubles): the field grows into it by filling in
            only the new cells, and memory that was never filled in is never touched (the
            arrays are zeroed by the system as their pages are first used). Only a field
            that outgrows its room is copied into a larger one.
    """

    def __init__(
        self,
        lattice_origin: tuple[float, float],
        resolution: float,
        max_distance: float,
        sigmas: tuple[float, ...],
        *,
        tile: int = 64,
        grow: float = 8.0,
        reserve: float = 40.0,
    ) -> None:
        if not (
            math.isfinite(resolution) and resolution > 0 and math.isfinite(max_distance) and max_distance > 0
        ):
            raise ValueError(
                f"resolution and max_distance must be positive metres, got {resolution}, {max_distance}"
            )
        if tile < 1 or not grow >= 0 or not reserve >= 0:
            raise ValueError(
                f"tile must be >= 1 cell, grow and reserve >= 0 m, got {tile}, {grow}, {reserve}"
            )
        self.lattice_origin = (float(lattice_origin[0]), float(lattice_origin[1]))
        self.resolution = float(resolution)
        self.max_distance = float(max_distance)
        self.sigmas = tuple(float(s) for s in sigmas)
        self.tile = int(tile)
        # the cells a change reaches: the clipped distance of a cell further away stays the same
        self.reach = math.ceil(self.max_distance / self.resolution) + 1
        self._grow = math.ceil(grow / self.resolution)
        self._reserve = math.ceil(reserve / self.resolution / self.tile) * self.tile
        self._k = np.array([-0.5 / (s * s) for s in self.sigmas])
        # the distance and scores of a cell with no obstacle within reach
        self._far = np.empty((1, 1), dtype=np.float32)
        self._far_scores = np.empty((len(self.sigmas), 1, 1), dtype=np.float32)
        _finish(
            np.full((1, 1), np.inf, np.float32),
            self.resolution,
            self.max_distance,
            self.reach,
            self._k,
            self._far,
            self._far_scores,
        )
        # the memory the field lives in: lattice rows/cols from (_brow0, _bcol0)
        self._brow0 = self._bcol0 = 0
        self._bufs: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        #: how many times the field outgrew its memory and was copied
        self.reallocations = 0
        self.row0 = self.col0 = 0
        self.occupied = np.zeros((0, 0), dtype=bool)
        self.free = np.zeros((0, 0), dtype=bool)
        self.distance = np.zeros((0, 0), dtype=np.float32)
        #: ``(len(sigmas), rows, cols)`` float32 ``exp(−d²/2σ²)``
        self.scores = np.zeros((len(self.sigmas), 0, 0), dtype=np.float32)
        self._dirty = np.zeros((0, 0), dtype=bool)
        self._mf: MatchField | None = None
        #: tiles redone by the last :meth:`update`
        self.tiles_updated = 0

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.distance.shape[0]), int(self.distance.shape[1]))

    def _cover(self, rmin: int, rmax: int, cmin: int, cmax: int) -> None:
        """Grow the arrays (tile-aligned) so that they hold lattice rows ``rmin..rmax`` and
        columns ``cmin..cmax`` (inclusive)."""
        rows, cols = self.shape
        if (
            rows
            and self.row0 <= rmin
            and rmax < self.row0 + rows
            and self.col0 <= cmin
            and cmax < self.col0 + cols
        ):
            return
        t, g = self.tile, self._grow
        if rows:
            rmin, rmax = min(rmin - g, self.row0), max(rmax + g, self.row0 + rows - 1)
            cmin, cmax = min(cmin - g, self.col0), max(cmax + g, self.col0 + cols - 1)
        else:
            rmin, rmax, cmin, cmax = rmin - g, rmax + g, cmin - g, cmax + g
        r0, c0 = (rmin // t) * t, (cmin // t) * t
        nr, nc = (rmax // t + 1) * t - r0, (cmax // t + 1) * t - c0
        a, b = (self.row0 - r0, self.col0 - c0) if rows else (0, 0)
        bufs = self._bufs
        br, bc = r0 - self._brow0, c0 - self._bcol0
        if bufs is None or br < 0 or bc < 0 or br + nr > bufs[0].shape[0] or bc + nc > bufs[0].shape[1]:
            # room around the field, at least half its size each side; np.zeros leaves the
            # pages to the system, which zeroes them when first touched
            pr, pc = max(self._reserve, nr // (2 * t) * t), max(self._reserve, nc // (2 * t) * t)
            shape = (nr + 2 * pr, nc + 2 * pc)
            new = (
                np.zeros(shape, dtype=bool),
                np.zeros(shape, dtype=bool),
                np.zeros(shape, dtype=np.float32),
                np.zeros((len(self.sigmas), *shape), dtype=np.float32),
            )
            if rows:
                for buf, old in zip(new, (self.occupied, self.free, self.distance, self.scores), strict=True):
                    buf[..., pr + a : pr + a + rows, pc + b : pc + b + cols] = old
                self.reallocations += 1
            bufs, self._bufs = new, new
            self._brow0, self._bcol0 = r0 - pr, c0 - pc
            br, bc = pr, pc
        occ, free, dist, scores = (buf[..., br : br + nr, bc : bc + nc] for buf in bufs)
        # the new cells, never touched: unknown (zero already), far from everything
        _fill_around(dist, a, b, rows, cols, self._far[0, 0])
        _fill_around(scores, a, b, rows, cols, self._far_scores)
        dirty = _placed(self._dirty, (nr // t, nc // t), a // t, b // t, False)
        self.row0, self.col0 = r0, c0
        self.occupied, self.free, self.distance, self.scores, self._dirty = occ, free, dist, scores, dirty
        self._mf = None

    def update(self, changes: np.ndarray) -> int:
        """Take the map's changes (``(K, 3)`` lattice row, column, state, as
        :meth:`~knowledge.metric.mapping.ScanMapper.take_changes` lists them) and redo the
        distances and scores of the tiles they reach; returns how many tiles were redone."""
        ch = np.asarray(changes, dtype=np.int64).reshape(-1, 3)
        if ch.shape[0]:
            m = self.reach
            self._cover(
                int(ch[:, 0].min()) - m,
                int(ch[:, 0].max()) + m,
                int(ch[:, 1].min()) - m,
                int(ch[:, 1].max()) + m,
            )
            _apply(self.occupied, self.free, self._dirty, ch, self.row0, self.col0, self.tile, m)
        done = 0
        t, m = self.tile, self.reach
        rows, cols = self.shape
        for ty in np.flatnonzero(self._dirty.any(axis=1)).tolist():
            line = self._dirty[ty]
            # each run of dirty tiles in this row of tiles: one distance transform
            edges = np.flatnonzero(np.diff(np.concatenate(([0], line.view(np.int8), [0])))).tolist()
            for tx0, tx1 in zip(edges[::2], edges[1::2], strict=True):
                r0, r1, c0, c1 = ty * t, (ty + 1) * t, tx0 * t, tx1 * t
                a0, a1, b0, b1 = max(r0 - m, 0), min(r1 + m, rows), max(c0 - m, 0), min(c1 + m, cols)
                occ = self.occupied[a0:a1, b0:b1]
                if occ.any():
                    raw = _raw_distances(occ)[r0 - a0 : r1 - a0, c0 - b0 : c1 - b0]
                    _finish(
                        raw,
                        self.resolution,
                        self.max_distance,
                        m,
                        self._k,
                        self.distance[r0:r1, c0:c1],
                        self.scores[:, r0:r1, c0:c1],
                    )
                else:
                    self.distance[r0:r1, c0:c1] = self._far[0, 0]
                    self.scores[:, r0:r1, c0:c1] = self._far_scores
                done += tx1 - tx0
            line[:] = False
        self.tiles_updated = done
        return done

    def match_field(self) -> MatchField:
        """The field and its scores for the matcher (sharing these arrays: valid until the
        next :meth:`update` that grows them; ask again after each update)."""
        if self._mf is None:
            res = self.resolution
            origin = (self.lattice_origin[0] + self.col0 * res, self.lattice_origin[1] + self.row0 * res, 0.0)
            lf = LikelihoodField(self.distance, self.free, self.occupied, res, origin, self.max_distance)
            self._mf = MatchField(lf, self.sigmas, scores=list(self.scores))
        return self._mf
