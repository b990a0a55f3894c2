"""Range input cleaning and the per-scan intermediates shared by the compiled kernels.

Scans are ``(S, M)`` arrays of beam lengths in metres; beam ``i`` points at ``i·2π/M`` rad
(counter-clockwise, a full 360° turn), so the polygon Pol(z) of each scan is star-shaped
around the robot and its vertices run counter-clockwise.

Cleaning (:func:`clean_chunk`): NaN, +inf and values above ``max_range`` become
``max_range`` (a beam that hit nothing); zero, negative and −inf values (anything below
:data:`MIN_RANGE`) become :data:`MIN_RANGE`. The minimum keeps every ratio (A.11, A.12,
A.15) and every polygon edge finite: no ratio exceeds ``max_range / MIN_RANGE``, the area is
positive and no edge has zero length.

The kernels (numba, compiled on first use and cached on disk) work scan by scan on small
per-scan buffers; the helpers here compute what several feature groups share: means and
population standard deviations, sliding minima, and the polygon's vertices and edges.
"""

from __future__ import annotations

import math
from functools import cache

import numba
import numpy as np

#: Smallest beam length in metres; shorter (0, negative) readings are raised to it. 1 cm is
#: below any laser scanner's minimum range, so only invalid readings are affected.
MIN_RANGE = 0.01

#: Floating-point freedoms of the kernels: reassociation lets sums vectorise, contraction
#: uses fused multiply-adds. Nothing assumes finite values (cleaning tests for NaN).
FASTMATH = {"reassoc", "contract"}


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


@cache
def beam_directions(M: int) -> tuple[np.ndarray, np.ndarray]:
    """``(cos ρ_i, sin ρ_i)`` for ``ρ_i = i·2π/M``, read-only arrays of shape (M,)."""
    rho = np.arange(M) * (2.0 * math.pi / M)
    c, s = np.cos(rho), np.sin(rho)
    c.setflags(write=False)
    s.setflags(write=False)
    return c, s


@numba.njit(cache=True, nogil=True)
def clean_chunk(src: np.ndarray, max_range: float, out: np.ndarray) -> None:
    """``out[s, i]`` = ``src[s, i]`` (S, M) with invalid readings replaced (see module doc)."""
    for s in range(src.shape[0]):
        for i in range(src.shape[1]):
            v = src[s, i]
            v = v if v <= max_range else max_range  # NaN, +inf, beyond the sensor's range
            out[s, i] = v if v >= MIN_RANGE else MIN_RANGE


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def mean_std(a: np.ndarray) -> tuple[float, float]:
    """Mean and population standard deviation (1/n) of ``a`` (n,), two-pass."""
    n = a.size
    total = 0.0
    for i in range(n):
        total += a[i]
    mean = total / n
    var = 0.0
    for i in range(n):
        dev = a[i] - mean
        var += dev * dev
    return mean, math.sqrt(var / n)


@numba.njit(cache=True, nogil=True)
def array_max(a: np.ndarray) -> float:
    """Largest value of ``a`` (n ≥ 1,) without NaN; four running maxima break the serial chain."""
    n4 = a.size // 4 * 4
    m0 = m1 = m2 = m3 = a[0]
    for i in range(0, n4, 4):
        m0 = max(m0, a[i])
        m1 = max(m1, a[i + 1])
        m2 = max(m2, a[i + 2])
        m3 = max(m3, a[i + 3])
    for i in range(n4, a.size):
        m0 = max(m0, a[i])
    return max(max(m0, m1), max(m2, m3))


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def vertices(d: np.ndarray, cos: np.ndarray, sin: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
    """Vertices ``(x, y)`` (M + 1,) of Pol(z), metres, robot at the origin, first one repeated."""
    M = d.size
    for i in range(M):
        x[i] = d[i] * cos[i]
        y[i] = d[i] * sin[i]
    x[M] = x[0]
    y[M] = y[0]


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def edges(d: np.ndarray, step: float, prod: np.ndarray, ell: np.ndarray) -> tuple[float, float]:
    """Products ``d_i·d_{i+1}`` and edge lengths ``|v_{i+1} − v_i|`` (M,); returns their sums.

    ``d`` holds M + 1 beams (the first repeated). The cross product ``x_i y_{i+1} − x_{i+1} y_i``
    is ``sin(2π/M)·d_i d_{i+1}``, so the area of Pol(z) is ``sin(2π/M)/2`` times the first sum
    (positive: the polygon is star-shaped around the robot); the perimeter is the second sum,
    the edges coming from the cancellation-free law of cosines.
    """
    M = prod.size
    h4 = 4.0 * math.sin(0.5 * step) ** 2
    total = 0.0
    perimeter = 0.0
    for i in range(M):
        p = d[i] * d[i + 1]
        diff = d[i] - d[i + 1]
        e = math.sqrt(diff * diff + h4 * p)
        prod[i] = p
        ell[i] = e
        total += p
        perimeter += e
    return total, perimeter


@numba.njit(cache=True, nogil=True)
def _min_pass(src: np.ndarray, dst: np.ndarray, n: int, shift: int) -> None:
    # ahead[j] instead of src[j + shift]: an index numba cannot prove non-negative gets a
    # wrap-around test that stops the loop from vectorising
    ahead = src[shift:]
    for j in range(n):
        dst[j] = min(src[j], ahead[j])


@numba.njit(cache=True, nogil=True)
def window_min(src: np.ndarray, w: int, tmp: np.ndarray, out: np.ndarray) -> None:
    """``out[j] = min(src[j : j + w])`` for j < out.size; ``src.size ≥ out.size + w − 1``.

    Doubling, branch-free and vectorised: after each pass ``tmp[·][j]`` is the minimum of
    ``span`` consecutive values, and two overlapping windows of the largest power of two ≤ w
    give the minimum over w. ``tmp`` is (2, ≥ src.size) scratch.
    """
    if w == 1:
        for j in range(out.size):
            out[j] = src[j]
        return
    n = src.size - 1
    _min_pass(src, tmp[0], n, 1)
    span = 2
    level = 0
    while 2 * span <= w:
        n -= span
        _min_pass(tmp[level], tmp[1 - level], n, span)
        span *= 2
        level = 1 - level
    _min_pass(tmp[level], out, out.size, w - span)
