"""The 14 segment features of the book's appendix C (C.1–C.14), for all segments of a scan at once.

Every feature is a function of one segment's end points ``p_0 … p_{N−1}`` (metres, sensor
frame, beam order) and returns one real number; :func:`segment_features` computes all of
them for every segment of a :class:`~knowledge.people.segmentation.Segmentation` in one
compiled pass (numba) over the segments. Its sums run in the order of numpy's grouped
reductions (``np.add.reduceat`` for sums over a segment's points, ``np.bincount`` for sums
over its steps and triples), so the features agree with the vectorised numpy formulas to
the last bit, apart from the rounding of ``atan2`` in C.3 and C.13 (tests/unit/test_people_fast.py
keeps that implementation as the reference). Lengths are metres, angles radians, speeds
metres per second.

Where the printed formulas leave a choice, this module decides as follows:

* C.2: the root mean squared distance of the points to their centre of gravity (eq. C.1).
* C.3: the mean distance to the vector of medians ``(x̃, ỹ)`` (eq. C.2–C.3). The
  coordinate-wise median depends on the axes, so it is taken in axes along and across the
  segment's mean bearing (the direction from the sensor to its centre of gravity): the
  feature then does not change when the scan is rotated, and equals the printed one for a
  segment straight ahead of the sensor.
* C.4/C.5: the jump at the segment's border, i.e. the distance between its first (last)
  point and the end point of the beam just before (after) it. When that beam has a return it
  is the previous segment's last (next segment's first) point, as printed. When it has none,
  the beam saw nothing up to the sensor's range: its end point is taken at ``range_max``
  along the beam (the jump to open space; measuring across the gap to whatever segment comes
  next would make the feature depend on how much of the scan is empty, which differs from
  laser to laser in the legs data — it was the main cause of missed legs). The first (last)
  segment of a scan has no beam there: the feature is ``range_max``.
* C.7: total least squares (perpendicular) line fit; the residual sum of squares is the
  smaller eigenvalue of the points' scatter matrix — the same line as the closed-form Hessian
  fit the book cites.
* C.8/C.9: the algebraic circle fit of eq. C.8–C.9, solved in coordinates centred on the
  segment (the fit is translation invariant; centring keeps it well conditioned). Then
  C.8 = Σ (r_c − ‖p_i − c‖)² (eq. C.10) and C.9 = r_c. Degenerate cases: one point → r = 0;
  two points → the smallest circle through both (r = half their distance, C.8 = 0); points on
  a line (or a fitted radius above :data:`MAX_RADIUS`) → the "circle of infinite radius",
  i.e. the line: r = :data:`MAX_RADIUS`, C.8 = C.7.
* C.11: population standard deviation of the N−1 distances between neighbours (eq. C.12);
  0 for N < 3.
* C.12: the printed formula is a sum, the name says "average": we use the **mean** of
  ``k = 4A/(d_A d_B d_C)`` over the N−2 triples of consecutive points (unsigned, as printed;
  0 for a triple with a repeated point, and for N < 3).
* C.13: the **mean** of the signed turning angles ``β_j = atan2(u×v, u·v) ∈ (−π, π]``
  between ``u = p_j − p_{j−1}`` and ``v = p_{j+1} − p_j`` (atan2 does the unwrapping); the
  sign says convex or concave as seen from the sensor; 0 for N < 3.
* C.14: the printed formula is a sum, the name and text say mean: the **mean** of
  ``v_i = (d_i^{k+1} − d_i^k)/(T_{k+1} − T_k)`` over the segment's beams that had a return in
  both scans (signed: negative = approaching); 0 when there is no previous scan or no such beam.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

from knowledge.people.segmentation import FloatArray, Segmentation

#: ``(code, name, unit)`` of each feature, in column order.
FEATURES: tuple[tuple[str, str, str], ...] = (
    ("C.1", "n_points", "count"),
    ("C.2", "std", "m"),
    ("C.3", "mad_median", "m"),
    ("C.4", "jump_prev", "m"),
    ("C.5", "jump_next", "m"),
    ("C.6", "width", "m"),
    ("C.7", "linearity", "m²"),
    ("C.8", "circularity", "m²"),
    ("C.9", "radius", "m"),
    ("C.10", "boundary_length", "m"),
    ("C.11", "boundary_regularity", "m"),
    ("C.12", "mean_curvature", "1/m"),
    ("C.13", "mean_angular_difference", "rad"),
    ("C.14", "mean_speed", "m/s"),
)
FEATURE_CODES: tuple[str, ...] = tuple(f[0] for f in FEATURES)
FEATURE_NAMES: tuple[str, ...] = tuple(f[1] for f in FEATURES)
N_FEATURES = len(FEATURES)
#: Column of C.14, the only feature that needs the previous scan.
MOTION_COLUMN = 13
#: The static features C.1–C.13 (the book's Tables 8.1–8.4 use only these).
STATIC_COLUMNS: tuple[int, ...] = tuple(range(13))
ALL_COLUMNS: tuple[int, ...] = tuple(range(N_FEATURES))
#: Columns of the jump distances C.4 and C.5, which describe the segment's surroundings.
JUMP_COLUMNS: tuple[int, ...] = (3, 4)
#: What the detector uses by default: the static features without the jump distances, i.e.
#: only the segment's own shape (C.1–C.3, C.6–C.13). In the legs data the jumps say how the
#: data were collected (labelled people stand in front of empty space) rather than what a leg
#: looks like; see docs/people.md.
DEFAULT_COLUMNS: tuple[int, ...] = tuple(c for c in STATIC_COLUMNS if c not in JUMP_COLUMNS)

#: Radius reported for a straight segment (the limit of a circle fit), metres.
MAX_RADIUS = 100.0
#: Below this ratio det/trace² of the scatter matrix the points are taken as collinear.
COLLINEAR_RATIO = 1e-12
#: Stands for "no previous scan" in the kernel's arguments.
_NO_SCAN = np.zeros(0)


def feature_label(column: int) -> str:
    """``"C.9 radius"`` for a column index."""
    code, name, _ = FEATURES[column]
    return f"{code} {name}"


@numba.njit(cache=True, nogil=True)
def _block_sum(a: FloatArray, lo: int, n: int) -> float:  # pragma: no cover - compiled
    """Sum of ``a[lo:lo + n]``, ``n ≤ 128``, in the order of numpy's pairwise summation:
    sequential below 8 values, else 8 interleaved accumulators."""
    if n < 8:
        res = -0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - n % 8:
        j = lo + i
        r0 += a[j]
        r1 += a[j + 1]
        r2 += a[j + 2]
        r3 += a[j + 3]
        r4 += a[j + 4]
        r5 += a[j + 5]
        r6 += a[j + 6]
        r7 += a[j + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@numba.njit(cache=True, nogil=True)
def _half(n: int) -> int:  # pragma: no cover - compiled
    """Where numpy's pairwise summation splits ``n > 128`` values: about half, a multiple of 8."""
    n2 = n // 2
    return n2 - n2 % 8


