"""Segment features C.1–C.14 on hand-made segments, against analytic values and slow definitions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize_scalar

from knowledge.people.features import FEATURE_CODES, MAX_RADIUS, N_FEATURES, segment_features
from knowledge.people.segmentation import segment_scan

INC = math.radians(0.5)
RMAX = 20.0
col = {code: i for i, code in enumerate(FEATURE_CODES)}


def scan_of_points(points: np.ndarray, *, inc: float = INC) -> tuple[np.ndarray, float]:
    """Ranges of a scan whose beams hit exactly ``points`` (in increasing bearing, on beam
    directions); beams between them have no return (range 0)."""
    bearings = np.arctan2(points[:, 1], points[:, 0])
    steps = (bearings - bearings[0]) / inc
    assert np.allclose(steps, np.round(steps), atol=1e-6), "points must lie on beam directions"
    idx = np.round(steps).astype(int)
    r = np.zeros(idx[-1] + 1)
    r[idx] = np.hypot(points[:, 0], points[:, 1])
    return r, float(bearings[0])


def features_of(points: np.ndarray) -> np.ndarray:
    """Features of a single segment made of ``points`` that lie on consecutive beams."""
    r, a0 = scan_of_points(points)
    seg = segment_scan(r, a0, INC, range_max=RMAX, jump=10.0)
    assert seg.n_segments == 1
    return segment_features(seg, range_max=RMAX)[0]


def on_beams(ranges_of_bearing: object, bearings: np.ndarray) -> np.ndarray:
    r = np.array([ranges_of_bearing(b) for b in bearings])  # type: ignore[operator]
    return np.column_stack([r * np.cos(bearings), r * np.sin(bearings)])


def circle_points(cx: float, cy: float, R: float, n: int) -> np.ndarray:
    """The near side of a circle as seen from the origin, hit by ``n`` consecutive beams."""
    d = math.hypot(cx, cy)
    half = math.asin(R / d) * 0.8
    centre = math.atan2(cy, cx)
    bearings = centre + (np.arange(n) - (n - 1) / 2) * min(INC, 2 * half / max(n - 1, 1))
    # re-grid on the beam lattice so the points lie exactly on beams
    bearings = np.round(bearings / INC) * INC
    bearings = np.unique(bearings)

    def hit(b: float) -> float:
        ux, uy = math.cos(b), math.sin(b)
        proj = ux * cx + uy * cy
        disc = proj**2 - (cx**2 + cy**2 - R**2)
        return proj - math.sqrt(disc)

    return on_beams(hit, bearings)


# -- slow, literal definitions --------------------------------------------------------------


def slow_line_rss(P: np.ndarray) -> float:
    """C.7 by brute force: min over the normal direction φ of Σ (x cos φ + y sin φ − r)², r optimal."""

    def rss(phi: float) -> float:
        proj = P[:, 0] * math.cos(phi) + P[:, 1] * math.sin(phi)
        return float(((proj - proj.mean()) ** 2).sum())

    grid = np.linspace(0, math.pi, 721)
    best = grid[np.argmin([rss(p) for p in grid])]
    res = minimize_scalar(rss, bounds=(best - 0.01, best + 0.01), method="bounded", options={"xatol": 1e-12})
    return float(res.fun)


def slow_circle(P: np.ndarray) -> tuple[float, float]:
    """C.8/C.9 exactly as printed (eq. C.8–C.10, uncentred, pseudo-inverse)."""
    A = np.column_stack([-2 * P[:, 0], -2 * P[:, 1], np.ones(len(P))])
    b = -(P[:, 0] ** 2 + P[:, 1] ** 2)
    xc, yc, c = np.linalg.pinv(A) @ b
    rc = math.sqrt(xc**2 + yc**2 - c)
    circ = float(sum((rc - math.hypot(xc - x, yc - y)) ** 2 for x, y in P))
    return circ, rc


def slow_features(P: np.ndarray) -> dict[str, float]:
    n = len(P)
    out: dict[str, float] = {"C.1": n}
    mean = P.mean(axis=0)
    out["C.2"] = math.sqrt(sum(float(np.dot(p - mean, p - mean)) for p in P) / n)
    # C.3 in axes along / across the mean bearing (see knowledge.people.features)
    th = math.atan2(mean[1], mean[0])
    rot = np.array([[math.cos(th), math.sin(th)], [-math.sin(th), math.cos(th)]])
    Q = P @ rot.T
    med = np.array([np.median(Q[:, 0]), np.median(Q[:, 1])])
    out["C.3"] = sum(math.hypot(*(q - med)) for q in Q) / n
    out["C.6"] = math.hypot(*(P[0] - P[-1]))
    out["C.7"] = slow_line_rss(P)
    out["C.8"], out["C.9"] = slow_circle(P)
    d = [math.hypot(*(P[i] - P[i + 1])) for i in range(n - 1)]
    out["C.10"] = sum(d)
    dbar = sum(d) / len(d)
    out["C.11"] = math.sqrt(sum((x - dbar) ** 2 for x in d) / len(d))
    ks, betas = [], []
    for j in range(1, n - 1):
        a, b, c = P[j - 1], P[j], P[j + 1]
        area = 0.5 * abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
        ks.append(4 * area / (math.dist(a, b) * math.dist(b, c) * math.dist(a, c)))
        ang_u = math.atan2(b[1] - a[1], b[0] - a[0])
        ang_v = math.atan2(c[1] - b[1], c[0] - b[0])
        beta = (ang_v - ang_u + math.pi) % (2 * math.pi) - math.pi  # unwrap into [−π, π)
        betas.append(beta)
    out["C.12"] = sum(ks) / len(ks)
    out["C.13"] = sum(betas) / len(betas)
    return out


# -- analytic cases --------------------------------------------------------------------------


def test_circle_arc_radius_circularity_curvature() -> None:
    R = 0.08
    P = circle_points(2.0, 0.3, R, 15)
    f = features_of(P)
    assert f[col["C.1"]] == len(P) >= 7
    assert f[col["C.9"]] == pytest.approx(R, rel=1e-6)
    assert f[col["C.8"]] == pytest.approx(0.0, abs=1e-12)
    assert f[col["C.12"]] == pytest.approx(1.0 / R, rel=1e-6)  # three points on a circle: k = 1/R
    assert f[col["C.7"]] > 1e-6  # an arc is not straight
    # the near side of a leg, traversed in beam order, turns clockwise
    assert f[col["C.13"]] < 0


def test_straight_wall_is_linear_with_no_curvature() -> None:
    bearings = np.arange(-20, 21) * INC
    P = on_beams(lambda b: 3.0 / math.cos(b), bearings)  # the wall x = 3 m
    f = features_of(P)
    assert f[col["C.7"]] == pytest.approx(0.0, abs=1e-20)
    assert f[col["C.12"]] == pytest.approx(0.0, abs=1e-9)
    assert f[col["C.13"]] == pytest.approx(0.0, abs=1e-9)
    assert f[col["C.9"]] == MAX_RADIUS  # a line is a circle of "infinite" radius
    assert f[col["C.8"]] == pytest.approx(f[col["C.7"]], abs=1e-20)
    assert f[col["C.6"]] == pytest.approx(P[-1, 1] - P[0, 1])
    assert f[col["C.10"]] == pytest.approx(f[col["C.6"]], rel=1e-12)


def test_two_points() -> None:
    P = on_beams(lambda b: 2.0, np.array([0.0, INC]))
    f = features_of(P)
    w = math.dist(P[0], P[1])
    assert f[col["C.1"]] == 2
    assert f[col["C.2"]] == pytest.approx(w / 2)
    assert f[col["C.3"]] == pytest.approx(w / 2)  # the median of two values is their mean
    assert f[col["C.6"]] == pytest.approx(w)
    assert f[col["C.7"]] == pytest.approx(0.0, abs=1e-15)
    assert f[col["C.8"]] == 0.0
    assert f[col["C.9"]] == pytest.approx(w / 2)  # the smallest circle through both
    assert f[col["C.10"]] == pytest.approx(w)
    assert f[col["C.11"]] == 0.0
    assert f[col["C.12"]] == 0.0
    assert f[col["C.13"]] == 0.0


def test_one_point_is_all_zero_but_the_count() -> None:
    f = features_of(np.array([[2.0, 0.0]]))
    assert f[col["C.1"]] == 1
    others = [i for i in range(N_FEATURES) if FEATURE_CODES[i] not in ("C.1", "C.4", "C.5")]
    assert np.all(f[others] == 0.0)


def test_boundary_regularity_of_alternating_spacing() -> None:
    # points along a line at alternating spacings a, b: the spacing deviations are ±(a − b)/2
    bearings = np.array([0, 1, 3, 4, 6, 7, 9]) * INC
    P = on_beams(lambda b: 4.0 / math.cos(b), bearings)
    f = features_of(np.array(P))
    steps = np.hypot(*np.diff(P, axis=0).T)
    assert f[col["C.11"]] == pytest.approx(np.std(steps), rel=1e-9)
    assert f[col["C.11"]] > 0.5 * (steps.max() - steps.min()) * 0.9


def test_jump_distances_to_neighbouring_segments() -> None:
    r = np.array([2.0] * 5 + [3.0] * 5 + [2.5] * 5)
    seg = segment_scan(r, 0.0, INC, range_max=RMAX)
    assert seg.n_segments == 3
    f = segment_features(seg, range_max=RMAX)
    P = seg.points
    assert f[0, col["C.4"]] == RMAX  # nothing before the first segment
    assert f[2, col["C.5"]] == RMAX
    assert f[1, col["C.4"]] == pytest.approx(math.dist(P[4], P[5]))
    assert f[0, col["C.5"]] == pytest.approx(math.dist(P[4], P[5]))
    assert f[1, col["C.5"]] == pytest.approx(math.dist(P[9], P[10]))
    assert f[2, col["C.4"]] == pytest.approx(math.dist(P[9], P[10]))


@pytest.mark.parametrize("no_return", [0.0, np.inf, RMAX, 0.008])
def test_jump_beside_a_beam_without_return_is_the_jump_to_open_space(no_return: float) -> None:
    # two objects at 2 m, 13 beams apart (23 cm): between them the beams see nothing
    r = np.array([2.0] * 5 + [no_return] * 12 + [2.0] * 5 + [2.4] * 3)
    seg = segment_scan(r, 0.0, INC, range_max=RMAX, range_min=0.02)
    assert seg.sizes.tolist() == [5, 5, 3]
    f = segment_features(seg, range_max=RMAX, range_min=0.02)
    P = seg.points

    def at_range_max(beam: int) -> np.ndarray:
        return RMAX * np.array([math.cos(beam * INC), math.sin(beam * INC)])

    # the beam after the first object has no return: the jump is to its end point at range_max
    assert f[0, col["C.5"]] == pytest.approx(math.dist(P[4], at_range_max(5)))
    assert f[1, col["C.4"]] == pytest.approx(math.dist(P[5], at_range_max(16)))
    assert f[0, col["C.5"]] > RMAX - 2.0 - 1e-9  # not the 0.23 m to the next object
    # a neighbouring beam with a return is the neighbouring segment's end point (eq. C.4/C.5)
    assert f[1, col["C.5"]] == pytest.approx(math.dist(P[9], P[10]))
    assert f[2, col["C.4"]] == pytest.approx(math.dist(P[9], P[10]))
    assert f[0, col["C.4"]] == RMAX and f[2, col["C.5"]] == RMAX  # the ends of the scan


def test_mean_speed_between_two_scans() -> None:
    prev = np.array([2.0] * 5 + [5.0] * 5)
    cur = np.array([1.9] * 5 + [5.0, 5.0, 0.0, 5.0, 5.0])  # a no-return beam in the second segment
    seg = segment_scan(cur, 0.0, INC, range_max=RMAX)
    f = segment_features(seg, range_max=RMAX, previous=prev, dt=0.1)
    assert f[0, col["C.14"]] == pytest.approx(-1.0)  # approaching at 1 m/s
    assert f[1, col["C.14"]] == pytest.approx(0.0)
    # a beam with no return in the previous scan does not count
    prev2 = prev.copy()
    prev2[0] = np.inf
    cur2 = cur.copy()
    f2 = segment_features(
        segment_scan(cur2, 0.0, INC, range_max=RMAX), range_max=RMAX, previous=prev2, dt=0.1
    )
    assert f2[0, col["C.14"]] == pytest.approx(-1.0)
    # without a previous scan C.14 is 0; with one, dt is required
    assert segment_features(seg, range_max=RMAX)[0, col["C.14"]] == 0.0
    with pytest.raises(ValueError, match="dt"):
        segment_features(seg, range_max=RMAX, previous=prev, dt=None)
    with pytest.raises(ValueError, match="same sensor"):
        segment_features(seg, range_max=RMAX, previous=prev[:5], dt=0.1)


def test_empty_scan_has_no_segments() -> None:
    seg = segment_scan(np.zeros(10), 0.0, INC, range_max=RMAX)
    assert segment_features(seg, range_max=RMAX).shape == (0, N_FEATURES)


# -- against the slow definitions ------------------------------------------------------------


@pytest.mark.parametrize("seed", range(6))
def test_matches_slow_definitions_on_noisy_segments(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(4, 30))
    bearings = (np.arange(n) + rng.integers(-50, 50)) * INC
    base = rng.uniform(0.5, 6.0)
    r = base + 0.05 * np.sin(np.arange(n) * rng.uniform(0.1, 0.8)) + rng.normal(0, 0.01, n)
    P = np.column_stack([r * np.cos(bearings), r * np.sin(bearings)])
    f = features_of(P)
    slow = slow_features(P)
    for code in ("C.1", "C.2", "C.3", "C.6", "C.10", "C.11", "C.12", "C.13"):
        assert f[col[code]] == pytest.approx(slow[code], rel=1e-7, abs=1e-12), code
    assert f[col["C.7"]] == pytest.approx(slow["C.7"], rel=1e-5, abs=1e-14)
    if f[col["C.9"]] < MAX_RADIUS:
        assert f[col["C.9"]] == pytest.approx(slow["C.9"], rel=1e-5)
        assert f[col["C.8"]] == pytest.approx(slow["C.8"], rel=1e-4, abs=1e-12)


def test_many_segments_at_once_equal_one_at_a_time(rng: np.random.Generator) -> None:
    r = np.concatenate([rng.uniform(1, 1.02, 7), rng.uniform(4, 4.05, 12), [0.0], rng.uniform(2, 2.01, 3)])
    seg = segment_scan(r, -0.3, INC, range_max=RMAX)
    F = segment_features(seg, range_max=RMAX)
    for i in range(seg.n_segments):
        one = features_of(seg.segment_points(i))
        inner = [k for k in range(13) if FEATURE_CODES[k] not in ("C.4", "C.5")]
        np.testing.assert_allclose(F[i, inner], one[inner], rtol=1e-9, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(
    shift=st.integers(min_value=-400, max_value=400),
    seed=st.integers(min_value=0, max_value=10_000),
)
def test_rotating_the_scan_by_whole_beams_changes_no_feature(shift: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    r = np.repeat(rng.uniform(0.5, 8.0, 12), rng.integers(1, 9, 12)) + rng.normal(0, 0.01, 1)[0]
    r = r + rng.normal(0, 0.005, r.size)
    a = segment_scan(r, -1.0, INC, range_max=RMAX)
    b = segment_scan(r, -1.0 + shift * INC, INC, range_max=RMAX)
    prev = r + 0.05
    Fa = segment_features(a, range_max=RMAX, previous=prev, dt=0.1)
    Fb = segment_features(b, range_max=RMAX, previous=prev, dt=0.1)
    np.testing.assert_allclose(Fa, Fb, rtol=1e-6, atol=1e-9)
