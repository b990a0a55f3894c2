"""The compiled people pipeline equals the vectorised one it replaced.

Segmentation, features C.1–C.14, detection and tracking were rewritten for speed (numba
kernels, a closed-form Kalman filter). The implementations they replaced are kept below,
verbatim but renamed, as the reference (the reference tracker steps with the matrix-form
:func:`kalman_predict`/:func:`kalman_update` that the module still offers): the new code must
give the same segments, the same features (to 1e-9; in practice bit for bit except the last
ulp of ``atan2`` in C.3/C.13), the same classifications and the same tracks (ids, counts,
hits, misses exactly; states to 1e-9), on random scans and detection sequences and on real
scans (the agent benchmark's simulated
drive, and the legs data when it is there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment

from knowledge.people import features as feat
from knowledge.people.detector import LegDetector, SegmentDetection
from knowledge.people.features import MAX_RADIUS, MOTION_COLUMN, N_FEATURES, segment_features
from knowledge.people.pairing import LONE_LEG_POLICIES, People, pair_legs
from knowledge.people.pipeline import PeoplePipeline, to_frame
from knowledge.people.segmentation import FloatArray, Segmentation, has_return, segment_scan
from knowledge.people.tracking import PeopleTracker, TrackerConfig, TrackState, kalman_predict, kalman_update

# ----------------------------------------------------------------------------------------
# The reference: the vectorised implementations as they were before the rewrite.
# ----------------------------------------------------------------------------------------

COLLINEAR_RATIO = 1e-12


def ref_segment_scan(
    ranges: npt.ArrayLike,
    angle_min: float,
    angle_increment: float,
    *,
    range_max: float,
    range_min: float = 0.0,
    jump: float = 0.15,
    max_gap: int | None = None,
) -> Segmentation:
    r = np.asarray(ranges, dtype=np.float64)
    index = np.flatnonzero(has_return(r, range_max, range_min)).astype(np.intp)
    rr = r[index]
    theta = angle_min + index * angle_increment
    points = np.empty((index.size, 2))
    points[:, 0] = rr * np.cos(theta)
    points[:, 1] = rr * np.sin(theta)
    if index.size == 0:
        empty = np.zeros(0, dtype=np.intp)
        return Segmentation(
            r.size,
            index,
            rr,
            points,
            empty,
            empty.copy(),
            float(jump),
            float(angle_min),
            float(angle_increment),
        )
    d = points[1:] - points[:-1]
    cut = (d[:, 0] ** 2 + d[:, 1] ** 2) > jump * jump
    if max_gap is not None:
        cut |= (index[1:] - index[:-1] - 1) > max_gap
    brk = np.flatnonzero(cut) + 1
    start = np.concatenate(([0], brk)).astype(np.intp)
    stop = np.concatenate((brk, [index.size])).astype(np.intp)
    return Segmentation(
        r.size, index, rr, points, start, stop, float(jump), float(angle_min), float(angle_increment)
    )


def _ref_group_sum(
    values: FloatArray, starts: npt.NDArray[np.intp], sizes: npt.NDArray[np.intp]
) -> FloatArray:
    if values.shape[0] == 0:
        return np.zeros((sizes.shape[0], *values.shape[1:]))
    out = np.add.reduceat(values, np.minimum(starts, values.shape[0] - 1), axis=0)
    out[sizes == 0] = 0.0
    return np.asarray(out)


def _ref_group_median(
    v: FloatArray, seg: npt.NDArray[np.intp], start: npt.NDArray[np.intp], n: npt.NDArray[np.intp]
) -> FloatArray:
    order = np.lexsort((v, seg))
    s = v[order]
    lo = start + (n - 1) // 2
    hi = start + n // 2
    return np.asarray(0.5 * (s[lo] + s[hi]))


def ref_segment_features(
    seg: Segmentation,
    *,
    range_max: float,
    range_min: float = 0.0,
    previous: npt.ArrayLike | None = None,
    dt: float | None = None,
) -> FloatArray:
    S = seg.n_segments
    out = np.zeros((S, N_FEATURES))
    if S == 0:
        return out
    P = seg.points
    start, stop = seg.start, seg.stop
    n = seg.sizes
    nf = n.astype(np.float64)
    g = seg.point_segment
    out[:, 0] = nf
    mean = _ref_group_sum(P, start, n) / nf[:, None]
    D = P - mean[g]
    sxx = _ref_group_sum(D[:, 0] ** 2, start, n)
    syy = _ref_group_sum(D[:, 1] ** 2, start, n)
    sxy = _ref_group_sum(D[:, 0] * D[:, 1], start, n)
    out[:, 1] = np.sqrt((sxx + syy) / nf)
    bearing = np.arctan2(mean[:, 1], mean[:, 0])
    cb, sb = np.cos(bearing)[g], np.sin(bearing)[g]
    along = D[:, 0] * cb + D[:, 1] * sb
    across = D[:, 1] * cb - D[:, 0] * sb
    med_along = _ref_group_median(along, g, start, n)
    med_across = _ref_group_median(across, g, start, n)
    out[:, 2] = _ref_group_sum(np.hypot(along - med_along[g], across - med_across[g]), start, n) / nf
    first = P[start]
    last = P[stop - 1]
    out[:, 3] = _ref_border_jump(seg, first, start, -1, range_max)
    out[:, 4] = _ref_border_jump(seg, last, stop - 1, +1, range_max)
    out[:, 5] = np.hypot(*(last - first).T)
    half_tr = 0.5 * (sxx + syy)
    disc = np.sqrt((0.5 * (sxx - syy)) ** 2 + sxy**2)
    linearity = np.maximum(half_tr - disc, 0.0)
    out[:, 6] = linearity
    q = D[:, 0] ** 2 + D[:, 1] ** 2
    bx = 0.5 * _ref_group_sum(D[:, 0] * q, start, n)
    by = 0.5 * _ref_group_sum(D[:, 1] * q, start, n)
    det = sxx * syy - sxy**2
    tr = sxx + syy
    regular = (n >= 3) & (det > COLLINEAR_RATIO * tr * tr) & (tr > 0)
    safe = np.where(regular, det, 1.0)
    xc = np.where(regular, (syy * bx - sxy * by) / safe, 0.0)
    yc = np.where(regular, (sxx * by - sxy * bx) / safe, 0.0)
    r2 = xc**2 + yc**2 + _ref_group_sum(q, start, n) / nf
    radius = np.sqrt(np.maximum(r2, 0.0))
    regular &= radius <= MAX_RADIUS
    resid = radius[g] - np.hypot(D[:, 0] - xc[g], D[:, 1] - yc[g])
    circularity = _ref_group_sum(resid**2, start, n)
    two = n == 2
    out[:, 7] = np.where(regular, circularity, np.where(n >= 3, linearity, 0.0))
    out[:, 8] = np.where(regular, radius, np.where(n >= 3, MAX_RADIUS, np.where(two, 0.5 * out[:, 5], 0.0)))
    if P.shape[0] > 1:
        step = np.hypot(*(P[1:] - P[:-1]).T)
        inner = g[1:] == g[:-1]
        gs = g[:-1][inner]
        st_ = step[inner]
        boundary = np.bincount(gs, weights=st_, minlength=S)
        m = np.maximum(nf - 1.0, 1.0)
        dbar = boundary / m
        reg = np.sqrt(np.bincount(gs, weights=(st_ - dbar[gs]) ** 2, minlength=S) / m)
        out[:, 9] = boundary
        out[:, 10] = np.where(n >= 3, reg, 0.0)
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
        kappa = np.where(prod > 0, 2.0 * np.abs(cross) / np.where(prod > 0, prod, 1.0), 0.0)
        beta = np.arctan2(cross, dot)
        m3 = np.maximum(nf - 2.0, 1.0)
        out[:, 11] = np.bincount(gt, weights=kappa, minlength=S) / m3
        out[:, 12] = np.bincount(gt, weights=beta, minlength=S) / m3
    if previous is not None:
        out[:, MOTION_COLUMN] = _ref_mean_speed(seg, previous, dt, range_max, range_min)
    return out


def _ref_border_jump(
    seg: Segmentation, ends: FloatArray, packed: npt.NDArray[np.intp], side: int, range_max: float
) -> FloatArray:
    beam = seg.index[packed] + side
    nb = packed + side
    inside = (beam >= 0) & (beam < seg.n_beams)
    ok = (nb >= 0) & (nb < seg.n_points)
    has = np.zeros(beam.shape, dtype=bool)
    has[ok] = seg.index[nb[ok]] == beam[ok]
    other = range_max * seg.beam_directions(beam)
    other[has] = seg.points[nb[has]]
    return np.asarray(np.where(inside, np.hypot(*(ends - other).T), range_max))


def _ref_mean_speed(
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


def ref_detect(
    det: LegDetector,
    ranges: npt.ArrayLike,
    angle_min: float,
    angle_increment: float,
    *,
    range_max: float,
    range_min: float = 0.0,
    previous: npt.ArrayLike | None = None,
    dt: float | None = None,
) -> SegmentDetection:
    seg = ref_segment_scan(
        ranges,
        angle_min,
        angle_increment,
        range_max=range_max,
        range_min=range_min,
        jump=det.jump,
        max_gap=det.max_gap,
    )
    X = ref_segment_features(seg, range_max=range_max, range_min=range_min, previous=previous, dt=dt)
    score = np.full(seg.n_segments, -np.inf)
    big = det.classifies(seg.sizes, np.hypot(*seg.centroids().T) if seg.n_segments else None)
    if big.any():
        score[big] = det.booster_.decision_function(X[big][:, list(det.columns)])
    return SegmentDetection(seg, X, score, score >= det.threshold)


def ref_pair_legs(legs: npt.ArrayLike, *, max_distance: float = 0.6, lone_legs: str = "person") -> People:
    L = np.asarray(legs, dtype=np.float64).reshape(-1, 2) if np.size(legs) else np.zeros((0, 2))
    if not (math.isfinite(max_distance) and max_distance > 0):
        raise ValueError(f"max_distance must be a positive number of metres, got {max_distance!r}")
    if lone_legs not in LONE_LEG_POLICIES:
        raise ValueError(f"lone_legs must be one of {LONE_LEG_POLICIES}, got {lone_legs!r}")
    K = L.shape[0]
    pairs: list[tuple[int, int]] = []
    used = np.zeros(K, dtype=bool)
    if K >= 2:
        i, j = np.triu_indices(K, k=1)
        d = np.hypot(L[i, 0] - L[j, 0], L[i, 1] - L[j, 1])
        close = d <= max_distance
        i, j, d = i[close], j[close], d[close]
        for k in np.argsort(d, kind="stable").tolist():
            a, b = int(i[k]), int(j[k])
            if not (used[a] or used[b]):
                used[a] = used[b] = True
                pairs.append((a, b))
    rows = [(a, b) for a, b in pairs]
    if lone_legs == "person":
        rows += [(int(a), -1) for a in np.flatnonzero(~used)]
    idx = np.array(rows, dtype=np.intp).reshape(-1, 2)
    if idx.shape[0] == 0:
        return People(np.zeros((0, 2)), idx)
    second = np.where(idx[:, 1:2] >= 0, L[np.maximum(idx[:, 1], 0)], L[idx[:, 0]])
    positions = 0.5 * (L[idx[:, 0]] + second)
    return People(positions, idx)


@dataclass
class _RefTrack:
    x: FloatArray
    P: FloatArray
    born: float
    last_seen: float
    hits: int = 1
    misses: int = 0
    age: int = 1
    id: int = 0

    @property
    def confirmed(self) -> bool:
        return self.id > 0

    def state(self) -> TrackState:
        return TrackState(
            id=self.id,
            position=self.x[:2].copy(),
            velocity=self.x[2:].copy(),
            covariance=self.P.copy(),
            hits=self.hits,
            misses=self.misses,
            age=self.age,
            first_seen=self.born,
            last_seen=self.last_seen,
        )


class RefTracker:
    def __init__(self, config: TrackerConfig | None = None) -> None:
        self.config = config or TrackerConfig()
        self._tracks: list[_RefTrack] = []
        self._next_id = 1
        self._time: float | None = None

    def reset(self) -> None:
        self._tracks = []
        self._time = None

    def tracks(self, *, include_tentative: bool = False) -> list[TrackState]:
        out = [t.state() for t in self._tracks if t.confirmed or include_tentative]
        return sorted(out, key=lambda s: (s.id == 0, s.id))

    def update(self, detections: npt.ArrayLike, t: float) -> list[TrackState]:
        Z = (
            np.asarray(detections, dtype=np.float64).reshape(-1, 2)
            if np.size(detections)
            else np.zeros((0, 2))
        )
        if not np.isfinite(Z).all():
            raise ValueError("detections must be finite (K, 2) positions in metres")
        if not math.isfinite(t):
            raise ValueError(f"t must be a finite time in seconds, got {t!r}")
        cfg = self.config
        dt = 0.0 if self._time is None else t - self._time
        if dt < 0:
            raise ValueError(f"time went backwards: update at t={t} after t={self._time}; call reset() first")
        self._time = t
        if dt > 0:
            for tr in self._tracks:
                tr.x, tr.P = kalman_predict(tr.x, tr.P, dt, cfg.accel_std)
        free = np.ones(Z.shape[0], dtype=bool)
        seen: set[int] = set()
        for group in (
            [tr for tr in self._tracks if tr.confirmed],
            [tr for tr in self._tracks if not tr.confirmed],
        ):
            cand = np.flatnonzero(free)
            if not group or cand.size == 0:
                continue
            pred = np.array([tr.x[:2] for tr in group])
            dist = np.hypot(pred[:, None, 0] - Z[None, cand, 0], pred[:, None, 1] - Z[None, cand, 1])
            big = cfg.gate * 1e3 + 1.0
            rows, cols = linear_sum_assignment(np.where(dist > cfg.gate, big, dist))
            for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
                if dist[r, c] > cfg.gate:
                    continue
                tr = group[r]
                z = Z[cand[c]]
                tr.x, tr.P = kalman_update(tr.x, tr.P, z, cfg.meas_std)
                tr.hits += 1
                tr.misses = 0
                tr.last_seen = t
                free[cand[c]] = False
                seen.add(id(tr))
        survivors: list[_RefTrack] = []
        for tr in self._tracks:
            if id(tr) not in seen:
                tr.misses += 1
            tr.age += 1
            if tr.confirmed:
                if tr.misses <= cfg.max_misses:
                    survivors.append(tr)
            elif tr.misses < cfg.tentative_misses:
                if tr.hits >= cfg.confirm_hits:
                    tr.id = self._next_id
                    self._next_id += 1
                survivors.append(tr)
        for z in Z[free]:
            P0 = np.diag([cfg.meas_std**2, cfg.meas_std**2, cfg.init_speed_std**2, cfg.init_speed_std**2])
            tr = _RefTrack(x=np.array([z[0], z[1], 0.0, 0.0]), P=P0, born=t, last_seen=t)
            if cfg.confirm_hits <= 1:
                tr.id = self._next_id
                self._next_id += 1
            survivors.append(tr)
        self._tracks = survivors
        return self.tracks()


# ----------------------------------------------------------------------------------------
# Comparisons
# ----------------------------------------------------------------------------------------

TOL = 1e-9


def assert_same_segmentation(a: Segmentation, b: Segmentation) -> None:
    assert a.n_beams == b.n_beams
    for name in ("index", "start", "stop"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype == np.intp, name
        np.testing.assert_array_equal(x, y, err_msg=name)
    np.testing.assert_array_equal(a.ranges, b.ranges)
    assert a.points.shape == b.points.shape and a.points.dtype == b.points.dtype
    np.testing.assert_allclose(a.points, b.points, rtol=1e-15, atol=1e-15)
    assert (a.jump, a.angle_min, a.angle_increment) == (b.jump, b.angle_min, b.angle_increment)


def assert_same_features(new: FloatArray, ref: FloatArray) -> None:
    assert new.shape == ref.shape and new.dtype == ref.dtype == np.float64
    np.testing.assert_allclose(new, ref, rtol=TOL, atol=TOL)


def assert_same_tracks(new: list[TrackState], ref: list[TrackState]) -> None:
    key = [(s.id, s.hits, s.misses, s.age, s.first_seen, s.last_seen) for s in new]
    assert key == [(s.id, s.hits, s.misses, s.age, s.first_seen, s.last_seen) for s in ref]
    for a, b in zip(new, ref, strict=True):
        np.testing.assert_allclose(a.position, b.position, rtol=TOL, atol=TOL)
        np.testing.assert_allclose(a.velocity, b.velocity, rtol=TOL, atol=TOL)
        assert a.covariance.shape == (4, 4)
        np.testing.assert_allclose(a.covariance, b.covariance, rtol=TOL, atol=TOL)


# ----------------------------------------------------------------------------------------
# Random scans
# ----------------------------------------------------------------------------------------

NO_RETURN = (np.inf, -np.inf, np.nan, 0.0, -1.0, 0.004)


def random_scan(
    rng: np.random.Generator, n_beams: int, inc: float, range_max: float, dropout: float
) -> FloatArray:
    """A scan of walls (straight, in polar form), leg-sized circles, clutter and no-returns."""
    angles = np.arange(n_beams) * inc
    r = np.full(n_beams, np.inf)
    b = 0
    while b < n_beams:
        width = int(rng.integers(1, max(2, n_beams // 2)))
        kind = rng.integers(0, 4)
        seg = slice(b, min(n_beams, b + width))
        th = angles[seg]
        if kind == 0:  # a straight wall: exactly collinear end points up to rounding
            d0 = rng.uniform(0.3, range_max * 0.8)
            phi = th[0] + rng.uniform(-1.2, 1.2)
            r[seg] = d0 / np.maximum(np.cos(th - phi), 0.05)
        elif kind == 1:  # a leg: a circle of 4–8 cm radius
            d0 = rng.uniform(0.2, 8.0)
            rad = rng.uniform(0.04, 0.08)
            off = (th - th.mean()) * d0
            r[seg] = d0 - np.sqrt(np.maximum(rad**2 - off**2, 0.0)) + rng.normal(0, 0.003, th.size)
        elif kind == 2:  # clutter
            r[seg] = rng.uniform(0.05, range_max * 1.1, th.size)
        b += width
    drop = rng.random(n_beams) < dropout
    r[drop] = rng.choice(NO_RETURN, int(drop.sum()))
    if rng.random() < 0.3:  # centimetre ranges, as an LMS gives them: repeated values
        r = np.round(r, 2)
    return r


scan_params = st.fixed_dictionaries(
    {
        "seed": st.integers(0, 2**32 - 1),
        "n_beams": st.integers(1, 720),
        "inc": st.sampled_from([0.0043633, 0.0061359, 0.0087266, 0.0174533, 0.05]),
        "angle_min": st.floats(-3.2, 3.2),
        "range_max": st.sampled_from([4.0, 11.0, 30.0]),
        "range_min": st.sampled_from([0.0, 0.0, 0.02]),
        "jump": st.sampled_from([0.05, 0.15, 0.15, 0.5, 3.0]),
        "max_gap": st.sampled_from([None, None, 0, 1, 3]),
        "dropout": st.sampled_from([0.0, 0.02, 0.2, 0.6]),
    }
)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(p=scan_params, with_prev=st.booleans())
def test_segmentation_and_features_equal_the_reference_on_random_scans(p: dict, with_prev: bool) -> None:
    rng = np.random.default_rng(p["seed"])
    r = random_scan(rng, p["n_beams"], p["inc"], p["range_max"], p["dropout"])
    kw = dict(range_max=p["range_max"], range_min=p["range_min"], jump=p["jump"], max_gap=p["max_gap"])
    seg = segment_scan(r, p["angle_min"], p["inc"], **kw)
    ref = ref_segment_scan(r, p["angle_min"], p["inc"], **kw)
    assert_same_segmentation(seg, ref)
    prev, dt = None, None
    if with_prev:
        prev = random_scan(rng, p["n_beams"], p["inc"], p["range_max"], p["dropout"])
        dt = float(rng.uniform(0.01, 0.5))
    fk = dict(range_max=p["range_max"], range_min=p["range_min"], previous=prev, dt=dt)
    X = segment_features(ref, **fk)
    assert_same_features(X, ref_segment_features(ref, **fk))
    X2, centre = feat._features(ref, **fk)
    np.testing.assert_array_equal(X2, X)
    np.testing.assert_array_equal(centre, ref.centroids())


@pytest.mark.parametrize("n", [1, 2, 7, 8, 9, 16, 17, 128, 129, 130, 257, 300, 1031, 3000])
def test_group_sums_follow_numpys_summation_order(n: int, rng: np.random.Generator) -> None:
    """The kernel's sums are numpy's ``reduceat`` sums bit for bit (pairwise order, recursion above 128)."""
    for scale in (1e-3, 1.0, 1e4):
        a = rng.normal(size=n) * scale + rng.normal() * scale
        assert feat._group_sum(a, n) == np.add.reduceat(a, [0])[0]


@settings(max_examples=150, deadline=None)
@given(
    values=st.lists(
        st.one_of(st.sampled_from([-1.0, -0.0, 0.0, 0.5, 2.0]), st.floats(-1e6, 1e6)), min_size=1, max_size=80
    )
)
def test_median_is_numpys_median(values: list[float]) -> None:
    """The kernel's quickselect median, with many ties among the values."""
    a = np.array(values)
    assert feat._median(a, a.size, np.empty(a.size)) == np.median(a)
    np.testing.assert_array_equal(a, values)  # the input is left alone


