"""Trajectory errors against reference poses: ATE and RPE, as the ``evo`` package defines them.

Both take two ``(N, 3)`` arrays of planar poses ``(x, y, theta)`` (metres, radians) of the
same instants (pair them first with :func:`associate`).

* **ATE** (absolute trajectory error): the estimate is first moved onto the reference by
  the rigid motion (rotation and translation, no scale) that minimises the squared position
  differences (:func:`align`: Umeyama's closed form in 2-D, evo's ``--align``), unless the
  two are already in one frame (``aligned=False``); the error of each pose is the distance
  between its position and the reference's; reported as RMS, mean, median and maximum.
* **RPE** (relative pose error): for pairs of poses ``(i, j)`` a path length ``delta``
  apart on the reference (consecutive pairs, evo's ``filter_pairs_by_path`` without
  ``all_pairs``, with ``pairs_from_reference``: a new pair starts where the last one ended),
  the error of the relative
  motion ``(⊖ref_i ⊕ ref_j)⁻¹ ⊕ (⊖est_i ⊕ est_j)``: its translation in metres and its
  rotation in radians. Independent of any alignment.

The test suite checks these against hand-computed cases and, where it is installed, against
evo 1.38 itself (``pip install evo``).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from knowledge.localization.se2 import between, compose, wrap

__all__ = ["ErrorStats", "align", "associate", "ate", "rpe"]


@dataclass(frozen=True)
class ErrorStats:
    """Summary of per-pose errors (metres, or radians for rotations)."""

    rmse: float
    mean: float
    median: float
    max: float
    n: int

    @classmethod
    def of(cls, errors: npt.ArrayLike) -> ErrorStats:
        e = np.asarray(errors, dtype=np.float64)
        if e.size == 0:
            nan = math.nan
            return cls(nan, nan, nan, nan, 0)
        return cls(
            float(np.sqrt(np.mean(e**2))), float(e.mean()), float(np.median(e)), float(e.max()), int(e.size)
        )

    def as_dict(self, digits: int = 4) -> dict[str, float | int]:
        return {
            "rmse": round(self.rmse, digits),
            "mean": round(self.mean, digits),
            "median": round(self.median, digits),
            "max": round(self.max, digits),
            "n": self.n,
        }


def associate(stamps_a: npt.ArrayLike, stamps_b: npt.ArrayLike, tolerance: float = 0.01) -> np.ndarray:
    """``(M, 2)`` index pairs ``(i, j)`` with ``|a[i] − b[j]| <= tolerance``: for each ``a``, its
    nearest ``b``, each ``b`` used once (the nearer claim wins). Both must be sorted."""
    a = np.asarray(stamps_a, dtype=np.float64)
    b = np.asarray(stamps_b, dtype=np.float64)
    if a.size == 0 or b.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    k = np.clip(np.searchsorted(b, a), 1, b.size - 1) if b.size > 1 else np.zeros(a.size, dtype=np.int64)
    if b.size > 1:
        left = k - 1
        k = np.where(np.abs(a - b[left]) <= np.abs(a - b[k]), left, k)
    d = np.abs(a - b[k])
    ok = d <= tolerance
    pairs = sorted(zip(d[ok].tolist(), np.nonzero(ok)[0].tolist(), k[ok].tolist(), strict=True))
    used: set[int] = set()
    out = []
    for _, i, j in pairs:
        if j not in used:
            used.add(j)
            out.append((i, j))
    out.sort()
    return np.asarray(out, dtype=np.int64).reshape(-1, 2)


def align(reference: npt.ArrayLike, estimate: npt.ArrayLike) -> np.ndarray:
    """The rigid motion ``T = (x, y, theta)`` that minimises ``Σ |ref_i − T·est_i|²`` over the
    positions (Umeyama 1991 without scale, in 2-D). Apply it with ``compose(T, estimate)``.

    Raises:
        ValueError: fewer than two poses, or shapes that differ.
    """
    R = np.asarray(reference, dtype=np.float64)[:, :2]
    E = np.asarray(estimate, dtype=np.float64)[:, :2]
    if R.shape != E.shape or R.shape[0] < 2:
        raise ValueError(f"align needs two (N >= 2, 3) arrays of equal shape, got {R.shape} and {E.shape}")
    mr, me = R.mean(axis=0), E.mean(axis=0)
    H = (E - me).T @ (R - mr)  # Σ e_i r_iᵀ
    theta = math.atan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1])
    c, s = math.cos(theta), math.sin(theta)
    t = mr - np.array([c * me[0] - s * me[1], s * me[0] + c * me[1]])
    return np.array([t[0], t[1], theta])


def ate(
    reference: npt.ArrayLike, estimate: npt.ArrayLike, *, aligned: bool = True
) -> tuple[ErrorStats, np.ndarray, np.ndarray]:
    """Absolute trajectory error of ``estimate`` against ``reference`` (both ``(N, 3)``).

    Returns:
        the position error statistics, ``(N,)`` the per-pose position errors (metres), and
        the estimate as compared (moved by :func:`align` when ``aligned``).
    """
    R = np.asarray(reference, dtype=np.float64)
    E = np.asarray(estimate, dtype=np.float64)
    if R.shape != E.shape or R.ndim != 2 or R.shape[1] != 3:
        raise ValueError(f"ate needs two (N, 3) arrays of equal shape, got {R.shape} and {E.shape}")
    if aligned:
        E = compose(align(R, E), E)
    err = np.hypot(E[:, 0] - R[:, 0], E[:, 1] - R[:, 1])
    return ErrorStats.of(err), err, E


def path_pairs(reference: npt.ArrayLike, delta: float) -> list[tuple[int, int]]:
    """Consecutive index pairs whose path along ``reference`` is at least ``delta`` metres
    (evo's ``filter_pairs_by_path`` without ``all_pairs``)."""
    if not delta > 0:
        raise ValueError(f"delta must be a positive path length in metres, got {delta}")
    R = np.asarray(reference, dtype=np.float64)
    ids = [0]
    path = 0.0
    for i in range(1, R.shape[0]):
        path += float(np.hypot(R[i, 0] - R[i - 1, 0], R[i, 1] - R[i - 1, 1]))
        if path >= delta:
            ids.append(i)
            path = 0.0
    return list(itertools.pairwise(ids))


def rpe(
    reference: npt.ArrayLike, estimate: npt.ArrayLike, delta: float = 1.0
) -> tuple[ErrorStats, ErrorStats]:
    """Relative pose error over ``delta`` metres of reference path: (translation in metres,
    rotation in radians)."""
    R = np.asarray(reference, dtype=np.float64)
    E = np.asarray(estimate, dtype=np.float64)
    if R.shape != E.shape or R.ndim != 2 or R.shape[1] != 3:
        raise ValueError(f"rpe needs two (N, 3) arrays of equal shape, got {R.shape} and {E.shape}")
    pairs = path_pairs(R, delta)
    if not pairs:
        return ErrorStats.of([]), ErrorStats.of([])
    i, j = np.array(pairs).T
    err = between(between(R[i], R[j]), between(E[i], E[j]))
    return ErrorStats.of(np.hypot(err[:, 0], err[:, 1])), ErrorStats.of(np.abs(wrap(err[:, 2])))
