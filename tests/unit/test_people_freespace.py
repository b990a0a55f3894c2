"""Free-space evidence: where the laser saw through a moment ago (a person walked in), and
where it did not (a wall, a post, the far side of a wall, places not yet looked at)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from knowledge.people.freespace import SeenThrough, SeenThroughParams

N = 768
INC = math.radians(270.0) / N
AMIN = -math.radians(135.0)
ANGLES = AMIN + INC * np.arange(N)


def wall_scan(distance: float = 4.0, post: tuple[float, float] | None = None) -> np.ndarray:
    """A straight wall ``distance`` m ahead (x = distance), no return elsewhere (11 m), and
    optionally a 4 cm post at ``post`` (x, y), laser at the origin facing +x."""
    r = np.full(N, 11.0)
    ahead = np.cos(ANGLES) > 0.05
    r[ahead] = np.minimum(distance / np.cos(ANGLES[ahead]), 11.0)
    if post is not None:
        px, py = post
        d, b = math.hypot(px, py), math.atan2(py, px)
        r[np.abs(ANGLES - b) * d < 0.02] = d
    return r


def memory(scans: list[np.ndarray], dt: float = 0.1, pose=(0.0, 0.0, 0.0), **kw) -> SeenThrough:
    st = SeenThrough(SeenThroughParams(**kw))
    for k, r in enumerate(scans):
        st.add(r, k * dt, pose, angle_min=AMIN, angle_increment=INC, range_max=11.0, range_min=0.02)
    return st


def test_a_place_in_front_of_the_wall_was_seen_through_behind_it_not() -> None:
    st = memory([wall_scan()] * 21, max_scans=32)  # 2 s of scans, 0.1 s apart
    ev = st.evidence(np.array([[2.0, 0.0], [3.8, 0.5], [4.0, 0.0], [5.0, 0.0]]), 2.0)
    # lags 0.25..2 s: scans at 0.0 .. 1.7 s, 18 of them; 3.8 m is within the 0.3 m margin
    assert ev.tolist() == [18, 0, 0, 0]
    # at most max_scans of them are looked at (16 by default)
    assert memory([wall_scan()] * 21).evidence(np.array([[2.0, 0.0]]), 2.0).tolist() == [16]


def test_a_thin_post_is_not_free_space_even_when_beams_beside_it_pass() -> None:
    st = memory([wall_scan(post=(2.0, 0.0))] * 10)
    ev = st.evidence(np.array([[2.0, 0.0], [2.0, 0.15], [2.0, 0.06]]), 1.0)
    assert ev[0] == 0  # the post itself
    assert ev[1] > 0  # 15 cm beside it: every beam within 10 cm passes
    assert ev[2] == 0  # 6 cm beside it: a beam of the window hits the post


def test_only_scans_between_min_lag_and_horizon_count() -> None:
    st = memory([wall_scan()] * 31, horizon=1.0, min_lag=0.5)
    assert st.evidence(np.array([[2.0, 0.0]]), 3.0).tolist() == [6]  # 2.0 .. 2.5 s
    assert len(st) == 11  # older scans are forgotten
    assert st.evidence(np.zeros((0, 2)), 3.0).shape == (0,)


def test_the_laser_pose_moves_the_beams() -> None:
    # the laser 1 m to the left, turned by 90°: the wall (4 m ahead of it) is at y = 5
    st = memory([wall_scan()] * 5, pose=(0.0, 1.0, math.pi / 2))
    ev = st.evidence(np.array([[0.0, 3.0], [0.0, 5.0], [3.0, 1.0]]), 0.5)
    assert ev[0] > 0 and ev[1] == 0
    assert ev[2] > 0  # to the laser's right: no return there, the beam passed everything


def test_a_point_outside_the_field_of_view_or_at_an_invalid_reading_is_no_evidence() -> None:
    r = wall_scan()
    r[np.abs(ANGLES) < 0.05] = 0.0  # invalid readings straight ahead
    st = memory([r] * 5)
    ev = st.evidence(np.array([[2.0, 0.0], [-2.0, 0.0]]), 0.5)  # behind the 270° laser
    assert ev.tolist() == [0, 0]


def test_params_are_checked() -> None:
    with pytest.raises(ValueError, match="horizon"):
        SeenThroughParams(horizon=0.0)
    with pytest.raises(ValueError, match="min_lag"):
        SeenThroughParams(min_lag=3.0)
    with pytest.raises(ValueError, match="max_scans"):
        SeenThroughParams(max_scans=0)


def test_hidden_behind_says_what_something_nearer_hides() -> None:
    from knowledge.people.pipeline import hidden_behind

    r = wall_scan(post=(1.5, 0.0))  # a post 1.5 m ahead, the wall at 4 m
    pose = (0.0, 0.0, 0.0)
    pts = np.array([[3.0, 0.0], [1.6, 0.0], [3.0, 1.5], [-2.0, 0.0]])
    # behind the post; just behind it (within the 0.3 m margin); in the open; behind the laser
    assert hidden_behind(pts, r, pose, AMIN, INC, 11.0).tolist() == [True, False, False, False]
    # the same scan taken by a laser at another pose, the points given in the tracking frame
    moved = (1.0, -1.0, math.pi / 2)
    c, s = math.cos(moved[2]), math.sin(moved[2])
    world = np.array([[moved[0] + c * x - s * y, moved[1] + s * x + c * y] for x, y in pts])
    assert hidden_behind(world, r, moved, AMIN, INC, 11.0).tolist() == [True, False, False, False]