def test_long_segments_and_degenerate_geometry_equal_the_reference() -> None:
    """Walls of hundreds of points (the pairwise sums' recursion), exactly collinear points,
    two-point and one-point segments, repeated ranges."""
    inc = 0.004363323129985824
    B = 1000
    th = -2.0 + np.arange(B) * inc
    r = 1.5 / np.cos(th - 0.3)  # one straight wall, hundreds of points
    r[np.abs(th - 0.3) > 1.3] = np.inf
    r[500] = 0.7  # a one-point segment inside the wall
    r[600:602] = 0.5  # a two-point one
    r[700:760] = 2.0  # an arc of equal ranges
    for ranges in (r, np.round(r, 2)):
        seg = ref_segment_scan(ranges, -2.0, inc, range_max=30.0)
        assert seg.sizes.max() > 256 and 1 in seg.sizes and 2 in seg.sizes
        assert_same_segmentation(segment_scan(ranges, -2.0, inc, range_max=30.0), seg)
        assert_same_features(
            segment_features(seg, range_max=30.0, previous=ranges[::-1], dt=0.1),
            ref_segment_features(seg, range_max=30.0, previous=ranges[::-1], dt=0.1),
        )


def test_feature_errors_are_unchanged() -> None:
    r = np.full(20, 2.0)
    seg = segment_scan(r, 0.0, 0.01, range_max=5.0)
    for kw in (
        dict(previous=r[:5], dt=0.1),
        dict(previous=r, dt=None),
        dict(previous=r, dt=0.0),
        dict(previous=r, dt=math.nan),
        dict(previous=r.reshape(4, 5), dt=0.1),
    ):
        with pytest.raises(ValueError) as new:
            segment_features(seg, range_max=5.0, **kw)
        with pytest.raises(ValueError) as ref:
            ref_segment_features(seg, range_max=5.0, **kw)
        assert str(new.value) == str(ref.value)
    # a scan without segments checks nothing, as before
    empty = segment_scan(np.zeros(20), 0.0, 0.01, range_max=5.0)
    assert segment_features(empty, range_max=5.0, previous=r[:3], dt=None).shape == (0, N_FEATURES)


