"""Scan features of scenes whose values follow from geometry by hand.

Expected values are derived from the shapes (regular polygons, rectangles, corridors, door
frames), never from the feature code.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from knowledge.places.features import compute_features, default_feature_names, parse_name
from knowledge.places.features.synthetic import cast_rays, doorway_segments

M = 360
MAX_RANGE = 30.0
NAMES = default_feature_names()


def features(scan: np.ndarray, max_range: float = MAX_RANGE) -> dict[str, float]:
    values = compute_features(scan, NAMES, max_range=max_range)
    return {n: float(v) for n, v in zip(NAMES, values, strict=True)}


def rectangle_scan(width: float, height: float, x: float, y: float, num_beams: int = M) -> np.ndarray:
    """Beam lengths from (x, y) inside [0, width] × [0, height], beam i at i·2π/num_beams."""
    phi = np.arange(num_beams) * 2 * math.pi / num_beams
    c, s = np.cos(phi), np.sin(phi)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 1e-12, (width - x) / c, np.where(c < -1e-12, -x / c, np.inf))
        ty = np.where(s > 1e-12, (height - y) / s, np.where(s < -1e-12, -y / s, np.inf))
    return np.minimum(np.minimum(tx, ty), MAX_RANGE)


# ------------------------------------------------------------------ a round room, robot at the centre
@pytest.mark.parametrize("r", [0.8, 3.0, 7.5])
def test_circular_room(r: float) -> None:
    f = features(np.full(M, r))
    half = math.pi / M  # half the angle between beams
    for name in ("A.1", "A.2", "A.3[maxrange=1m]", "A.4[maxrange=5m]", "A.6", "A.12", "A.14", "B.5", "B.16"):
        assert f[name] == pytest.approx(0.0, abs=1e-6), name
    assert f["A.5"] == pytest.approx(r)
    assert f["A.11"] == pytest.approx(1.0) and f["A.13"] == pytest.approx(1.0)
    assert f["A.7[gap=0.05m]"] == 0 and f["A.15[ratio=1.05]"] == 0
    assert f["A.16"] == -3.0  # constant scan convention
    assert f["A.9"] == 0 and f["A.10"] == 0  # no minimum at all
    # the scan polygon is the inscribed regular 360-gon
    area = 0.5 * M * r * r * math.sin(2 * half)
    perimeter = 2 * M * r * math.sin(half)
    assert f["B.1"] == pytest.approx(area, rel=1e-6) and area == pytest.approx(math.pi * r * r, rel=1e-4)
    assert f["B.2"] == pytest.approx(perimeter, rel=1e-6) and perimeter == pytest.approx(
        2 * math.pi * r, rel=1e-4
    )
    assert f["B.3"] == pytest.approx(area / perimeter, rel=1e-6)
    assert f["B.4"] == pytest.approx(r, rel=1e-6) and f["B.15"] == pytest.approx(1.0, rel=1e-6)
    assert f["B.12"] == pytest.approx(4 * math.pi * area / math.sqrt(perimeter), rel=1e-6)
    assert f["B.13"] == pytest.approx(perimeter**2 / area, rel=1e-6)
    assert f["B.14"] == pytest.approx(math.pi / (M * math.tan(half)), rel=1e-6)
    assert f["B.14"] == pytest.approx(1.0, abs=1e-4)
    # Fourier: a regular M-gon only has c_n for n ≡ 1 (mod M); |c_1| = r·(sin(π/M)/(π/M))²
    assert max(f[n] for n in NAMES if n.startswith("B.6[")) < 1e-9
    c1 = r * (math.sin(half) / half) ** 2
    assert f["B.7"] == pytest.approx(c1, rel=1e-6) and f["B.8"] == pytest.approx(c1, rel=1e-6)
    assert f["B.7/B.8"] == pytest.approx(1.0, rel=1e-6)
    # vertex moments of M points on a circle: μ20 = μ02 = M r²/2, the rest vanish
    assert f["B.9[phi=1]"] == pytest.approx(r * r / M, rel=1e-5)
    for k in range(2, 8):
        assert abs(f[f"B.9[phi={k}]"]) < 1e-9 * max(1.0, r**6)
    assert f["B.10"] == pytest.approx(area / (M * r * r), rel=1e-5)
    assert f["B.11"] == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("r", [0.8, 3.0])
def test_circular_room_lines(r: float) -> None:
    """w consecutive end points on an arc: the best line is the chord direction, so the RMS
    residual is r·std(cos φ_k) over the window's angles φ_k."""
    f = features(np.full(M, r))
    for name in [n for n in NAMES if n.startswith("A.8[")]:
        w_param, eps = parse_name(name).params
        w = int(w_param)
        phis = (np.arange(w) - (w - 1) / 2) * 2 * math.pi / M
        rms = r * float(np.std(np.cos(phis)))
        assert abs(rms - eps) > 1e-4  # not on the decision boundary
        assert f[name] == (M if rms <= eps else 0), name


