"""The compiled masking (knowledge/people/masking.py) gives what the plain-Python one gave.

The ``_reference_*`` functions below are the implementation of ``person_beams``,
``free_standing`` and ``fill_masked`` before they were compiled with numba (copied verbatim,
only renamed), kept here as the oracle: the property tests compare the two on generated scans
(NaN, no-return beams at ``range_max``, beams below ``range_min``, masked runs at the scan's
edges, full-turn scans, with and without the beams' angles), and on the scans and leg
detections of the agent benchmark's drive through a generated office.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.pipeline import PeopleParams, is_full_turn
from knowledge.people.detector import SegmentDetection
from knowledge.people.masking import fill_masked, free_standing, person_beams, unknown_masked
from knowledge.people.pipeline import PeoplePipeline
from knowledge.people.segmentation import BoolArray, FloatArray, has_return, segment_scan
from sim.drives import DriveScans
from sim.lms_world import ray_circle_ranges

# ------------------------------------------------------------------------------ the reference
_REF_WALL_POINTS = 4
_REF_WALL_TOLERANCE = 0.03


def _reference_free_standing(detection: SegmentDetection, clearance: float) -> BoolArray:
    seg = detection.segmentation
    idx, rr = seg.index, seg.ranges
    m = seg.n_points
    first, last = seg.start, seg.stop - 1

    def side_clear(end: npt.NDArray[np.intp], step: int) -> BoolArray:
        ok = np.ones(end.shape, dtype=bool)
        best = np.full(end.shape, -np.inf)
        adjacent = np.zeros(end.shape, dtype=bool)
        for k in (1, 2):
            nb = end + step * k
            inside = (nb >= 0) & (nb < m)
            nbc = np.clip(nb, 0, max(m - 1, 0))
            if k == 1:
                adjacent = inside & (np.abs(idx[nbc] - idx[end]) == 1)
            best = np.where(inside, np.maximum(best, rr[nbc]), best)
        ok = ~adjacent | (best - rr[end] >= clearance)
        return ok

    if seg.n_segments == 0:
        return np.zeros(0, dtype=bool)
    return side_clear(first, -1) & side_clear(last, 1)


def _reference_person_beams(
    detection: SegmentDetection, *, margin: int = 1, clearance: float | None = 0.2
) -> BoolArray:
    if margin < 0:
        raise ValueError(f"margin must be a number of beams >= 0, got {margin}")
    if clearance is not None and not clearance >= 0:
        raise ValueError(f"clearance must be None or a distance >= 0 metres, got {clearance}")
    seg = detection.segmentation
    flags = detection.is_person
    if clearance is not None and flags.any():
        flags = flags & _reference_free_standing(detection, clearance)
    mask = seg.beam_mask(flags)
    if margin == 0 or not mask.any():
        return mask
    owner = seg.beam_segment()  # (B,) segment of each beam, −1 without a return
    sizes = seg.sizes
    loose = np.ones(seg.n_beams, dtype=bool)  # beams the margin may take
    has = owner >= 0
    loose[has] = sizes[owner[has]] == 1
    grown = mask.copy()
    n = seg.n_beams
    for shift in range(1, margin + 1):
        left = np.zeros(n, dtype=bool)
        left[:-shift] = mask[shift:]  # beam m is `shift` beams before a person beam
        right = np.zeros(n, dtype=bool)
        right[shift:] = mask[:-shift]
        grown |= (left | right) & loose
    return _reference_connected(grown, mask)


def _reference_connected(grown: BoolArray, core: BoolArray) -> BoolArray:
    if grown.all() or not grown.any():
        return grown
    edges = np.flatnonzero(np.diff(grown.astype(np.int8)))
    starts = np.concatenate(([0], edges + 1))
    stops = np.concatenate((edges + 1, [grown.size]))
    out = np.zeros_like(grown)
    for a, b in zip(starts.tolist(), stops.tolist(), strict=True):
        if grown[a] and core[a:b].any():
            out[a:b] = True
    return out


def _reference_runs(mask: BoolArray) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    d = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return np.flatnonzero(d == 1).astype(np.intp), np.flatnonzero(d == -1).astype(np.intp)


def _reference_side_line(xs: list[float], ys: list[float]) -> tuple[float, float, float, float] | None:
    k = len(xs)
    if k < 2:
        return None
    cx, cy = sum(xs) / k, sum(ys) / k
    dx = [x - cx for x in xs]
    dy = [y - cy for y in ys]
    sxx = sum(v * v for v in dx)
    syy = sum(v * v for v in dy)
    sxy = sum(u * v for u, v in zip(dx, dy, strict=True))
    phi = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    ux, uy = math.cos(phi), math.sin(phi)
    along = [u * ux + v * uy for u, v in zip(dx, dy, strict=True)]
    if max(along) - min(along) < 0.05:
        return None
    if max(abs(v * ux - u * uy) for u, v in zip(dx, dy, strict=True)) > _REF_WALL_TOLERANCE:
        return None
    return cx, cy, ux, uy


def _reference_hit_line(
    cos: FloatArray, sin: FloatArray, line: tuple[float, float, float, float]
) -> FloatArray:
    cx, cy, ux, uy = line
    den = cos * uy - sin * ux
    num = cx * uy - cy * ux
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    return np.where(np.isfinite(t) & (t > 0), t, np.inf)


def _reference_fill_masked(
    ranges: npt.ArrayLike,
    mask: npt.ArrayLike,
    *,
    range_max: float,
    range_min: float = 0.0,
    circular: bool = False,
    angle_min: float = 0.0,
    angle_increment: float | None = None,
) -> FloatArray:
    r = np.array(ranges, dtype=np.float64)
    m = np.asarray(mask, dtype=bool)
    if r.ndim != 1 or m.shape != r.shape:
        raise ValueError(f"ranges and mask must be 1-D of the same length, got {r.shape} and {m.shape}")
    if not m.any():
        return r
    with np.errstate(invalid="ignore"):
        usable = ~m & ~np.isnan(r) & (r >= range_min) & (r > 0.0)
    hit = has_return(r, range_max, range_min)
    value = np.where(hit, r, range_max)
    idx = np.flatnonzero(usable)
    if idx.size == 0:
        return r
    n = r.size
    cos = sin = px = py = None
    if angle_increment is not None:
        theta = angle_min + np.arange(n, dtype=np.float64) * angle_increment
        cos, sin = np.cos(theta), np.sin(theta)
        with np.errstate(invalid="ignore"):
            px, py = r * cos, r * sin
    starts, stops = _reference_runs(m)
    out = r.copy()
    for a, b in zip(starts.tolist(), stops.tolist(), strict=True):
        k = int(np.searchsorted(idx, a))
        sides: list[npt.NDArray[np.intp]] = []
        if k > 0:
            sides.append(idx[max(0, k - _REF_WALL_POINTS) : k][::-1])
        elif circular:
            sides.append(idx[-_REF_WALL_POINTS:][::-1])
        if k < idx.size:
            sides.append(idx[k : k + _REF_WALL_POINTS])
        elif circular:
            sides.append(idx[:_REF_WALL_POINTS])
        if not sides:
            continue
        fallback = min(max(float(value[s[0]]) for s in sides), range_max)
        fill = np.full(b - a, fallback)
        if cos is not None and sin is not None and px is not None and py is not None:
            best = np.full(b - a, np.inf)
            for side in sides:
                if not hit[side[0]]:
                    continue
                side = side[hit[side]]
                if side.size < 2:
                    continue
                line = _reference_side_line(px[side].tolist(), py[side].tolist())
                if line is None:
                    continue
                t = _reference_hit_line(cos[a:b], sin[a:b], line)
                t = np.where(t > r[a:b], t, np.inf)
                best = np.minimum(best, t)
            fill = np.where(np.isfinite(best), np.minimum(best, range_max), fill)
        out[a:b] = fill
    return out


# ------------------------------------------------------------------------------ generated scans
def _same(new: FloatArray, ref: FloatArray) -> None:
    assert new.dtype == np.float64 and new.shape == ref.shape
    np.testing.assert_allclose(new, ref, rtol=0.0, atol=1e-9, equal_nan=True)


def _room(rng: np.random.Generator, angles: npt.NDArray[np.floating]) -> FloatArray:
    """Ranges (metres, inf: nothing hit) of one to three straight walls and up to three legs."""
    r = np.full(angles.shape, np.inf)
    for _ in range(int(rng.integers(1, 4))):
        normal, distance = rng.uniform(-np.pi, np.pi), rng.uniform(0.3, 8.0)
        c = np.cos(angles - normal)
        with np.errstate(divide="ignore"):
            r = np.minimum(r, np.where(c > 1e-9, distance / c, np.inf))
    k = int(rng.integers(0, 4))
    if k:
        bearing, dist = rng.uniform(angles[0], angles[-1] + 1e-9, k), rng.uniform(0.4, 4.0, k)
        centres = np.column_stack([dist * np.cos(bearing), dist * np.sin(bearing)])
        r = np.minimum(r, ray_circle_ranges((0.0, 0.0), angles, centres, rng.uniform(0.04, 0.1, k)))
    if rng.random() < 0.5:
        r = r + rng.normal(0.0, 0.005, r.shape)
    return r


@st.composite
def fill_cases(draw: st.DrawFn) -> tuple[FloatArray, BoolArray, dict[str, object]]:
    """A scan (walls and legs, or arbitrary readings), a mask and the keywords of a call."""
    n = draw(st.sampled_from([1, 2, 3, 5, 8, 13, 40, 90, 361]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    range_max = draw(st.sampled_from([5.0, 30.0, 81.82]))
    range_min = draw(st.sampled_from([0.0, 0.01, 0.3]))
    angle_min = draw(st.sampled_from([-np.pi / 2, 0.0, float(rng.uniform(-np.pi, np.pi))]))
    increment = draw(st.sampled_from([np.pi / 360, np.pi / 180, 2 * np.pi / n, 0.05]))
    angles = angle_min + np.arange(n) * increment
    if draw(st.booleans()):
        r = _room(rng, angles)
    else:
        r = rng.uniform(0.0, range_max * 1.1, n)
    # special readings: no return (range_max, inf, beyond), invalid (NaN, 0, < 0, < range_min)
    special = np.array([np.nan, np.inf, range_max, 2 * range_max, 0.0, -1.0, range_min / 2, -np.inf])
    pick = rng.random(n) < draw(st.sampled_from([0.0, 0.05, 0.3]))
    r[pick] = rng.choice(special, int(pick.sum()))
    if draw(st.booleans()):
        r = np.where(r >= range_max, range_max, r)  # the house convention for "nothing hit"
    how = draw(st.sampled_from(["runs", "bits", "near", "edges", "all"]))
    if how == "runs":
        m = np.zeros(n, dtype=bool)
        for _ in range(int(rng.integers(1, 5))):
            a = int(rng.integers(0, n))
            m[a : a + int(rng.integers(1, max(2, n // 4)))] = True
    elif how == "bits":
        m = rng.random(n) < rng.uniform(0.05, 0.9)
    elif how == "near":  # the nearest beams, as legs would be
        with np.errstate(invalid="ignore"):
            m = (
                r < np.nanpercentile(np.where(np.isfinite(r), r, np.nan), 25)
                if np.isfinite(r).any()
                else r < 0
            )
    elif how == "edges":
        m = np.zeros(n, dtype=bool)
        m[: int(rng.integers(1, 4))] = True
        m[n - int(rng.integers(1, 4)) :] = True
    else:
        m = np.ones(n, dtype=bool)
    kw: dict[str, object] = {"range_max": range_max, "range_min": range_min, "circular": draw(st.booleans())}
    if draw(st.booleans()):
        kw["angle_min"] = angle_min
        kw["angle_increment"] = increment
    return r, m, kw


@settings(max_examples=200, deadline=None)
@given(fill_cases(), st.sampled_from(["plain", "float32", "list", "strided", "readonly"]))
def test_fill_masked_gives_what_the_reference_gave(
    case: tuple[FloatArray, BoolArray, dict], form: str
) -> None:
    r, m, kw = case
    ranges: object = r
    mask: object = m
    if form == "float32":  # what the drivers hand over
        ranges = r.astype(np.float32)
    elif form == "list":
        ranges, mask = r.tolist(), m.astype(int).tolist()
    elif form == "strided":
        ranges, mask = np.repeat(r, 2)[::2], np.repeat(m, 2)[::2]
    elif form == "readonly":
        r.setflags(write=False)
        m.setflags(write=False)
    before = np.array(ranges, dtype=np.float64)
    new = fill_masked(ranges, mask, **kw)  # type: ignore[arg-type]
    ref = _reference_fill_masked(ranges, mask, **kw)  # type: ignore[arg-type]
    _same(new, ref)
    np.testing.assert_array_equal(np.array(ranges, dtype=np.float64), before)  # the input is left alone
    _same(unknown_masked(ranges, mask), np.where(np.asarray(mask, dtype=bool), np.nan, before))  # type: ignore[arg-type]


def test_fill_masked_fits_walls_in_the_generated_scans() -> None:
    """The generated rooms do reach the wall fit (not only the larger-neighbour fallback)."""
    rng = np.random.default_rng(7)
    angles = -np.pi / 2 + np.arange(361) * np.pi / 360
    walls = 0
    for _ in range(30):
        r = _room(rng, angles)
        m = np.zeros(361, dtype=bool)
        m[int(rng.integers(0, 340)) :][:15] = True
        kw = {"range_max": 30.0, "angle_min": -np.pi / 2, "angle_increment": np.pi / 360}
        new, ref = fill_masked(r, m, **kw), _reference_fill_masked(r, m, **kw)  # type: ignore[arg-type]
        _same(new, ref)
        walls += not np.array_equal(ref, _reference_fill_masked(r, m, range_max=30.0))
    assert walls >= 10


@st.composite
def detections(draw: st.DrawFn) -> SegmentDetection:
    """The segments of a scan of walls and legs with mixed pixels and dropouts, random flags."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.sampled_from([1, 4, 30, 181, 361]))
    inc = np.pi / 360
    r = np.minimum(_room(rng, -np.pi / 2 + inc * np.arange(n)), 30.0)
    jumps = np.flatnonzero(np.abs(np.diff(r)) > 0.3)
    mixed = jumps[rng.random(jumps.size) < 0.6]
    r[mixed] = 0.5 * (r[mixed] + r[mixed + 1])  # a mixed pixel between the two
    drop = rng.random(n) < draw(st.sampled_from([0.0, 0.05, 0.2]))
    r[drop] = rng.choice(np.array([30.0, np.nan, 0.0]), int(drop.sum()))
    seg = segment_scan(
        r, -np.pi / 2, inc, range_max=30.0, range_min=0.01, max_gap=draw(st.sampled_from([None, 0, 1]))
    )
    s = seg.n_segments
    flags = rng.random(s) < draw(st.sampled_from([0.0, 0.3, 1.0]))
    return SegmentDetection(seg, np.zeros((s, 14)), np.zeros(s), flags)