# ----------------------------------------------------------------------------------------
# Pairing
# ----------------------------------------------------------------------------------------


def assert_same_people(a: People, b: People) -> None:
    assert a.positions.dtype == b.positions.dtype == np.float64 and a.legs.dtype == b.legs.dtype == np.intp
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.legs, b.legs)
    assert a.positions.shape == b.positions.shape and a.legs.shape == b.legs.shape


@settings(max_examples=150, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    k=st.integers(0, 14),
    spread=st.sampled_from([0.3, 1.0, 4.0]),
    grid=st.booleans(),
    max_distance=st.sampled_from([0.2, 0.6, 1.0]),
    lone_legs=st.sampled_from(LONE_LEG_POLICIES),
)
def test_pairing_equals_the_reference(
    seed: int, k: int, spread: float, grid: bool, max_distance: float, lone_legs: str
) -> None:
    """Random legs; on a 10 cm grid many distances tie exactly (the stable order decides)."""
    rng = np.random.default_rng(seed)
    L = rng.uniform(-spread, spread, (k, 2))
    if grid:
        L = np.round(L, 1)
    kw = dict(max_distance=max_distance, lone_legs=lone_legs)
    assert_same_people(pair_legs(L, **kw), ref_pair_legs(L, **kw))  # type: ignore[arg-type]
    assert_same_people(pair_legs(L.tolist(), **kw), ref_pair_legs(L.tolist(), **kw))  # type: ignore[arg-type]