def test_off_centre_in_a_round_room_has_one_minimum() -> None:
    R, a = 4.0, 1.5
    phi = np.arange(M) * 2 * math.pi / M
    scan = -a * np.cos(phi) + np.sqrt(R * R - (a * np.sin(phi)) ** 2)  # robot at (a, 0)
    f = features(scan)
    assert f["A.9"] == 0 and f["A.10"] == 0  # only the wall point nearest to the robot
    assert f["A.5"] == pytest.approx(float(scan.mean()))
    assert f["B.1"] == pytest.approx(math.pi * R * R, rel=1e-3)
    assert f["B.14"] == pytest.approx(1.0, abs=1e-3)
    assert max(f[n] for n in NAMES if n.startswith("B.6[")) < 1e-3  # still nearly a circle


# ------------------------------------------------------------------ rectangles
def _rectangle_coefficient(width: float, height: float, n: int, samples: int = 400_000) -> complex:
    """c_n = (1/T)∫ z(t) e^{−j2πnt/T} dt over the boundary, by the midpoint rule."""
    T = 2 * (width + height)
    t = (np.arange(samples) + 0.5) * T / samples
    corners = np.array([0, width, width + height, 2 * width + height, T])
    pts = [complex(0, 0), complex(width, 0), complex(width, height), complex(0, height), complex(0, 0)]
    k = np.searchsorted(corners, t, side="right") - 1
    start = np.array(pts)[k]
    direction = np.array([1, 1j, -1, -1j])[k]
    z = start + direction * (t - corners[k])
    return complex(np.mean(z * np.exp(-2j * math.pi * n * t / T)))


def test_centred_square() -> None:
    s = 6.0
    f = features(rectangle_scan(s, s, s / 2, s / 2))
    # mean over φ ∈ [−π/4, π/4] of (s/2)/cos φ = (2s/π)·ln(1 + √2)
    assert f["A.5"] == pytest.approx(2 * s / math.pi * math.log(1 + math.sqrt(2)), rel=1e-4)
    assert f["A.13"] == pytest.approx(f["A.5"] / (s / math.sqrt(2)), rel=1e-6)
    assert f["B.1"] == pytest.approx(s * s, rel=1e-6)  # beams 45° apart hit the corners exactly
    assert f["B.2"] == pytest.approx(4 * s, rel=1e-6)
    assert f["B.14"] == pytest.approx(math.pi / 4, rel=1e-5)
    assert f["B.11"] == pytest.approx(0.0, abs=1e-9)  # 4-fold symmetry: μ20 = μ02, μ11 = 0
    # 4-fold symmetry: c_n = 0 unless n ≡ 1 (mod 4)
    for n in (-1, 2, -2, 3, 4, -4, 6, 7):
        assert f[f"B.6[n={n}]"] < 1e-9, n
    for n in (-3, 5, -7, 9):
        assert f[f"B.6[n={n}]"] > 1e-3, n
    c1 = _rectangle_coefficient(s, s, 1)
    c3 = _rectangle_coefficient(s, s, -3)
    assert f["B.7"] == pytest.approx(abs(c1), rel=1e-5)
    assert f["B.7/B.8"] == pytest.approx(1.0, rel=1e-6)
    assert f["B.6[n=-3]"] == pytest.approx(abs(c3) / abs(c1), rel=1e-4)