@numba.njit(cache=True, nogil=True)
def _pairwise_sum(a: FloatArray, lo: int, n: int) -> float:  # pragma: no cover - compiled
    """Sum of ``a[lo:lo + n]`` in numpy's pairwise order: blocks of at most 128 values summed
    by :func:`_block_sum`, halves added recursively. The recursion runs on an explicit stack
    (numba's on-disk cache crashes on recursive functions, numba issue #6061)."""
    if n <= 128:
        return _block_sum(a, lo, n)
    los = np.empty(64, dtype=np.int64)
    ns = np.empty(64, dtype=np.int64)
    left_done = np.zeros(64, dtype=np.bool_)
    left = np.empty(64)
    top = 0
    los[0] = lo
    ns[0] = n
    while True:
        if ns[top] > 128:  # descend into the left half
            left_done[top] = False
            los[top + 1] = los[top]
            ns[top + 1] = _half(ns[top])
            top += 1
            continue
        v = _block_sum(a, los[top], ns[top])
        while True:  # hand v up to the parents
            if top == 0:
                return v
            top -= 1
            if not left_done[top]:  # v is the left half: now the right one
                left[top] = v
                left_done[top] = True
                n2 = _half(ns[top])
                los[top + 1] = los[top] + n2
                ns[top + 1] = ns[top] - n2
                top += 1
                break
            v = left[top] + v