def test_pairing_errors_and_empty_inputs_are_unchanged() -> None:
    for legs in ([], np.zeros((0, 2)), [1.0, 2.0], [[1.0, 2.0], [1.3, 2.0], [1.0, 2.0]]):
        for lone in LONE_LEG_POLICIES:
            assert_same_people(pair_legs(legs, lone_legs=lone), ref_pair_legs(legs, lone_legs=lone))
    for kw in (dict(max_distance=0.0), dict(max_distance=math.nan), dict(lone_legs="keep")):
        with pytest.raises(ValueError) as new:
            pair_legs([[0.0, 0.0]], **kw)
        with pytest.raises(ValueError) as ref:
            ref_pair_legs([[0.0, 0.0]], **kw)
        assert str(new.value) == str(ref.value)


# ----------------------------------------------------------------------------------------
# Tracking
# ----------------------------------------------------------------------------------------

tracker_configs = st.builds(
    TrackerConfig,
    gate=st.sampled_from([0.3, 0.6, 1.5]),
    confirm_hits=st.integers(1, 4),
    tentative_misses=st.integers(1, 3),
    max_misses=st.integers(1, 6),
    accel_std=st.sampled_from([0.5, 2.0]),
    meas_std=st.sampled_from([0.03, 0.08, 0.3]),
    init_speed_std=st.sampled_from([0.5, 1.0]),
)


