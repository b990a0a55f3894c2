"""Range input cleaning and the shared intermediates of a chunk of scans.

Scans are ``(S, M)`` arrays of beam lengths in metres; beam ``i`` points at ``i·2π/M`` rad
(counter-clockwise, a full 360° turn), so the polygon Pol(z) of each scan is star-shaped
around the robot and its vertices run counter-clockwise.

Cleaning (:func:`clean_ranges`): NaN, +inf and values above ``max_range`` become
``max_range`` (a beam that hit nothing); zero, negative and −inf values become
:data:`MIN_RANGE`. The minimum keeps every ratio (A.11, A.12, A.15) and every polygon edge
finite: no ratio exceeds ``max_range / MIN_RANGE``, the area is positive and no edge has
zero length.

:class:`ScanBatch` computes an intermediate (beam differences, polygon coordinates, area,
moments, ...) the first time a feature kernel asks for it and keeps it for the other
kernels of the same chunk, so a feature set pays only for what it uses.
"""

from __future__ import annotations

import math
from functools import cache, cached_property
from typing import Any

import numpy as np

#: Smallest beam length in metres; shorter (0, negative) readings are raised to it. 1 cm is
#: below any laser scanner's minimum range, so only invalid readings are affected.
MIN_RANGE = 0.01


def check_max_range(max_range: float) -> float:
    """``max_range`` as a float; ValueError unless it is finite and above :data:`MIN_RANGE`."""
    try:
        value = float(max_range)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"max_range must be a number of metres, got {max_range!r}") from exc
    if not (math.isfinite(value) and value > MIN_RANGE):
        raise ValueError(
            f"max_range must be the sensor's finite maximum range in metres (> {MIN_RANGE}), got {max_range!r}"
        )
    return value


def clean_ranges(ranges: np.ndarray, max_range: float) -> np.ndarray:
    """A float64 copy of ``ranges`` (S, M) with invalid readings replaced (see module doc)."""
    d = np.array(ranges, dtype=np.float64)
    np.nan_to_num(d, copy=False, nan=max_range, posinf=max_range, neginf=MIN_RANGE)
    np.clip(d, MIN_RANGE, max_range, out=d)
    return d


@cache
def beam_directions(M: int) -> tuple[np.ndarray, np.ndarray]:
    """``(cos ρ_i, sin ρ_i)`` for ``ρ_i = i·2π/M``, read-only arrays of shape (M,)."""
    rho = np.arange(M) * (2.0 * math.pi / M)
    c, s = np.cos(rho), np.sin(rho)
    c.setflags(write=False)
    s.setflags(write=False)
    return c, s


