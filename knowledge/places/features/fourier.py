"""B.6–B.8 and Ma/Mi: Fourier coefficients of Pol(z) as a closed curve in arc length.

With the vertices ``v_k`` as complex numbers, the edges ``Δv_k = v_{k+1} − v_k`` of length
``ℓ_k``, unit directions ``Δs_k = Δv_k / ℓ_k``, arc positions ``t_k = Σ_{i<k} ℓ_i`` and the
perimeter T, the Fourier coefficients of the polygon z(t), t ∈ [0, T), are

    c_n = −T / (2πn)² · Σ_k (Δs_k − Δs_{k−1}) · e^{−j n (2π/T) t_k}          (n ≠ 0)

(integrate ``z(t) e^{−jωt}`` by parts twice: z'' is a sum of Dirac impulses, the turn
``Δs_k − Δs_{k−1}`` at vertex k, which sits at ``t_k``). The book's (B.13) prints "π" for
the n of the exponent (see shared/BOOK.md) and pairs the turn at vertex k+1 with ``t_k``;
we pair each turn with its own vertex, which makes c_n the exact coefficients of the
polygon: for a circle of radius r, |c_1| = r and c_n = 0 otherwise, and B.7/B.8 are the
semi-axes of the ellipse ``c_1 e^{jωt} + c_{−1} e^{−jωt}`` in metres.

**B.6** is the magnitude of the book's similarity-invariant descriptor (B.18),
``|c_n| / |c_1|``: invariant to rotation, translation, scale and to the start vertex (a
rotation of the scan by whole beams only changes phases). The 200 descriptors of the
default family are n = −100..−1 and 2..101: n = 0 is the centroid (it depends on where the
robot stands, not on the shape) and n = 1 is 1 by construction. If |c_1| is degenerate
(``|Σ_1| < 1e-9``; it never happens for a star-shaped scan polygon) the descriptors are 0.
**Ma/Mi** (``B.7/B.8``) is ``Ma / max(Mi, 1e-6·Ma)``, capped at 10⁶ when the ellipse
degenerates to a segment.

Speed (compiled, per scan). The turns ``τ_k`` and the unit phasors ``E_k = e^{−j2πt_k/T}``
are computed once; the phasors by reduction to a quarter turn and Taylor series of cos and
sin on [−π/4, π/4] (to ~1e-18, vectorised, no calls into libm). Only the requested sums
``S_{±n} = Σ_k τ_k E_k^{±n}`` are formed: the powers ``E^n`` come from a short program of
complex products (baby steps and giant steps, :mod:`.fourier_plan`), and each requested |n|
is one pass over the vertices accumulating ``Σ τ·E^n`` and ``Σ conj(τ)·E^n`` together
(``S_{−n} = conj(Σ conj(τ) E^n)``). The loops over the vertices are innermost and
vectorise; vertices go in blocks of :data:`_BLOCK` so that a block's powers stay in the L1
cache. Powers are products of at most ~2√max|n| unit phasors in float64: the error is
~1e-14 of |τ|, far below the features' n²-scaled resolution, so no renormalisation is needed.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from knowledge.places.features.batch import FASTMATH
from knowledge.places.features.fourier_plan import MAJOR, MINOR, MUL, RATIO, FourierPlan

#: |S_1| below this means c_1 = 0 (degenerate polygon): descriptors are defined as 0.
_DEGENERATE_S1 = 1e-9
#: Cap of Ma/Mi when the minor axis vanishes.
_MAX_AXIS_RATIO = 1e6
#: Taylor coefficients of cos a and (sin a)/a in powers of a² up to a¹⁶: on |a| ≤ π/4 the first
#: omitted terms are below 2e-18.
_COS = tuple((-1.0) ** k / math.factorial(2 * k) for k in range(9))
_SIN = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(9))
#: Vertices per block of the sums (a block's rows of powers stay in the L1 cache).
_BLOCK = 128


@numba.njit(cache=True, nogil=True)
def make_work(plan: FourierPlan, M: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scratch arrays of :func:`fourier_features` for M-beam scans: ``vert`` (5, M) for τ, E
    and the arc positions, ``work`` for a block of vertices (see :func:`_fourier_sums`) and
    ``sums`` (N, 4) for the N orders |n|."""
    vert = np.empty((5, M))
    work = np.empty((plan.rows, _BLOCK))
    sums = np.empty((plan.order_nn.size, 4))
    return vert, work, sums


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _horner(x: float, coefficients: tuple[float, ...]) -> float:
    """``Σ_i coefficients[i]·x^i`` by Horner's rule (constant tuples unroll)."""
    acc = coefficients[-1]
    for i in range(len(coefficients) - 2, -1, -1):
        acc = acc * x + coefficients[i]
    return acc


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _turns_and_phasors(x: np.ndarray, y: np.ndarray, ell: np.ndarray, T: float, vert: np.ndarray) -> None:
    """Turns ``τ_k`` into ``vert[0]``, ``vert[1]`` (re, im) and phasors ``E_k`` into ``vert[2]``,
    ``vert[3]``; ``vert[4]`` ends up holding the arc positions ``t_k / T``.

    ``x``, ``y`` are the M vertices with the first repeated at index M; ``ell`` the edges.
    """
    M = ell.size
    tr, ti, er, ei, u = vert[0], vert[1], vert[2], vert[3], vert[4]
    inv = 1.0 / ell[M - 1] if ell[M - 1] > 0.0 else 0.0
    prev_x, prev_y = (x[M] - x[M - 1]) * inv, (y[M] - y[M - 1]) * inv  # the last edge's direction
    for k in range(M):  # turns: unit edge direction minus the previous one
        inv = 1.0 / ell[k] if ell[k] > 0.0 else 0.0
        ux, uy = (x[k + 1] - x[k]) * inv, (y[k + 1] - y[k]) * inv
        tr[k] = ux - prev_x
        ti[k] = uy - prev_y
        prev_x, prev_y = ux, uy
    # arc positions t_k / T, two edges per step (halves the serial chain of additions)
    inv_T = 1.0 / T
    t = 0.0
    for k in range(0, M - 1, 2):
        u[k] = t * inv_T
        u[k + 1] = (t + ell[k]) * inv_T
        t += ell[k] + ell[k + 1]
    if M % 2:
        u[M - 1] = t * inv_T
    half_pi = 0.5 * math.pi
    for k in range(M):
        # 2πu = qπ/2 + a with a ∈ [−π/4, π/4]; e^{−j2πu} = (−j)^q · (cos a − j sin a)
        v = 4.0 * u[k]
        q = math.floor(v + 0.5)
        a = (v - q) * half_pi
        a2 = a * a
        c = _horner(a2, _COS)
        sn = a * _horner(a2, _SIN)
        quarter = q - 4.0 * math.floor(0.25 * q)
        odd = quarter == 1.0 or quarter == 3.0
        re = sn if odd else c
        im = c if odd else sn
        er[k] = -re if quarter == 1.0 or quarter == 2.0 else re
        ei[k] = im if quarter == 2.0 or quarter == 3.0 else -im


