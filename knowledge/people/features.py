"""The 14 segment features of the book's appendix C (C.1–C.14), for all segments of a scan at once.

Every feature is a function of one segment's end points ``p_0 … p_{N−1}`` (metres, sensor
frame, beam order) and returns one real number; :func:`segment_features` computes all of
them for every segment of a :class:`~knowledge.people.segmentation.Segmentation` with
grouped numpy reductions (no Python loop over segments). Lengths are metres, angles radians,
speeds metres per second.

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

import numpy as np
import numpy.typing as npt

from knowledge.people.segmentation import FloatArray, Segmentation, has_return

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


def feature_label(column: int) -> str:
    """``"C.9 radius"`` for a column index."""
    code, name, _ = FEATURES[column]
    return f"{code} {name}"


def _group_sum(values: FloatArray, starts: npt.NDArray[np.intp], sizes: npt.NDArray[np.intp]) -> FloatArray:
    """Sum of ``values`` (first axis) over each packed group; 0 for empty groups."""
    if values.shape[0] == 0:
        return np.zeros((sizes.shape[0], *values.shape[1:]))
    out = np.add.reduceat(values, np.minimum(starts, values.shape[0] - 1), axis=0)
    out[sizes == 0] = 0.0
    return np.asarray(out)


def _group_median(
    v: FloatArray, seg: npt.NDArray[np.intp], start: npt.NDArray[np.intp], n: npt.NDArray[np.intp]
) -> FloatArray:
    """Median of ``v`` within each segment (all segments non-empty), eq. C.2."""
    order = np.lexsort((v, seg))
    s = v[order]
    lo = start + (n - 1) // 2
    hi = start + n // 2
    return np.asarray(0.5 * (s[lo] + s[hi]))


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
    S = seg.n_segments
    out = np.zeros((S, N_FEATURES))
    if S == 0:
        return out
    P = seg.points
    start, stop = seg.start, seg.stop
    n = seg.sizes
    nf = n.astype(np.float64)
    g = seg.point_segment

    # C.1
    out[:, 0] = nf
    # C.2: deviations from the centre of gravity
    mean = _group_sum(P, start, n) / nf[:, None]
    D = P - mean[g]
    sxx = _group_sum(D[:, 0] ** 2, start, n)
    syy = _group_sum(D[:, 1] ** 2, start, n)
    sxy = _group_sum(D[:, 0] * D[:, 1], start, n)
    out[:, 1] = np.sqrt((sxx + syy) / nf)
    # C.3: vector of medians, in axes along and across the segment's mean bearing
    bearing = np.arctan2(mean[:, 1], mean[:, 0])
    cb, sb = np.cos(bearing)[g], np.sin(bearing)[g]
    along = D[:, 0] * cb + D[:, 1] * sb
    across = D[:, 1] * cb - D[:, 0] * sb
    med_along = _group_median(along, g, start, n)
    med_across = _group_median(across, g, start, n)
    out[:, 2] = _group_sum(np.hypot(along - med_along[g], across - med_across[g]), start, n) / nf
    # C.4/C.5: jumps to the neighbouring beams
    first = P[start]
    last = P[stop - 1]
    out[:, 3] = _border_jump(seg, first, start, -1, range_max)
    out[:, 4] = _border_jump(seg, last, stop - 1, +1, range_max)
    # C.6
    out[:, 5] = np.hypot(*(last - first).T)
    # C.7: smaller eigenvalue of the scatter matrix = perpendicular residual sum of squares
    half_tr = 0.5 * (sxx + syy)
    disc = np.sqrt((0.5 * (sxx - syy)) ** 2 + sxy**2)
    linearity = np.maximum(half_tr - disc, 0.0)
    out[:, 6] = linearity
    # C.8/C.9: algebraic circle fit in centred coordinates. With Σx = Σy = 0 the normal
    # equations of eq. C.8–C.9 split into c = −Σq/N and a 2×2 system for the centre.
    q = D[:, 0] ** 2 + D[:, 1] ** 2
    bx = 0.5 * _group_sum(D[:, 0] * q, start, n)
    by = 0.5 * _group_sum(D[:, 1] * q, start, n)
    det = sxx * syy - sxy**2
    tr = sxx + syy
    regular = (n >= 3) & (det > COLLINEAR_RATIO * tr * tr) & (tr > 0)
    safe = np.where(regular, det, 1.0)
    xc = np.where(regular, (syy * bx - sxy * by) / safe, 0.0)
    yc = np.where(regular, (sxx * by - sxy * bx) / safe, 0.0)
    r2 = xc**2 + yc**2 + _group_sum(q, start, n) / nf
    radius = np.sqrt(np.maximum(r2, 0.0))
    regular &= radius <= MAX_RADIUS
    resid = radius[g] - np.hypot(D[:, 0] - xc[g], D[:, 1] - yc[g])
    circularity = _group_sum(resid**2, start, n)
    two = n == 2
    out[:, 7] = np.where(regular, circularity, np.where(n >= 3, linearity, 0.0))
    out[:, 8] = np.where(regular, radius, np.where(n >= 3, MAX_RADIUS, np.where(two, 0.5 * out[:, 5], 0.0)))
    # C.10/C.11: distances between neighbouring points of a segment
    if P.shape[0] > 1:
        step = np.hypot(*(P[1:] - P[:-1]).T)
        inner = g[1:] == g[:-1]
        gs = g[:-1][inner]
        st = step[inner]
        boundary = np.bincount(gs, weights=st, minlength=S)
        m = np.maximum(nf - 1.0, 1.0)
        dbar = boundary / m
        reg = np.sqrt(np.bincount(gs, weights=(st - dbar[gs]) ** 2, minlength=S) / m)
        out[:, 9] = boundary
        out[:, 10] = np.where(n >= 3, reg, 0.0)
    # C.12/C.13: triples of consecutive points
    if P.shape[0] > 2:
        a, b, c = P[:-2], P[1:-1], P[2:]
        trip = g[2:] == g[:-2]
        gt = g[:-2][trip]
        u = (b - a)[trip]
        v = (c - b)[trip]
        w = (c - a)[trip]
        cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
        dot = (u * v).sum(axis=1)
        da = np.hypot(*u.T)
        db = np.hypot(*v.T)
        dc = np.hypot(*w.T)
        prod = da * db * dc
        # area of the triangle = |u × w| / 2 = |u × v| / 2
        kappa = np.where(prod > 0, 2.0 * np.abs(cross) / np.where(prod > 0, prod, 1.0), 0.0)
        beta = np.arctan2(cross, dot)
        m3 = np.maximum(nf - 2.0, 1.0)
        out[:, 11] = np.bincount(gt, weights=kappa, minlength=S) / m3
        out[:, 12] = np.bincount(gt, weights=beta, minlength=S) / m3
    # C.14
    if previous is not None:
        out[:, MOTION_COLUMN] = _mean_speed(seg, previous, dt, range_max, range_min)
    return out


def _border_jump(
    seg: Segmentation, ends: FloatArray, packed: npt.NDArray[np.intp], side: int, range_max: float
) -> FloatArray:
    """C.4 (``side = −1``) or C.5 (``+1``): distance from each segment's end point ``ends``
    ``(S, 2)`` (packed point ``packed``) to the end point of the beam beside it (see the module doc)."""
    beam = seg.index[packed] + side
    nb = packed + side
    inside = (beam >= 0) & (beam < seg.n_beams)
    # the neighbouring beam has a return iff it is the neighbouring packed point's beam
    ok = (nb >= 0) & (nb < seg.n_points)
    has = np.zeros(beam.shape, dtype=bool)
    has[ok] = seg.index[nb[ok]] == beam[ok]
    other = range_max * seg.beam_directions(beam)
    other[has] = seg.points[nb[has]]
    return np.asarray(np.where(inside, np.hypot(*(ends - other).T), range_max))


def _mean_speed(
    seg: Segmentation, previous: npt.ArrayLike, dt: float | None, range_max: float, range_min: float
) -> FloatArray:
    prev = np.asarray(previous, dtype=np.float64)
    if prev.shape != (seg.n_beams,):
        raise ValueError(
            f"the previous scan has shape {prev.shape}, this one {seg.n_beams} beams: "
            "C.14 needs two scans of the same sensor"
        )
    if dt is None or not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be the positive number of seconds between the two scans, got {dt!r}")
    ok = has_return(prev, range_max, range_min)[seg.index]
    v = np.where(ok, (seg.ranges - np.where(ok, prev[seg.index], 0.0)) / dt, 0.0)
    S = seg.n_segments
    g = seg.point_segment
    total = np.bincount(g, weights=v, minlength=S)
    count = np.bincount(g, weights=ok.astype(np.float64), minlength=S)
    return np.asarray(np.where(count > 0, total / np.maximum(count, 1.0), 0.0))