def mean_std(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row mean and population standard deviation (1/M) of ``a`` (C, M), two-pass."""
    mean = a.mean(axis=1)
    dev = a - mean[:, None]
    var = np.einsum("ij,ij->i", dev, dev) / a.shape[1]
    return mean, np.sqrt(var)


class ScanBatch:
    """Cleaned scans ``d`` (C, M, float64, metres) and their intermediates, computed lazily.

    Attributes:
        d: the cleaned beam lengths.
        max_range: the sensor's maximum range (a beam of that length hit nothing).
        step: the angle between consecutive beams, 2π/M rad.
        fourier_orders: the Fourier orders n the planned features need (see fourier.py).
        cache: storage for kernels' own intermediates (keyed by the kernel module).
    """

    def __init__(self, d: np.ndarray, max_range: float, fourier_orders: frozenset[int] = frozenset()):
        self.d = d
        self.max_range = max_range
        self.M = d.shape[1]
        self.step = 2.0 * math.pi / self.M
        self.fourier_orders = fourier_orders
        self.cache: dict[str, Any] = {}

    # ---------------------------------------------------------------- raw beams (set A)
    @cached_property
    def d_next(self) -> np.ndarray:
        """``d[(i+1) mod M]`` (C, M)."""
        return np.roll(self.d, -1, axis=1)

    @cached_property
    def absdiff(self) -> np.ndarray:
        """``|d_i − d_{i+1}|`` (C, M), metres."""
        return np.abs(self.d - self.d_next)

    @cached_property
    def ratio(self) -> np.ndarray:
        """``d_i / d_{i+1}`` (C, M)."""
        return self.d / self.d_next

    @cached_property
    def beam_stats(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean and population standard deviation of the beam lengths (C,), metres."""
        return mean_std(self.d)

    @cached_property
    def hit(self) -> np.ndarray:
        """Beams that hit something, ``d < max_range`` (C, M) bool."""
        return self.d < self.max_range

    # ---------------------------------------------------------------- polygon Pol(z) (set B)
    @cached_property
    def xy(self) -> tuple[np.ndarray, np.ndarray]:
        """Vertex coordinates ``(x, y)`` of Pol(z), each (C, M), metres, robot at the origin."""
        c, s = beam_directions(self.M)
        return self.d * c, self.d * s

    @cached_property
    def prod_next(self) -> np.ndarray:
        """``d_i·d_{i+1}`` (C, M): the cross product x_i y_{i+1} − x_{i+1} y_i is this times sin(2π/M)."""
        return self.d * self.d_next

    @cached_property
    def area(self) -> np.ndarray:
        """Area of Pol(z) (C,), m². Positive: the polygon is star-shaped around the robot."""
        return 0.5 * math.sin(self.step) * self.prod_next.sum(axis=1)

    @cached_property
    def edge_len(self) -> np.ndarray:
        """Edge lengths ``|v_{i+1} − v_i|`` (C, M), metres, by the cancellation-free law of cosines."""
        h = math.sin(0.5 * self.step)
        diff = self.d - self.d_next
        return np.sqrt(diff * diff + (4.0 * h * h) * self.prod_next)

    @cached_property
    def perimeter(self) -> np.ndarray:
        """Perimeter of Pol(z) (C,), metres."""
        return self.edge_len.sum(axis=1)

    @cached_property
    def centroid(self) -> tuple[np.ndarray, np.ndarray]:
        """Area centroid ``(c_x, c_y)`` of Pol(z) (B.6, B.7), each (C,), metres.

        With the cross products ``sin(2π/M)·d_i d_{i+1}`` the factor 1/(6A) becomes
        ``1 / (3 Σ d_i d_{i+1})``.
        """
        x, y = self.xy
        p = self.prod_next
        denom = 3.0 * p.sum(axis=1)
        cx = np.einsum("ij,ij->i", x + np.roll(x, -1, axis=1), p) / denom
        cy = np.einsum("ij,ij->i", y + np.roll(y, -1, axis=1), p) / denom
        return cx, cy

    @cached_property
    def centroid_dist(self) -> np.ndarray:
        """Distances between the centroid and the vertices (C, M), metres."""
        x, y = self.xy
        cx, cy = self.centroid
        return np.hypot(x - cx[:, None], y - cy[:, None])

    @cached_property
    def centred(self) -> tuple[np.ndarray, np.ndarray]:
        """Vertex coordinates minus their mean ``(x − x̄, y − ȳ)`` (B.31, B.32), metres."""
        x, y = self.xy
        return x - x.mean(axis=1, keepdims=True), y - y.mean(axis=1, keepdims=True)

    @cached_property
    def moments2(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Second-order central vertex moments ``(μ20, μ02, μ11)`` (C,), m²."""
        xc, yc = self.centred
        return (
            np.einsum("ij,ij->i", xc, xc),
            np.einsum("ij,ij->i", yc, yc),
            np.einsum("ij,ij->i", xc, yc),
        )

    @cached_property
    def moments3(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Third-order central vertex moments ``(μ30, μ03, μ21, μ12)`` (C,), m³."""
        xc, yc = self.centred
        xx, yy = xc * xc, yc * yc
        return (
            np.einsum("ij,ij->i", xx, xc),
            np.einsum("ij,ij->i", yy, yc),
            np.einsum("ij,ij->i", xx, yc),
            np.einsum("ij,ij->i", xc, yy),
        )
