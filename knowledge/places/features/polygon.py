"""Set B: features of the polygon Pol(z) (book Appendix B), vectorised over scans.

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
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from knowledge.places.features.batch import ScanBatch, mean_std
from knowledge.places.features.raw import Kernel
from knowledge.places.features.registry import FeatureSpec


def shape_kernel(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    """B.1–B.5 and B.10–B.16 (area, perimeter and their ratios, centroid distances, moments)."""
    out = np.empty((batch.d.shape[0], len(specs)), dtype=np.float64)
    cstats: tuple[np.ndarray, np.ndarray] | None = None
    for j, spec in enumerate(specs):
        fam = spec.family
        if fam in ("B.4", "B.5", "B.15", "B.16"):
            if cstats is None:
                cstats = mean_std(batch.centroid_dist)
            value = cstats[0] if fam in ("B.4", "B.15") else cstats[1]
            if fam in ("B.15", "B.16"):
                value = value / batch.centroid_dist.max(axis=1)
            out[:, j] = value
        elif fam in ("B.10", "B.11"):
            m20, m02, m11 = batch.moments2
            trace = m20 + m02
            if fam == "B.10":
                out[:, j] = batch.area / trace
            else:
                out[:, j] = np.sqrt((m20 - m02) ** 2 + 4.0 * m11 * m11) / trace
        else:
            A = batch.area
            if fam == "B.1":
                out[:, j] = A
                continue
            P = batch.perimeter
            if fam == "B.2":
                out[:, j] = P
            elif fam == "B.3":
                out[:, j] = A / P
            elif fam == "B.12":
                out[:, j] = 4.0 * math.pi * A / np.sqrt(P)
            elif fam == "B.13":
                out[:, j] = P * P / A
            elif fam == "B.14":
                out[:, j] = 4.0 * math.pi * A / (P * P)
            else:
                raise AssertionError(f"shape kernel got {fam}")
    return out


def hu_invariants(
    eta20: np.ndarray,
    eta02: np.ndarray,
    eta11: np.ndarray,
    eta30: np.ndarray,
    eta03: np.ndarray,
    eta21: np.ndarray,
    eta12: np.ndarray,
) -> list[np.ndarray]:
    """Hu's seven invariants φ1..φ7 of normalised central moments (any matching shapes)."""
    a, b = eta30 + eta12, eta21 + eta03
    c, e = eta30 - 3.0 * eta12, 3.0 * eta21 - eta03
    d20 = eta20 - eta02
    a2, b2 = a * a, b * b
    return [
        eta20 + eta02,
        d20 * d20 + 4.0 * eta11 * eta11,
        c * c + e * e,
        a2 + b2,
        c * a * (a2 - 3.0 * b2) + e * b * (3.0 * a2 - b2),
        d20 * (a2 - b2) + 4.0 * eta11 * a * b,
        e * a * (a2 - 3.0 * b2) - c * b * (3.0 * a2 - b2),
    ]


def hu_kernel(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    """B.9: Hu's invariants φ_k of the vertex moments (see the module doc)."""
    M = float(batch.M)
    m20, m02, m11 = batch.moments2
    n2 = M**2.0
    need3 = any(int(s.params[0]) >= 3 for s in specs)
    if need3:
        m30, m03, m21, m12 = batch.moments3
        n3 = M**2.5
        third = (m30 / n3, m03 / n3, m21 / n3, m12 / n3)
    else:
        zero = np.zeros_like(m20)
        third = (zero, zero, zero, zero)
    phis = hu_invariants(m20 / n2, m02 / n2, m11 / n2, *third)
    out = np.empty((batch.d.shape[0], len(specs)), dtype=np.float64)
    for j, spec in enumerate(specs):
        out[:, j] = phis[int(spec.params[0]) - 1]
    return out


KERNELS: dict[str, Kernel] = {"shape": shape_kernel, "hu": hu_kernel}