def detection_sequence(rng: np.random.Generator, n_scans: int) -> list[tuple[float, FloatArray]]:
    """Walkers that appear, move, hide and leave, plus clutter; irregular scan times (also
    repeated ones, dt = 0)."""
    walkers: list[list[float]] = []  # x, y, vx, vy, scans left
    t = float(rng.uniform(0, 100))
    out = []
    for _ in range(n_scans):
        t += float(rng.choice([0.0, 0.05, 0.1, 0.1, 0.1, rng.uniform(0.01, 0.6)]))
        if rng.random() < 0.15 or not walkers:
            walkers.append([*rng.uniform(-5, 5, 2), *rng.normal(0, 0.8, 2), float(rng.integers(1, 60))])
        dets = []
        for w in walkers:
            w[0] += w[2] * 0.1
            w[1] += w[3] * 0.1
            w[4] -= 1
            if rng.random() < 0.8:
                dets.append([w[0] + rng.normal(0, 0.05), w[1] + rng.normal(0, 0.05)])
        walkers = [w for w in walkers if w[4] > 0]
        dets += rng.uniform(-6, 6, (int(rng.integers(0, 3)), 2)).tolist()
        order = rng.permutation(len(dets))
        out.append((t, np.array(dets).reshape(-1, 2)[order]))
    return out


