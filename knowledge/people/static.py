"""What has stood still: cells of the tracking frame that the laser has hit for a while.

The leg detector takes table and chair legs for legs (docs/people.md: most of its false
positives are furniture that stays put), and the tracker, following such "legs" while the
robot drives past a row of desks, can hop from one to the next and seem to walk. Time
separates the two: a person's legs stand where the laser saw free space or nothing a moment
ago, furniture where it has seen an obstacle for as long as it has looked.

:class:`StaticCells` remembers, for each ``cell`` × ``cell`` square of the tracking frame
(the odometry frame), when the laser first hit it and when it last did. A cell hit again
within ``forget`` seconds keeps its first time; one not hit for longer starts afresh (a
person who stood there and left). A point is *static* when a cell within ``reach`` of it
has been hit continuously for at least ``settle`` seconds.

Points are ``(k, 2)`` metres in the tracking frame; times are seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["StaticCells", "StaticParams"]


@dataclass(frozen=True)
class StaticParams:
    """How long counts as standing still (see the module docstring).

    Attributes:
        cell: metres, the side of a cell.
        settle: seconds a cell must have been hit for its obstacle to count as static.
        forget: seconds without a hit after which a cell starts afresh.
        reach: metres around a point whose cells are looked at.
    """

    cell: float = 0.1
    settle: float = 3.0
    forget: float = 2.0
    reach: float = 0.1

    def __post_init__(self) -> None:
        for name in ("cell", "settle", "forget"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"StaticParams.{name} must be a positive number, got {v!r}")
        if not (math.isfinite(self.reach) and self.reach >= 0):
            raise ValueError(f"StaticParams.reach must be >= 0 metres, got {self.reach!r}")


#: Side of the table of cells (cells): a cell lives at (i mod SIZE, j mod SIZE), so two cells
#: share a slot only when they are SIZE cells apart (51 m at 10 cm); the slot keeps the one
#: hit last, and a cell whose slot holds another cell counts as never hit.
SIZE = 512
_EMPTY = np.iinfo(np.int64).min


class StaticCells:
    """The first and last hit time of each cell (see the module docstring), in a fixed table:
    constant memory, no sorting; cells not hit for ``forget`` seconds are forgotten."""

    def __init__(self, params: StaticParams | None = None) -> None:
        self.params = params or StaticParams()
        self._key = np.full((SIZE, SIZE), _EMPTY, dtype=np.int64)
        self._first = np.zeros((SIZE, SIZE), dtype=np.float64)
        self._last = np.full((SIZE, SIZE), -np.inf, dtype=np.float64)
        self._time = -math.inf

    def __len__(self) -> int:
        """Cells hit within the last ``forget`` seconds."""
        return int(np.count_nonzero(self._last >= self._time - self.params.forget))

    def update(self, points: np.ndarray, stamp: float) -> None:
        """The scan at ``stamp`` hit ``points`` (``(k, 2)`` metres, tracking frame)."""
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
        t = float(stamp)
        _update(pts, t, self.params.cell, self.params.forget, self._key, self._first, self._last)
        self._time = t

    def static(self, points: np.ndarray) -> np.ndarray:
        """``(k,)`` bool: a cell within ``reach`` of each point has been hit, without a break
        longer than ``forget``, for ``settle`` seconds up to the last update."""
        prm = self.params
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
        out = np.zeros(pts.shape[0], dtype=np.bool_)
        if pts.shape[0] and self._time != -math.inf:
            r = math.ceil(prm.reach / prm.cell)
            _static(
                pts, self._time, prm.cell, prm.settle, prm.forget, r, self._key, self._first, self._last, out
            )
        return out


@numba.njit(cache=True, nogil=True)
def _key_of(i: int, j: int) -> int:
    return (i << 32) | (j & 0xFFFFFFFF)


@numba.njit(cache=True, nogil=True)
def _update(
    pts: np.ndarray,
    t: float,
    cell: float,
    forget: float,
    key: np.ndarray,
    first: np.ndarray,
    last: np.ndarray,
) -> None:
    """:meth:`StaticCells.update`: each finite point's cell is hit at ``t``; a cell not hit
    within ``forget`` (or whose slot held another cell) starts afresh."""
    for k in range(pts.shape[0]):
        x, y = pts[k, 0], pts[k, 1]
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        i, j = math.floor(x / cell), math.floor(y / cell)
        kk = _key_of(i, j)
        a, b = i % SIZE, j % SIZE
        if not (key[a, b] == kk and last[a, b] >= t - forget):
            first[a, b] = t
        last[a, b] = t
        key[a, b] = kk


@numba.njit(cache=True, nogil=True)
def _static(
    pts: np.ndarray,
    now: float,
    cell: float,
    settle: float,
    forget: float,
    r: int,
    key: np.ndarray,
    first: np.ndarray,
    last: np.ndarray,
    out: np.ndarray,
) -> None:
    """:meth:`StaticCells.static` into ``out`` (K,) bool."""
    for k in range(pts.shape[0]):
        i0, j0 = math.floor(pts[k, 0] / cell), math.floor(pts[k, 1] / cell)
        for di in range(-r, r + 1):
            for dj in range(-r, r + 1):
                i, j = i0 + di, j0 + dj
                a, b = i % SIZE, j % SIZE
                if key[a, b] == _key_of(i, j) and now - first[a, b] >= settle and last[a, b] >= now - forget:
                    out[k] = True
