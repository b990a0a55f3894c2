"""Where the laser saw through a moment ago: evidence that a leg candidate walked in.

A person walks into space that the laser saw empty a moment before; a table leg stands
where the laser has always found an obstacle (or never looked). :class:`SeenThrough` keeps
the last scans with the laser's pose in the tracking frame (the odometry frame) and says,
for a point of the current scan, in how many of the scans ``min_lag`` to ``horizon``
seconds old *every* beam within ``half_width`` metres to either side of the point passed at
least ``margin`` metres beyond it (a beam without a return passed everything). The window
of beams and the margin keep a thin post from looking like free space when one beam slips
past it, and the odometry's error from turning a wall into free space.

Points are ``(K, 2)`` metres in the tracking frame; poses ``(x, y, θ)`` of the laser in it;
ranges ``(B,)`` metres, beam ``m`` at ``angle_min + m·angle_increment``; times seconds.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["SeenThrough", "SeenThroughParams"]


@dataclass(frozen=True)
class SeenThroughParams:
    """How the evidence is taken (see the module doc).

    Attributes:
        min_lag, horizon: seconds; the scans looked at are this old.
        margin: metres a beam must pass beyond the point.
        half_width: metres to either side of the point whose beams must all pass.
        max_scans: at most this many scans are looked at, spread over the window (a fast
            laser keeps the cost bounded).
    """

    min_lag: float = 0.25
    horizon: float = 2.0
    margin: float = 0.3
    half_width: float = 0.1
    max_scans: int = 16

    def __post_init__(self) -> None:
        for name in ("horizon", "margin", "half_width"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"SeenThroughParams.{name} must be a positive number, got {v!r}")
        if not (math.isfinite(self.min_lag) and 0 <= self.min_lag < self.horizon):
            raise ValueError(f"SeenThroughParams.min_lag must be in [0, horizon), got {self.min_lag!r}")
        if int(self.max_scans) != self.max_scans or self.max_scans < 1:
            raise ValueError(f"SeenThroughParams.max_scans must be an integer >= 1, got {self.max_scans!r}")


@dataclass(frozen=True, eq=False)
class _Scan:
    stamp: float
    pose: tuple[float, float, float]
    ranges: npt.NDArray[np.float64]  # no return -> inf, invalid -> NaN
    angle_min: float
    angle_increment: float


class SeenThrough:
    """The recent scans of one laser (see the module doc)."""

    def __init__(self, params: SeenThroughParams | None = None) -> None:
        self.params = params or SeenThroughParams()
        self._scans: list[_Scan] = []
        self._stamps: list[float] = []

    def __len__(self) -> int:
        return len(self._scans)

    def add(
        self,
        ranges: npt.ArrayLike,
        stamp: float,
        pose: tuple[float, float, float],
        *,
        angle_min: float,
        angle_increment: float,
        range_max: float,
        range_min: float = 0.0,
    ) -> None:
        """Remember a scan and forget those older than ``horizon``."""
        orig = np.asarray(ranges, dtype=np.float64)
        r = orig.copy()
        with np.errstate(invalid="ignore"):
            no_return = np.isposinf(orig) | (orig >= range_max)
            invalid = np.isnan(orig) | np.isneginf(orig) | (orig <= 0) | (orig < range_min)
        r[no_return] = np.inf
        r[invalid] = np.nan
        self._scans.append(_Scan(float(stamp), pose, r, float(angle_min), float(angle_increment)))
        self._stamps.append(float(stamp))
        cut = bisect.bisect_left(self._stamps, stamp - self.params.horizon)
        if cut:
            del self._scans[:cut], self._stamps[:cut]

    def evidence(self, points: npt.ArrayLike, stamp: float) -> npt.NDArray[np.int64]:
        """``(K,)`` for each point, how many remembered scans ``min_lag``–``horizon`` s before
        ``stamp`` saw through it."""
        prm = self.params
        q = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
        out = np.zeros(q.shape[0], dtype=np.int64)
        if not q.shape[0]:
            return out
        lo = bisect.bisect_left(self._stamps, stamp - prm.horizon)
        hi = bisect.bisect_right(self._stamps, stamp - prm.min_lag)
        old = self._scans[lo:hi]
        if len(old) > prm.max_scans:
            pick = np.linspace(0, len(old) - 1, prm.max_scans).round().astype(int)
            old = [old[i] for i in pick]
        for s in old:  # scans of one laser: the same beams, in practice one kernel call
            _count_seen_through(
                q,
                s.ranges,
                s.pose[0],
                s.pose[1],
                s.pose[2],
                s.angle_min,
                s.angle_increment,
                prm.margin,
                prm.half_width,
                out,
            )
        return out


@numba.njit(cache=True, nogil=True)
def _count_seen_through(
    q: np.ndarray,
    ranges: np.ndarray,
    x: float,
    y: float,
    th: float,
    angle_min: float,
    inc: float,
    margin: float,
    half_width: float,
    out: np.ndarray,
) -> None:
    """``out[k] += 1`` for each point ``q[k]`` that every beam of the scan within
    ``half_width`` metres of it (at its distance) passed by ``margin`` metres (no return:
    ``+inf``; invalid: NaN, which never passes; a window reaching past the scan's ends fails)."""
    n = ranges.shape[0]
    for k in range(q.shape[0]):
        dx = q[k, 0] - x
        dy = q[k, 1] - y
        d = math.hypot(dx, dy)
        b = math.atan2(dy, dx) - th
        b = math.atan2(math.sin(b), math.cos(b))
        centre = int(np.rint((b - angle_min) / inc))
        w = math.ceil(half_width / (max(d, 0.05) * inc))
        if centre - w < 0 or centre + w >= n:
            continue
        ok = True
        for i in range(centre - w, centre + w + 1):
            if not ranges[i] > d + margin:  # NaN fails too
                ok = False
                break
        if ok:
            out[k] += 1