@pytest.mark.slow
@settings(max_examples=30, deadline=None)
@given(cfg=tracker_configs, seed=st.integers(0, 2**32 - 1))
def test_tracker_equals_the_reference_on_long_random_sequences(cfg: TrackerConfig, seed: int) -> None:
    rng = np.random.default_rng(seed)
    new, ref = PeopleTracker(cfg), RefTracker(cfg)
    n_confirmed = 0
    for k, (t, Z) in enumerate(detection_sequence(rng, 150)):
        a, b = new.update(Z, t), ref.update(Z, t)
        assert_same_tracks(a, b)
        n_confirmed = max(n_confirmed, len(a))
        if k % 10 == 0:
            assert_same_tracks(new.tracks(include_tentative=True), ref.tracks(include_tentative=True))
        if k == 100:
            new.reset()
            ref.reset()
    assert new._next_id == ref._next_id
    assert n_confirmed > 0  # the sequences exercise confirmed tracks, not only births


def test_tracker_errors_are_unchanged() -> None:
    for args in (([[math.nan, 0.0]], 0.0), ([[0.0, 0.0]], math.inf)):
        with pytest.raises(ValueError) as new:
            PeopleTracker().update(*args)
        with pytest.raises(ValueError) as ref:
            RefTracker().update(*args)
        assert str(new.value) == str(ref.value)
    tr, rt = PeopleTracker(), RefTracker()
    tr.update([[1.0, 1.0]], 5.0)
    rt.update([[1.0, 1.0]], 5.0)
    with pytest.raises(ValueError) as new:
        tr.update([], 4.0)
    with pytest.raises(ValueError) as ref:
        rt.update([], 4.0)
    assert str(new.value) == str(ref.value)


