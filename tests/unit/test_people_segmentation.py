"""Jump-distance segmentation on hand-made scans."""

from __future__ import annotations

import math

import numpy as np
import pytest

from knowledge.people.segmentation import has_return, segment_scan

INC = math.radians(1.0)


def test_a_range_jump_starts_a_new_segment() -> None:
    r = np.array([2.0] * 10 + [3.0] * 10)
    seg = segment_scan(r, 0.0, INC, range_max=10.0)
    assert seg.n_segments == 2
    assert seg.sizes.tolist() == [10, 10]
    assert seg.segment_beams(1).tolist() == list(range(10, 20))
    np.testing.assert_allclose(seg.segment_points(0)[3], [2 * math.cos(3 * INC), 2 * math.sin(3 * INC)])


def test_the_jump_threshold_is_inclusive() -> None:
    # three beams in (almost) the same direction: the points are 0.15 m and 0.1501 m apart
    angles = 0.0
    r = np.array([2.0, 2.15, 2.3001 + 0.0])
    seg = segment_scan(r, angles, 1e-9, range_max=10.0, jump=0.15 + 1e-12)
    assert seg.sizes.tolist() == [2, 1]  # 0.15 joins, 0.1501 splits
    seg = segment_scan(r, angles, 1e-9, range_max=10.0, jump=0.1)
    assert seg.sizes.tolist() == [1, 1, 1]


def test_a_wall_of_close_points_is_one_segment_and_its_far_end_splits() -> None:
    # a wall at x = 1 m: neighbouring points get further apart with the bearing
    b = np.arange(-80, 81) * INC
    r = 1.0 / np.cos(b)
    seg = segment_scan(r, float(b[0]), INC, range_max=100.0, jump=0.15)
    steps = np.hypot(*np.diff(np.column_stack([np.ones_like(b), np.tan(b)]), axis=0).T)
    assert seg.n_segments == int((steps > 0.15).sum()) + 1
    assert seg.n_segments > 1  # at ±80° the points are > 15 cm apart
    centre = seg.beam_segment()[80]
    assert seg.sizes[centre] > 50


@pytest.mark.parametrize("bad", [0.0, np.inf, np.nan, -1.0, 8.0, 9.5])
def test_no_return_beams_belong_to_no_segment(bad: float) -> None:
    r = np.array([2.0, 2.0, bad, 2.0, 2.0])
    assert has_return(r, 8.0).tolist() == [True, True, False, True, True]
    seg = segment_scan(r, 0.0, INC, range_max=8.0)
    assert seg.n_points == 4
    assert seg.beam_segment()[2] == -1
    # a dropout inside an object does not cut it (points 2 beams apart are 7 cm apart) ...
    assert seg.n_segments == 1
    # ... unless max_gap says so
    assert segment_scan(r, 0.0, INC, range_max=8.0, max_gap=0).sizes.tolist() == [2, 2]
    assert segment_scan(r, 0.0, INC, range_max=8.0, max_gap=1).n_segments == 1


def test_readings_below_range_min_are_no_returns() -> None:
    # a Hokuyo reports errors as ranges of a few millimetres (the legs data has 6-15 mm)
    r = np.array([2.0, 2.0, 0.006, 2.0, 2.0, 0.009, 0.009, 2.0])
    assert has_return(r, 8.0, 0.02).tolist() == [True, True, False, True, True, False, False, True]
    seg = segment_scan(r, 0.0, INC, range_max=8.0, range_min=0.02)
    assert seg.n_segments == 1 and seg.n_points == 5
    # taken as returns, the error codes are points at the laser that cut the object
    raw = segment_scan(r, 0.0, INC, range_max=8.0)
    assert raw.sizes.tolist() == [2, 1, 2, 2, 1]
    assert np.hypot(*raw.centroids()[1]) < 0.01


def test_points_far_apart_across_a_gap_are_split() -> None:
    r = np.array([2.0, 2.0] + [0.0] * 20 + [2.0, 2.0])  # 20 beams ≈ 0.7 m apart at 2 m
    seg = segment_scan(r, 0.0, INC, range_max=8.0)
    assert seg.sizes.tolist() == [2, 2]


def test_scan_without_returns_has_no_segments() -> None:
    seg = segment_scan(np.full(50, np.inf), -1.0, INC, range_max=8.0)
    assert seg.n_segments == 0
    assert seg.centroids().shape == (0, 2)
    assert (seg.beam_segment() == -1).all()
    assert not seg.beam_mask(np.zeros(0, dtype=bool)).any()


def test_beam_mask_labels_the_beams_of_flagged_segments() -> None:
    r = np.array([2.0] * 3 + [0.0] + [5.0] * 4 + [2.0] * 2)
    seg = segment_scan(r, 0.0, INC, range_max=8.0)
    assert seg.sizes.tolist() == [3, 4, 2]
    mask = seg.beam_mask(np.array([False, True, False]))
    assert mask.tolist() == [False] * 4 + [True] * 4 + [False] * 2
    with pytest.raises(ValueError, match="one flag per segment"):
        seg.beam_mask(np.array([True]))
    c = seg.centroids()
    np.testing.assert_allclose(
        np.hypot(*c[1]), 5.0 * (math.cos(1.5 * INC) + math.cos(0.5 * INC)) / 2, rtol=1e-12
    )


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"jump": 0.0}, "jump"),
        ({"jump": float("nan")}, "jump"),
        ({"range_max": 0.0}, "range_max"),
        ({"max_gap": -1}, "max_gap"),
        ({"range_min": -0.1}, "range_min"),
        ({"range_min": 8.0}, "range_min"),
    ],
)
def test_bad_arguments_say_what_to_do(kwargs: dict[str, float], match: str) -> None:
    args = {"range_max": 8.0} | kwargs
    with pytest.raises(ValueError, match=match):
        segment_scan(np.ones(5), 0.0, INC, **args)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="angle_increment"):
        segment_scan(np.ones(5), 0.0, 0.0, range_max=8.0)
    with pytest.raises(ValueError, match="1-D"):
        segment_scan(np.ones((2, 5)), 0.0, INC, range_max=8.0)