# The block loops index rows of one work array, w[row, k], with k from range(L): numba can
# prove such indices non-negative (no wrap-around test), which the vectoriser needs, and no
# array views are made in the loops (each view costs reference-count updates).


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _mul(w: np.ndarray, a: int, b: int, c: int, L: int) -> None:
    """Rows ``c, c+1`` = rows ``(a, a+1) · (b, b+1)`` as complex numbers (re, im), first L columns."""
    for k in range(L):
        re = w[a, k] * w[b, k] - w[a + 1, k] * w[b + 1, k]
        w[c + 1, k] = w[a, k] * w[b + 1, k] + w[a + 1, k] * w[b, k]
        w[c, k] = re


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _dot4(w: np.ndarray, p: int, L: int) -> tuple[float, float, float, float]:
    """With τ in rows 0, 1 and ``V`` in rows p, p+1: ``A = Σ τr·Vr, B = Σ τi·Vi, C = Σ τr·Vi,
    D = Σ τi·Vr``, so that ``Σ τV = (A − B, C + D)`` and ``conj(Σ conj(τ)V) = (A + B, D − C)``."""
    a = b = c = d = 0.0
    for k in range(L):
        vr, vi = w[p, k], w[p + 1, k]
        a += w[0, k] * vr
        b += w[1, k] * vi
        c += w[0, k] * vi
        d += w[1, k] * vr
    return a, b, c, d


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _dot4_product(w: np.ndarray, q: int, p: int, L: int) -> tuple[float, float, float, float]:
    """:func:`_dot4` for ``V = (rows q, q+1) · (rows p, p+1)``, formed on the fly."""
    a = b = c = d = 0.0
    for k in range(L):
        qr, qi, pr, pi = w[q, k], w[q + 1, k], w[p, k], w[p + 1, k]
        vr = qr * pr - qi * pi
        vi = qr * pi + qi * pr
        a += w[0, k] * vr
        b += w[1, k] * vi
        c += w[0, k] * vi
        d += w[1, k] * vr
    return a, b, c, d


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _fourier_sums(vert: np.ndarray, plan: FourierPlan, w: np.ndarray, sums: np.ndarray) -> None:
    """``sums[j] = (Re S_n, Im S_n, Re S_−n, Im S_−n)`` for the plan's orders |n| (module doc).

    ``vert`` holds τ and E (rows 0–3, see :func:`_turns_and_phasors`); ``w`` and ``sums``
    come from :func:`make_work`. Per block of L ≤ :data:`_BLOCK` vertices, τ and E are
    copied to rows 0–3 of ``w`` and the plan's program runs on its rows.
    """
    M = vert.shape[1]
    ops = plan.ops
    sums[:, :] = 0.0
    for start in range(0, M, _BLOCK):
        L = min(_BLOCK, M - start)
        for row in range(4):  # (explicit loops: numba's slice assignment is much slower)
            src = vert[row, start:]
            for k in range(L):
                w[row, k] = src[k]
        for i in range(ops.shape[0]):
            if ops[i, 0] == MUL:
                _mul(w, ops[i, 1], ops[i, 2], ops[i, 3], L)
                continue
            p, q, j = ops[i, 1], ops[i, 2], ops[i, 3]
            if q < 0:
                A, Bv, C, D = _dot4(w, p, L)
            else:
                A, Bv, C, D = _dot4_product(w, q, p, L)
            sums[j, 0] += A - Bv
            sums[j, 1] += C + D
            sums[j, 2] += A + Bv
            sums[j, 3] += D - C


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def fourier_features(
    x: np.ndarray,
    y: np.ndarray,
    ell: np.ndarray,
    T: float,
    plan: FourierPlan,
    vert: np.ndarray,
    work: np.ndarray,
    sums: np.ndarray,
    out: np.ndarray,
) -> None:
    """The plan's Fourier features of one scan polygon into ``out`` (the scan's output row).

    ``x``, ``y`` (M + 1,) are the vertices with the first repeated, ``ell`` (M,) the edge
    lengths, ``T`` the perimeter; ``vert``, ``work`` and ``sums`` come from :func:`make_work`.
    """
    _turns_and_phasors(x, y, ell, T, vert)
    _fourier_sums(vert, plan, work, sums)
    a1 = math.sqrt(sums[0, 0] ** 2 + sums[0, 1] ** 2)  # |n| = 1 comes first
    am1 = math.sqrt(sums[0, 2] ** 2 + sums[0, 3] ** 2)
    degenerate = a1 < _DEGENERATE_S1
    for j in range(plan.order_nn.size):
        scale = 0.0 if degenerate else 1.0 / (a1 * plan.order_nn[j])
        if plan.order_pos[j] >= 0:
            out[plan.order_pos[j]] = math.sqrt(sums[j, 0] ** 2 + sums[j, 1] ** 2) * scale
        if plan.order_neg[j] >= 0:
            out[plan.order_neg[j]] = math.sqrt(sums[j, 2] ** 2 + sums[j, 3] ** 2) * scale
    if plan.single[MAJOR] >= 0 or plan.single[MINOR] >= 0 or plan.single[RATIO] >= 0:
        scale = T / (4.0 * math.pi**2)  # |c_n| = T / (2πn)² · |S_n|
        major = scale * (a1 + am1)
        minor = scale * abs(a1 - am1)
        floor = major / _MAX_AXIS_RATIO
        if major > 0.0:
            ratio = major / (minor if minor > floor else (floor if floor > 0.0 else 1.0))
        else:
            ratio = 1.0
        if plan.single[MAJOR] >= 0:
            out[plan.single[MAJOR]] = major
        if plan.single[MINOR] >= 0:
            out[plan.single[MINOR]] = minor
        if plan.single[RATIO] >= 0:
            out[plan.single[RATIO]] = ratio
