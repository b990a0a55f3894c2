"""Set B: features of the polygon Pol(z) (book Appendix B), compiled scan by scan.

Pol(z) has the beam end points as vertices (B.1). Because every beam has a positive length
and consecutive beams are 2π/M apart, the polygon is star-shaped around the robot, its area
is positive and no edge has zero length, so the divisions below are always defined.

Where the printed formulas need care:

* **B.9** prints the central moments as a double sum over i and j; we use the vertex moments
  ``μ_pq = Σ_i (x_i − x̄)^p (y_i − ȳ)^q`` with ``μ_00 = M``, normalised as printed (B.33,
  B.34): ``η_pq = μ_pq / M^((p+q)/2 + 1)``. Vertex moments are invariant to rotation and
  translation; with μ_00 = M (not an area) they are not scale invariant. Hu's invariants
  are the standard ones: (B.39) and (B.41) print ``(η30 − η12)`` where Hu has
  ``(η30 + η12)``, which would not be rotation invariant.
* **B.11** prints ``√((μ20 + μ02)² + 4μ11²)``, which changes when the scan rotates (μ11 does);
  we use the standard eccentricity ``√((μ20 − μ02)² + 4μ11²) / (μ20 + μ02)`` (0 for a
  circle, 1 for a segment).
* **B.12** is the form factor as printed, ``4πA/√P`` (units m^1.5); **B.14** is
  ``4πA/P²`` (1 for a circle). Both are kept; boosting picks whichever separates.
* **B.4/B.5, B.15/B.16** use the area centroid of (B.6, B.7) and population deviations.

:func:`polygon_chunk` computes the polygon (vertices, edges, area, perimeter) once per scan
and from it the requested shape features, Hu invariants and Fourier features
(:mod:`.fourier`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numba
import numpy as np

from knowledge.places.features import fourier
from knowledge.places.features.batch import FASTMATH, array_max, edges, mean_std, vertices
from knowledge.places.features.fourier_plan import FourierPlan
from knowledge.places.features.registry import FeatureSpec

#: Families of set B without parameters (Fourier ones aside), in the order of
#: :attr:`PolygonPlan.single`.
SINGLE = ("B.1", "B.2", "B.3", "B.4", "B.5", "B.10", "B.11", "B.12", "B.13", "B.14", "B.15", "B.16")
_B1, _B2, _B3, _B4, _B5, _B10, _B11, _B12, _B13, _B14, _B15, _B16 = range(len(SINGLE))
#: Families :func:`make_plan` serves.
FAMILIES = frozenset((*SINGLE, "B.9"))


class PolygonPlan(NamedTuple):
    """Output columns of the requested shape features (−1: not requested).

    ``single`` holds the columns of :data:`SINGLE`, ``hu[k − 1]`` the column of B.9[phi=k];
    ``hu_max`` is the largest k requested (0: none).
    """

    single: np.ndarray
    hu: np.ndarray
    hu_max: int

    @property
    def active(self) -> bool:
        return bool((self.single >= 0).any() or (self.hu >= 0).any())


def make_plan(specs: Sequence[FeatureSpec], columns: Sequence[int]) -> PolygonPlan:
    """The plan for the shape features and Hu invariants ``specs`` written to ``columns``."""
    single = np.full(len(SINGLE), -1, dtype=np.int64)
    hu = np.full(7, -1, dtype=np.int64)
    for spec, col in zip(specs, columns, strict=True):
        if spec.family == "B.9":
            hu[int(spec.params[0]) - 1] = col
        else:
            single[SINGLE.index(spec.family)] = col
    return PolygonPlan(single, hu, int(np.flatnonzero(hu >= 0).max(initial=-1)) + 1)


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _centroid_features(
    x: np.ndarray,
    y: np.ndarray,
    prod: np.ndarray,
    total: float,
    plan: PolygonPlan,
    dist: np.ndarray,
    out: np.ndarray,
) -> None:
    """B.4, B.5, B.15, B.16 from the distances between the area centroid and the vertices.

    With the cross products ``sin(2π/M)·d_i d_{i+1}`` the centroid's factor 1/(6A) becomes
    ``1 / (3 Σ d_i d_{i+1})`` (``total`` is that sum).
    """
    M = prod.size
    sx = sy = 0.0
    for i in range(M):
        sx += (x[i] + x[i + 1]) * prod[i]
        sy += (y[i] + y[i + 1]) * prod[i]
    cx, cy = sx / (3.0 * total), sy / (3.0 * total)
    for i in range(M):
        dist[i] = math.sqrt((x[i] - cx) ** 2 + (y[i] - cy) ** 2)
    dmax = array_max(dist)
    mean, std = mean_std(dist)
    sg = plan.single
    if sg[_B4] >= 0:
        out[sg[_B4]] = mean
    if sg[_B5] >= 0:
        out[sg[_B5]] = std
    if sg[_B15] >= 0:
        out[sg[_B15]] = mean / dmax
    if sg[_B16] >= 0:
        out[sg[_B16]] = std / dmax


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _moment_features(x: np.ndarray, y: np.ndarray, area: float, plan: PolygonPlan, out: np.ndarray) -> None:
    """B.10, B.11 and the Hu invariants B.9 of the central vertex moments μ_pq (see the module doc)."""
    M = x.size - 1
    mx = my = 0.0
    for i in range(M):
        mx += x[i]
        my += y[i]
    mx /= M
    my /= M
    m20 = m02 = m11 = 0.0
    for i in range(M):
        xc, yc = x[i] - mx, y[i] - my
        m20 += xc * xc
        m02 += yc * yc
        m11 += xc * yc
    sg = plan.single
    trace = m20 + m02
    if sg[_B10] >= 0:
        out[sg[_B10]] = area / trace
    if sg[_B11] >= 0:
        out[sg[_B11]] = math.sqrt((m20 - m02) ** 2 + 4.0 * m11 * m11) / trace
    hu = plan.hu
    if plan.hu_max == 0:
        return
    m30 = m03 = m21 = m12 = 0.0
    if plan.hu_max >= 3:
        for i in range(M):
            xc, yc = x[i] - mx, y[i] - my
            xx, yy = xc * xc, yc * yc
            m30 += xx * xc
            m03 += yy * yc
            m21 += xx * yc
            m12 += xc * yy
    n2, n3 = float(M) ** 2.0, float(M) ** 2.5
    e20, e02, e11 = m20 / n2, m02 / n2, m11 / n2
    e30, e03, e21, e12 = m30 / n3, m03 / n3, m21 / n3, m12 / n3
    a, b = e30 + e12, e21 + e03
    c, e = e30 - 3.0 * e12, 3.0 * e21 - e03
    d20 = e20 - e02
    a2, b2 = a * a, b * b
    if hu[0] >= 0:
        out[hu[0]] = e20 + e02
    if hu[1] >= 0:
        out[hu[1]] = d20 * d20 + 4.0 * e11 * e11
    if hu[2] >= 0:
        out[hu[2]] = c * c + e * e
    if hu[3] >= 0:
        out[hu[3]] = a2 + b2
    if hu[4] >= 0:
        out[hu[4]] = c * a * (a2 - 3.0 * b2) + e * b * (3.0 * a2 - b2)
    if hu[5] >= 0:
        out[hu[5]] = d20 * (a2 - b2) + 4.0 * e11 * a * b
    if hu[6] >= 0:
        out[hu[6]] = e * a * (a2 - 3.0 * b2) - c * b * (3.0 * a2 - b2)


@numba.njit(cache=True, nogil=True)
def polygon_chunk(
    d: np.ndarray,
    cos: np.ndarray,
    sin: np.ndarray,
    plan: PolygonPlan,
    fplan: FourierPlan,
    out: np.ndarray,
) -> None:
    """The plans' set-B features of the cleaned scans ``d`` (S, M) into ``out`` (S, F).

    ``cos``, ``sin`` (M,) are the beam directions.
    """
    S, M = d.shape
    step = 2.0 * math.pi / M
    sg = plan.single
    want_centroid = sg[_B4] >= 0 or sg[_B5] >= 0 or sg[_B15] >= 0 or sg[_B16] >= 0
    want_moments = sg[_B10] >= 0 or sg[_B11] >= 0 or plan.hu_max > 0
    want_fourier = fplan.order_nn.size > 0
    dp = np.empty(M + 1)
    x = np.empty(M + 1)
    y = np.empty(M + 1)
    buf = np.empty((3, M))
    prod, ell, dist = buf[0], buf[1], buf[2]
    vert, work, sums = fourier.make_work(fplan, M)
    for s in range(S):
        row = out[s]
        scan = d[s]
        for i in range(M):
            dp[i] = scan[i]
        dp[M] = scan[0]
        vertices(dp[:M], cos, sin, x, y)
        total, P = edges(dp, step, prod, ell)
        A = 0.5 * math.sin(step) * total
        if sg[_B1] >= 0:
            row[sg[_B1]] = A
        if sg[_B2] >= 0:
            row[sg[_B2]] = P
        if sg[_B3] >= 0:
            row[sg[_B3]] = A / P
        if sg[_B12] >= 0:
            row[sg[_B12]] = 4.0 * math.pi * A / math.sqrt(P)
        if sg[_B13] >= 0:
            row[sg[_B13]] = P * P / A
        if sg[_B14] >= 0:
            row[sg[_B14]] = 4.0 * math.pi * A / (P * P)
        if want_centroid:
            _centroid_features(x, y, prod, total, plan, dist, row)
        if want_moments:
            _moment_features(x, y, A, plan, row)
        if want_fourier:
            fourier.fourier_features(x, y, ell, P, fplan, vert, work, sums, row)
