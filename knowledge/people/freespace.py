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

import math
from collections import deque
from dataclasses import dataclass

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
        self._scans: deque[_Scan] = deque()

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
        """Remember a scan (after :meth:`evidence` was asked about its points)."""
        orig = np.asarray(ranges, dtype=np.float64)
        r = orig.copy()
        with np.errstate(invalid="ignore"):
            no_return = np.isposinf(orig) | (orig >= range_max)
            invalid = np.isnan(orig) | np.isneginf(orig) | (orig <= 0) | (orig < range_min)
        r[no_return] = np.inf
        r[invalid] = np.nan
        self._scans.append(_Scan(float(stamp), pose, r, float(angle_min), float(angle_increment)))
        while self._scans and self._scans[0].stamp < stamp - self.params.horizon:
            self._scans.popleft()

    def _window(
        self, s: _Scan, q: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """For points ``q`` ``(K, 2)`` seen from scan ``s``: their distances ``(K,)`` and the
        ranges of the beams within ``half_width`` of each ``(K, M)`` (NaN where a beam of the
        window is outside the scan or invalid; ``+inf`` where there is no window to look at)."""
        prm = self.params
        x, y, th = s.pose
        dx, dy = q[:, 0] - x, q[:, 1] - y
        d = np.hypot(dx, dy)
        b = np.arctan2(dy, dx) - th
        b = np.arctan2(np.sin(b), np.cos(b))
        centre = np.rint((b - s.angle_min) / s.angle_increment).astype(np.int64)
        w = np.ceil(prm.half_width / (np.maximum(d, 0.05) * s.angle_increment)).astype(np.int64)
        W = int(w.max())
        off = np.arange(-W, W + 1)
        idx = centre[:, None] + off[None, :]
        n = s.ranges.size
        r = s.ranges[np.clip(idx, 0, n - 1)].copy()
        r[(idx < 0) | (idx >= n)] = np.nan
        r[np.abs(off)[None, :] > w[:, None]] = np.inf  # outside the window: no constraint
        return d, r

    def evidence(self, points: npt.ArrayLike, stamp: float) -> npt.NDArray[np.int64]:
        """``(K,)`` for each point, how many remembered scans ``min_lag``–``horizon`` s before
        ``stamp`` saw through it."""
        prm = self.params
        q = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(q.shape[0], dtype=np.int64)
        if not q.shape[0]:
            return out
        old = [s for s in self._scans if prm.min_lag <= stamp - s.stamp <= prm.horizon]
        if len(old) > prm.max_scans:
            pick = np.linspace(0, len(old) - 1, prm.max_scans).round().astype(int)
            old = [old[i] for i in pick]
        for s in old:
            d, r = self._window(s, q)
            with np.errstate(invalid="ignore"):
                out += (r > (d + prm.margin)[:, None]).all(axis=1)
        return out