def test_ties_between_detections_go_where_the_hungarian_method_puts_them() -> None:
    """Two detections at the same distance from one track: the shortcut for a single row
    must not decide, the Hungarian method does, as before."""
    cfg = TrackerConfig(confirm_hits=1)
    for dets in ([[1.0, 0.2], [1.0, -0.2]], [[1.0, -0.2], [1.0, 0.2]], [[0.8, 0.0], [1.2, 0.0], [1.0, 0.0]]):
        new, ref = PeopleTracker(cfg), RefTracker(cfg)
        for t, Z in ((0.0, [[1.0, 0.0]]), (0.0, dets), (0.0, dets[::-1])):
            assert_same_tracks(new.update(Z, t), ref.update(Z, t))
            assert_same_tracks(new.tracks(include_tentative=True), ref.tracks(include_tentative=True))


def test_reported_states_are_the_callers_to_change() -> None:
    """Writing into a reported state's arrays changes neither the tracker nor other states."""
    new, ref = PeopleTracker(TrackerConfig(confirm_hits=1)), RefTracker(TrackerConfig(confirm_hits=1))
    for t, Z in ((0.0, [[1.0, 0.0], [3.0, 0.0]]), (0.1, [[1.1, 0.0], [3.0, 0.1]])):
        states = new.update(Z, t)
        ref.update(Z, t)
        for s in states:
            s.position[:] = 99.0
            s.velocity[:] = 99.0
            s.covariance[:] = 99.0
    assert_same_tracks(new.tracks(), ref.tracks())
    assert_same_tracks(new.update([[1.2, 0.0]], 0.2), ref.update([[1.2, 0.0]], 0.2))