@numba.njit(cache=True, nogil=True)
def _group_sum(a: FloatArray, n: int) -> float:  # pragma: no cover - compiled
    """``Σ a[:n]`` exactly as ``np.add.reduceat`` sums a group: first value + pairwise sum of the rest."""
    if n == 1:
        return float(a[0])
    return float(a[0] + _pairwise_sum(a, 1, n - 1))


@numba.njit(cache=True, nogil=True)
def _median(a: FloatArray, n: int, work: FloatArray) -> float:  # pragma: no cover - compiled
    """Median of ``a[:n]`` (the mean of the two middle values for even ``n``), by quickselect
    (Hoare partitions) on a copy in ``work``."""
    for i in range(n):
        work[i] = a[i]
    k = (n - 1) // 2
    lo, hi = 0, n - 1
    while lo < hi:
        pivot = work[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while work[i] < pivot:
                i += 1
            while work[j] > pivot:
                j -= 1
            if i <= j:
                work[i], work[j] = work[j], work[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    below = work[k]
    if n % 2:
        return float(below)
    above = work[k + 1]  # everything after position k is >= work[k]: the next value is their minimum
    for i in range(k + 2, n):
        above = min(above, work[i])
    return float(0.5 * (below + above))


@numba.njit(cache=True, nogil=True)
def _border_jump(
    points: FloatArray,
    index: npt.NDArray[np.intp],
    packed: int,
    side: int,
    n_beams: int,
    angle_min: float,
    angle_increment: float,
    range_max: float,
) -> float:  # pragma: no cover - compiled
    """C.4 (``side = −1``) or C.5 (``+1``) of the segment end at packed point ``packed``: the
    distance to the end point of the beam beside it (see the module doc)."""
    beam = index[packed] + side
    if beam < 0 or beam >= n_beams:
        return range_max
    nb = packed + side
    if 0 <= nb < points.shape[0] and index[nb] == beam:
        ox, oy = points[nb, 0], points[nb, 1]
    else:
        theta = angle_min + float(beam) * angle_increment
        ox, oy = range_max * math.cos(theta), range_max * math.sin(theta)
    return math.hypot(points[packed, 0] - ox, points[packed, 1] - oy)


@numba.njit(cache=True, nogil=True)
def _features_kernel(
    points: FloatArray,
    index: npt.NDArray[np.intp],
    ranges: FloatArray,
    start: npt.NDArray[np.intp],
    stop: npt.NDArray[np.intp],
    n_beams: int,
    angle_min: float,
    angle_increment: float,
    range_max: float,
    range_min: float,
    prev: FloatArray,
    dt: float,
    with_prev: bool,
) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - compiled
    """Features ``(S, 14)`` and centres of gravity ``(S, 2)`` of every segment, one segment at
    a time (sums in numpy's order, see the module doc); ``prev``/``dt`` are used only
    ``with_prev``."""
    S = start.shape[0]
    out = np.zeros((S, 14))
    centre = np.empty((S, 2))
    nmax = 1
    for s in range(S):
        nmax = max(nmax, stop[s] - start[s])
    dx = np.empty(nmax)
    dy = np.empty(nmax)
    q = np.empty(nmax)
    t = np.empty(nmax)
    u = np.empty(nmax)
    for s in range(S):
        a = start[s]
        n = stop[s] - a
        nf = float(n)
        # C.1, C.2: centre of gravity and the scatter matrix of the deviations from it
        for k in range(n):
            t[k] = points[a + k, 0]
            u[k] = points[a + k, 1]
        mx = _group_sum(t, n) / nf
        my = _group_sum(u, n) / nf
        centre[s, 0] = mx
        centre[s, 1] = my
        for k in range(n):
            dx[k] = points[a + k, 0] - mx
            dy[k] = points[a + k, 1] - my
        for k in range(n):
            t[k] = dx[k] * dx[k]
        sxx = _group_sum(t, n)
        for k in range(n):
            t[k] = dy[k] * dy[k]
        syy = _group_sum(t, n)
        for k in range(n):
            t[k] = dx[k] * dy[k]
        sxy = _group_sum(t, n)
        out[s, 0] = nf
        out[s, 1] = math.sqrt((sxx + syy) / nf)
        # C.3: medians along and across the mean bearing
        bearing = math.atan2(my, mx)
        cb = math.cos(bearing)
        sb = math.sin(bearing)
        for k in range(n):
            t[k] = dx[k] * cb + dy[k] * sb
            u[k] = dy[k] * cb - dx[k] * sb
        med_along = _median(t, n, q)
        med_across = _median(u, n, q)
        for k in range(n):
            t[k] = math.hypot(t[k] - med_along, u[k] - med_across)
        out[s, 2] = _group_sum(t, n) / nf
        # C.4/C.5
        last = a + n - 1
        out[s, 3] = _border_jump(points, index, a, -1, n_beams, angle_min, angle_increment, range_max)
        out[s, 4] = _border_jump(points, index, last, 1, n_beams, angle_min, angle_increment, range_max)
        # C.6
        width = math.hypot(points[last, 0] - points[a, 0], points[last, 1] - points[a, 1])
        out[s, 5] = width
        # C.7
        half_tr = 0.5 * (sxx + syy)
        h = 0.5 * (sxx - syy)
        disc = math.sqrt(h * h + sxy * sxy)
        linearity = max(half_tr - disc, 0.0)
        out[s, 6] = linearity
        # C.8/C.9: the centred algebraic circle fit
        for k in range(n):
            q[k] = dx[k] * dx[k] + dy[k] * dy[k]
        for k in range(n):
            t[k] = dx[k] * q[k]
        bx = 0.5 * _group_sum(t, n)
        for k in range(n):
            t[k] = dy[k] * q[k]
        by = 0.5 * _group_sum(t, n)
        det = sxx * syy - sxy * sxy
        tr = sxx + syy
        regular = n >= 3 and det > COLLINEAR_RATIO * tr * tr and tr > 0
        xc = (syy * bx - sxy * by) / det if regular else 0.0
        yc = (sxx * by - sxy * bx) / det if regular else 0.0
        r2 = xc * xc + yc * yc + _group_sum(q, n) / nf
        radius = math.sqrt(max(r2, 0.0))
        if regular and radius <= MAX_RADIUS:
            for k in range(n):
                res = radius - math.hypot(dx[k] - xc, dy[k] - yc)
                t[k] = res * res
            out[s, 7] = _group_sum(t, n)
            out[s, 8] = radius
        elif n >= 3:
            out[s, 7] = linearity
            out[s, 8] = MAX_RADIUS
        elif n == 2:
            out[s, 8] = 0.5 * width
        # C.10/C.11: steps between neighbours
        boundary = 0.0
        for k in range(n - 1):
            step = math.hypot(
                points[a + k + 1, 0] - points[a + k, 0], points[a + k + 1, 1] - points[a + k, 1]
            )
            t[k] = step
            boundary += step
        m = max(nf - 1.0, 1.0)
        dbar = boundary / m
        acc = 0.0
        for k in range(n - 1):
            e = t[k] - dbar
            acc += e * e
        out[s, 9] = boundary
        out[s, 10] = math.sqrt(acc / m) if n >= 3 else 0.0
        # C.12/C.13: triples of consecutive points
        kappa = 0.0
        beta = 0.0
        for j in range(n - 2):  # t[j] is still the step from point j to j + 1
            k = a + j
            ux = points[k + 1, 0] - points[k, 0]
            uy = points[k + 1, 1] - points[k, 1]
            vx = points[k + 2, 0] - points[k + 1, 0]
            vy = points[k + 2, 1] - points[k + 1, 1]
            wx = points[k + 2, 0] - points[k, 0]
            wy = points[k + 2, 1] - points[k, 1]
            cross = ux * vy - uy * vx
            dot = ux * vx + uy * vy
            prod = t[j] * t[j + 1] * math.hypot(wx, wy)
            kappa += 2.0 * abs(cross) / prod if prod > 0 else 0.0
            beta += math.atan2(cross, dot)
        m3 = max(nf - 2.0, 1.0)
        out[s, 11] = kappa / m3
        out[s, 12] = beta / m3
        # C.14: mean range rate over the beams with a return in both scans
        if with_prev:
            total = 0.0
            count = 0.0
            for k in range(a, a + n):
                p = prev[index[k]]
                if math.isfinite(p) and p > 0.0 and p >= range_min and p < range_max:
                    total += (ranges[k] - p) / dt
                    count += 1.0
                else:
                    total += 0.0
            out[s, 13] = total / max(count, 1.0) if count > 0 else 0.0
    return out, centre


def segment_features(
    seg: Segmentation,
    *,
    range_max: float,
    range_min: float = 0.0,
    previous: npt.ArrayLike | None = None,
    dt: float | None = None,
) -> FloatArray:
    """Features C.1–C.14 of every segment: ``(S, 14)`` float64, columns as :data:`FEATURES`.

    Args:
        seg: the scan's segmentation.
        range_max: the sensor's maximum range in metres (C.4/C.5 at the scan's ends; beams of
            ``previous`` at or beyond it have no return).
        range_min: the sensor's minimum range in metres (beams of ``previous`` below it have
            no return).
        previous: ``(B,)`` ranges in metres of the previous scan of the same sensor, for C.14.
        dt: seconds between the previous scan and this one (> 0), required with ``previous``.
    """
    return _features(seg, range_max=range_max, range_min=range_min, previous=previous, dt=dt)[0]


def _features(
    seg: Segmentation,
    *,
    range_max: float,
    range_min: float = 0.0,
    previous: npt.ArrayLike | None = None,
    dt: float | None = None,
) -> tuple[FloatArray, FloatArray]:
    """:func:`segment_features` and the segments' centres of gravity ``(S, 2)`` (metres, equal
    to :meth:`~knowledge.people.segmentation.Segmentation.centroids`), computed together."""
    S = seg.n_segments
    if S == 0:
        return np.zeros((0, N_FEATURES)), np.zeros((0, 2))
    if previous is not None:
        prev = np.ascontiguousarray(previous, dtype=np.float64)
        if prev.shape != (seg.n_beams,):
            raise ValueError(
                f"the previous scan has shape {prev.shape}, this one {seg.n_beams} beams: "
                "C.14 needs two scans of the same sensor"
            )
        if dt is None or not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be the positive number of seconds between the two scans, got {dt!r}")
    else:
        prev = _NO_SCAN
    out, centre = _features_kernel(
        np.ascontiguousarray(seg.points, dtype=np.float64),
        np.ascontiguousarray(seg.index, dtype=np.intp),
        np.ascontiguousarray(seg.ranges, dtype=np.float64),
        np.ascontiguousarray(seg.start, dtype=np.intp),
        np.ascontiguousarray(seg.stop, dtype=np.intp),
        int(seg.n_beams),
        float(seg.angle_min),
        float(seg.angle_increment),
        float(range_max),
        float(range_min),
        prev,
        float(dt) if previous is not None and dt is not None else 1.0,
        previous is not None,
    )
    return out, centre