@settings(max_examples=150, deadline=None)
@given(detections(), st.integers(0, 4), st.sampled_from([None, 0.0, 0.2, 0.5]))
def test_person_beams_gives_what_the_reference_gave(
    det: SegmentDetection, margin: int, clearance: float | None
) -> None:
    new = person_beams(det, margin=margin, clearance=clearance)
    ref = _reference_person_beams(det, margin=margin, clearance=clearance)
    assert new.dtype == np.bool_
    np.testing.assert_array_equal(new, ref)
    c = 0.2 if clearance is None else clearance
    np.testing.assert_array_equal(free_standing(det, c), _reference_free_standing(det, c))


def test_bad_arguments_raise_what_the_reference_raised() -> None:
    r = np.array([3.0, 1.0, 1.0, 3.0, 3.0, 30.0])
    seg = segment_scan(r, 0.0, 0.01, range_max=30.0)
    det = SegmentDetection(
        seg, np.zeros((seg.n_segments, 14)), np.zeros(seg.n_segments), np.ones(seg.n_segments, bool)
    )
    for kw in ({"margin": -1}, {"clearance": -0.1}, {"clearance": float("nan")}):
        with pytest.raises(ValueError, match="margin" if "margin" in kw else "clearance"):
            person_beams(det, **kw)
        with pytest.raises(ValueError, match="margin" if "margin" in kw else "clearance"):
            _reference_person_beams(det, **kw)
    odd = SegmentDetection(seg, det.features, det.score, np.ones(seg.n_segments + 2, bool))
    with pytest.raises(ValueError, match="one flag per segment"):
        person_beams(odd)
    for bad in (np.zeros((2, 3)), np.zeros(5)):
        with pytest.raises(ValueError, match="same length"):
            fill_masked(bad, np.zeros(6, bool), range_max=30.0)
        with pytest.raises(ValueError, match="same length"):
            _reference_fill_masked(bad, np.zeros(6, bool), range_max=30.0)