# ----------------------------------------------------------------------------------------
# Real scans
# ----------------------------------------------------------------------------------------


def ref_people_frame(
    det: LegDetector, ranges: FloatArray, pose: tuple[float, float, float], geo: dict
) -> tuple[SegmentDetection, FloatArray]:
    """The reference detection of one scan and its people's positions in the tracking frame."""
    d = ref_detect(det, ranges, **geo)
    legs = to_frame(d.segmentation.centroids()[d.is_person], pose)
    people = ref_pair_legs(legs)
    return d, people.positions


@pytest.fixture(scope="module")
def detector() -> LegDetector:
    return LegDetector.load()


def test_pipeline_equals_the_reference_on_the_agents_drive(detector: LegDetector) -> None:
    """The agent benchmark's drive (furniture legs that become tracks): detections, features
    and tracks of the new pipeline equal the reference chain's, scan by scan."""
    from sim.drives import DriveScans

    drive = DriveScans()
    chunk = drive.take(250)
    # the reference chain has the plain tracker: no static cells, no free-space evidence, no score floor
    pipe = PeoplePipeline(detector, tracker=TrackerConfig(), static=None, min_seen_through=0, min_score=None)
    tracker = RefTracker()
    n_tracks = n_legs = 0
    for i in range(len(chunk)):
        scan = drive.scan(chunk, i)
        o = chunk.odom[i]
        pose = (float(o.x), float(o.y), float(o.theta))
        frame = pipe.process_scan(scan, sensor_pose=pose)
        geo = dict(
            angle_min=scan.angle_min,
            angle_increment=scan.angle_increment,
            range_max=scan.range_max,
            range_min=float(getattr(scan, "range_min", 0.0)),
        )
        d, people = ref_people_frame(detector, np.asarray(scan.ranges, dtype=np.float64), pose, geo)
        assert_same_segmentation(frame.detection.segmentation, d.segmentation)
        assert_same_features(frame.detection.features, d.features)
        np.testing.assert_array_equal(frame.detection.is_person, d.is_person)
        np.testing.assert_allclose(frame.detection.score, d.score, rtol=TOL, atol=TOL)
        np.testing.assert_array_equal(frame.detection.beam_labels, d.beam_labels)
        np.testing.assert_array_equal(frame.people.positions, people)
        assert_same_tracks(frame.tracks, tracker.update(people, float(scan.stamp)))
        n_tracks = max(n_tracks, len(frame.tracks))
        n_legs += int(d.is_person.sum())
    assert n_legs > 0 and n_tracks > 0


def test_detector_equals_the_reference_on_the_legs_data(shared_data: Path, detector: LegDetector) -> None:
    """Real people (positive_6) and real clutter (negative_2, rear laser), with C.14 from the
    scan before: the same features and the same classifications."""
    from knowledge.people import dataset as ds

    legs = ds.find_legs_dir(shared_data)
    n_people = 0
    for name in ("positive_6_extracted.training_scan.npz", "negative_2.rear_scan.npz"):
        rec = ds.load_recording(legs / name)
        geo = dict(
            angle_min=rec.angle_min,
            angle_increment=rec.angle_increment,
            range_max=rec.range_max,
            range_min=rec.range_min,
        )
        for k in range(1, min(rec.n_scans, 150)):
            new = detector.detect(rec.ranges[k], previous=rec.ranges[k - 1], dt=rec.period, **geo)
            ref = ref_detect(detector, rec.ranges[k], previous=rec.ranges[k - 1], dt=rec.period, **geo)
            assert_same_segmentation(new.segmentation, ref.segmentation)
            assert_same_features(new.features, ref.features)
            np.testing.assert_array_equal(new.is_person, ref.is_person)
            np.testing.assert_allclose(new.score, ref.score, rtol=TOL, atol=TOL)
            n_people += int(new.is_person.sum())
    assert n_people > 0