def test_elongated_rectangle() -> None:
    # corners at ±20° and 180° ± 20° from the centre: beams hit them, so Pol(z) is the rectangle
    W = 10.0
    H = W * math.tan(math.radians(20))
    f = features(rectangle_scan(W, H, W / 2, H / 2))
    assert f["B.1"] == pytest.approx(W * H, rel=1e-6)
    assert f["B.2"] == pytest.approx(2 * (W + H), rel=1e-6)
    c1, cm1 = abs(_rectangle_coefficient(W, H, 1)), abs(_rectangle_coefficient(W, H, -1))
    assert f["B.7"] == pytest.approx(c1 + cm1, rel=1e-5)
    assert f["B.8"] == pytest.approx(c1 - cm1, rel=1e-5)
    assert f["B.7/B.8"] == pytest.approx((c1 + cm1) / (c1 - cm1), rel=1e-5) and f["B.7/B.8"] > 1.5
    assert f["B.6[n=3]"] == pytest.approx(abs(_rectangle_coefficient(W, H, 3)) / c1, rel=1e-4)
    # 2-fold symmetry: even orders vanish
    assert max(f[f"B.6[n={n}]"] for n in (2, -2, 4, -4, 10, -10)) < 1e-9
    assert f["B.11"] > 0.3
    # the two walls nearest to the robot: H/2 away on both sides, 180° apart
    assert f["A.9"] == pytest.approx(H, rel=1e-6) and f["A.10"] == pytest.approx(math.pi)


def test_corners_between_beams_are_cut() -> None:
    """Off-axis corners fall between two beams: the polygon loses a small triangle per corner."""
    W, H = 10.0, 3.0
    f = features(rectangle_scan(W, H, W / 2, H / 2))
    assert W * H * 0.99 < f["B.1"] < W * H
    assert 2 * (W + H) * 0.98 < f["B.2"] < 2 * (W + H)


def test_rotation_of_the_room_is_a_shift_of_the_beams() -> None:
    scan = rectangle_scan(7.0, 4.0, 2.0, 1.3)
    base = compute_features(scan, NAMES, max_range=MAX_RANGE)
    for k in (1, 45, 200):
        np.testing.assert_allclose(
            compute_features(np.roll(scan, k), NAMES, max_range=MAX_RANGE), base, rtol=2e-5, atol=1e-7
        )


# ------------------------------------------------------------------ a long corridor
def test_long_corridor() -> None:
    width, length = 2.0, 100.0
    scan = rectangle_scan(length, width, length / 2, width / 2)
    f = features(scan)
    # d = 1/|sin φ| m across the corridor; |sin φ| < 1/30 only for the beams at 0°, ±1°, 180°, 180° ± 1°
    assert int((scan >= MAX_RANGE).sum()) == 6
    assert f["A.3[maxrange=1m]"] == 0.0  # no beam is shorter than 1 m
    # jumps > 5 m: 1/sin 2° − 1/sin 3° = 9.5 m, 1/sin 3° − 1/sin 4° = 4.8 m, 30 − 1/sin 2° = 1.3 m,
    # so one gap on each side of each corridor direction
    assert f["A.7[gap=5m]"] == 4
    assert compute_features(scan, ["A.7[gap=10m]"], max_range=MAX_RANGE)[0] == 0
    # both walls at 1 m, 180° apart: the two (tied) minima
    assert f["A.9"] == pytest.approx(width) and f["A.10"] == pytest.approx(math.pi)
    assert f["B.7/B.8"] > 5  # an elongated ellipse
    assert f["A.13"] < 0.3


def test_corridor_off_centre() -> None:
    scan = rectangle_scan(100.0, 2.0, 50.0, 0.7)
    f = features(scan)
    assert f["A.9"] == pytest.approx(2.0) and f["A.10"] == pytest.approx(math.pi)


# ------------------------------------------------------------------ a door frame
@pytest.mark.parametrize(("y", "heading"), [(2.4, 0.0), (2.45, 1.0), (2.3, 2.5)])
def test_doorway(y: float, heading: float) -> None:
    """Robot in a 0.9 m door (y ∈ [2.0, 2.9]) of a 0.2 m thick wall between two rooms: the two
    jamb faces are the lowest local minima, straight up and down, so A.9 is the door width."""
    segs = np.array(doorway_segments((5.0, 6.0), (4.0, 6.0), (2.0, 2.9), 0.2))
    scan = cast_rays(
        np.array([[0.0, y]]), segs[None], num_beams=M, max_range=MAX_RANGE, headings=np.array([heading])
    )[0]
    f = features(scan)
    # with a heading that is not a multiple of 1°, the beams nearest to ±90° miss it by < 0.5°
    assert f["A.9"] == pytest.approx(0.9, abs=2e-3)
    assert f["A.10"] == pytest.approx(math.pi, abs=2 * math.pi / M)