# ------------------------------------------------------------------------------ the agent's drive
def test_the_drives_scans_and_the_pipelines_masks_give_what_the_reference_gave() -> None:
    """300 scans of the agent benchmark's drive: the leg detector's detections, the masks with
    the pipeline's settings (and others), the filled ranges as the classifier gets them."""
    drive = DriveScans()
    chunk = drive.take(300)
    people = PeoplePipeline()
    defaults = PeopleParams()
    masked = walls = 0
    for i in range(len(chunk)):
        scan = drive.scan(chunk, i)
        det = people.process_scan(scan).detection
        for margin, clearance in ((defaults.margin, defaults.clearance), (0, None), (3, 0.0)):
            m = person_beams(det, margin=margin, clearance=clearance)
            np.testing.assert_array_equal(m, _reference_person_beams(det, margin=margin, clearance=clearance))
        m = person_beams(det, margin=defaults.margin, clearance=defaults.clearance)
        if not m.any():
            continue
        masked += 1
        kw: dict[str, object] = {"range_max": scan.range_max, "range_min": scan.range_min}
        ang = {"angle_min": scan.angle_min, "angle_increment": scan.angle_increment}
        for extra in ({**ang, "circular": is_full_turn(scan)}, {**ang, "circular": True}, {}):
            new = fill_masked(scan.ranges, m, **kw, **extra)  # type: ignore[arg-type]
            ref = _reference_fill_masked(scan.ranges, m, **kw, **extra)  # type: ignore[arg-type]
            _same(new, ref)
            if extra:
                plain = _reference_fill_masked(scan.ranges, m, **kw)  # type: ignore[arg-type]
                walls += not np.array_equal(ref, plain)
    assert masked >= 100, masked  # measured: 250 of the 300 scans have masked beams
    assert walls >= 50, walls  # and the wall fit changes many of them
