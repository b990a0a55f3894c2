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


def _keys(ij: np.ndarray) -> np.ndarray:
    return (ij[:, 0].astype(np.int64) << 32) | (ij[:, 1].astype(np.int64) & 0xFFFFFFFF)


class StaticCells:
    """The first and last hit time of each cell (see the module docstring); bounded by
    ``forget``: cells not hit for that long are dropped."""

    def __init__(self, params: StaticParams | None = None) -> None:
        self.params = params or StaticParams()
        self._keys = np.zeros(0, dtype=np.int64)  # sorted
        self._first = np.zeros(0, dtype=np.float64)
        self._last = np.zeros(0, dtype=np.float64)
        self._time = -math.inf

    def __len__(self) -> int:
        return int(self._keys.size)

    def update(self, points: np.ndarray, stamp: float) -> None:
        """The scan at ``stamp`` hit ``points`` (``(k, 2)`` metres, tracking frame)."""
        prm = self.params
        t = float(stamp)
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        pts = pts[np.isfinite(pts).all(axis=1)]
        keys = np.unique(_keys(np.floor(pts / prm.cell)))
        alive = self._last >= t - prm.forget
        k, first, last = self._keys[alive], self._first[alive], self._last[alive]
        i = np.searchsorted(k, keys).clip(0, max(k.size - 1, 0))
        known = (k.size > 0) & (k[i] == keys) if k.size else np.zeros(keys.size, dtype=bool)
        last = last.copy()
        last[i[known]] = t
        new = keys[~known]
        if new.size:
            k = np.concatenate((k, new))
            first = np.concatenate((first, np.full(new.size, t)))
            last = np.concatenate((last, np.full(new.size, t)))
            order = np.argsort(k, kind="stable")
            k, first, last = k[order], first[order], last[order]
        self._keys, self._first, self._last = k, first, last
        self._time = t

    def static(self, points: np.ndarray) -> np.ndarray:
        """``(k,)`` bool: a cell within ``reach`` of each point has been hit, without a break
        longer than ``forget``, for ``settle`` seconds up to the last update."""
        prm = self.params
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(pts.shape[0], dtype=bool)
        if not self._keys.size or not pts.shape[0]:
            return out
        settled = (self._time - self._first >= prm.settle) & (self._last >= self._time - prm.forget)
        r = math.ceil(prm.reach / prm.cell)
        base = np.floor(pts / prm.cell).astype(np.int64)
        for di in range(-r, r + 1):
            for dj in range(-r, r + 1):
                keys = _keys(base + np.array([di, dj], dtype=np.int64))
                i = np.searchsorted(self._keys, keys).clip(0, self._keys.size - 1)
                out |= (self._keys[i] == keys) & settled[i]
        return out
