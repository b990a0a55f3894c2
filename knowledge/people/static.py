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
        interval: seconds; scans closer than this to the last one remembered are skipped.
    """

    cell: float = 0.1
    settle: float = 3.0
    forget: float = 2.0
    reach: float = 0.1
    interval: float = 0.1

    def __post_init__(self) -> None:
        for name in ("cell", "settle", "forget"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"StaticParams.{name} must be a positive number, got {v!r}")
        for name in ("reach", "interval"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"StaticParams.{name} must be >= 0, got {v!r}")


class StaticCells:
    """The first and last hit time of each cell (see the module docstring); bounded by
    ``forget``: cells not hit for that long are dropped (swept every ``forget`` seconds)."""

    def __init__(self, params: StaticParams | None = None) -> None:
        self.params = params or StaticParams()
        self._cells: dict[tuple[int, int], list[float]] = {}  # cell -> [first hit, last hit]
        self._time = -math.inf
        self._swept = -math.inf

    def __len__(self) -> int:
        return len(self._cells)

    def update(self, points: np.ndarray, stamp: float) -> None:
        """The scan at ``stamp`` hit ``points`` (``(k, 2)`` metres, tracking frame). Scans
        closer than ``interval`` seconds to the last one taken change nothing (a 75 Hz laser
        need not be remembered at 75 Hz to know what stood still for seconds)."""
        prm = self.params
        t = float(stamp)
        if t - self._time < prm.interval:
            return
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        ij = np.floor(pts[np.isfinite(pts).all(axis=1)] / prm.cell).astype(np.int64)
        cells = self._cells
        stale = t - prm.forget
        for key in set(zip(ij[:, 0].tolist(), ij[:, 1].tolist(), strict=True)):
            rec = cells.get(key)
            if rec is None or rec[1] < stale:
                cells[key] = [t, t]
            else:
                rec[1] = t
        if t - self._swept >= prm.forget:
            self._cells = {k: v for k, v in cells.items() if v[1] >= stale}
            self._swept = t
        self._time = t

    def static(self, points: np.ndarray) -> np.ndarray:
        """``(k,)`` bool: a cell within ``reach`` of each point has been hit, without a break
        longer than ``forget``, for ``settle`` seconds up to the last update."""
        prm = self.params
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(pts.shape[0], dtype=bool)
        r = math.ceil(prm.reach / prm.cell)
        stale, settled = self._time - prm.forget, self._time - prm.settle
        for k, (i, j) in enumerate(np.floor(pts / prm.cell).astype(np.int64).tolist()):
            for di in range(-r, r + 1):
                for dj in range(-r, r + 1):
                    rec = self._cells.get((i + di, j + dj))
                    if rec is not None and rec[1] >= stale and rec[0] <= settled:
                        out[k] = True
                        break
                if out[k]:
                    break
        return out
