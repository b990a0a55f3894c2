"""Scan matching and pose tracking on simulated scans in a small test world."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.localization_world import ANGLES, RANGE_MAX, drifting_odometry, path, scans, world

from knowledge.localization.likelihood import LikelihoodField, distance_field, surface
from knowledge.localization.scan_matching import MatchParams, ScanMatcher, scan_points
from knowledge.localization.se2 import compose, wrap
from knowledge.localization.tracking import PoseTracker
from knowledge.localization.trajectory import ate


@pytest.fixture(scope="module")
def setting() -> tuple:
    g = world()
    truth = path()
    return g, truth, scans(g, truth), drifting_odometry(truth)


def test_surface_leaves_out_the_inside_of_solid_blocks() -> None:
    occ = np.zeros((7, 7), dtype=bool)
    occ[1:6, 1:6] = True
    s = surface(occ)
    assert s[1, 1] and s[1, 3] and s[5, 5] and not s[3, 3] and not s[2:5, 2:5].any()


def test_distance_field_by_hand() -> None:
    occ = np.zeros((5, 7), dtype=bool)
    occ[2, 3] = True
    d = distance_field(occ, 0.1, 0.25)
    assert d[2, 3] == 0.0
    assert d[2, 5] == pytest.approx(0.2, abs=1e-4)
    assert d[0, 0] == pytest.approx(0.25)  # clipped (0.36 m)
    assert distance_field(np.zeros((2, 2), dtype=bool), 0.1, 1.0).min() == 1.0


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (0.15, -0.1, 0.08), (-0.25, 0.2, -0.3)])
def test_matcher_finds_the_pose_from_an_offset_prior(setting: tuple, offset: tuple) -> None:
    g, truth, R, _ = setting
    lf = LikelihoodField.from_grid(g, 1.0)
    matcher = ScanMatcher(MatchParams(angular_window=0.4))
    mf = matcher.field(lf)
    for i in (5, 60, 100):
        pts = scan_points(R[i], ANGLES, range_max=RANGE_MAX)
        res = matcher.match(mf, pts, lf.to_map(truth[i] + np.array(offset)))
        got = lf.to_world(res.pose)
        # 5 cm cells: along a corridor the end walls (seen at grazing angles) pin it to a cell
        assert np.hypot(*(got[:2] - truth[i][:2])) < 0.05
        assert abs(wrap(got[2] - truth[i][2])) < 0.01
        assert res.fit > 0.8


def test_search_runs_when_asked_or_when_the_fit_is_poor(setting: tuple) -> None:
    g, truth, R, _ = setting
    lf = LikelihoodField.from_grid(g, 1.0)
    pts = scan_points(R[60], ANGLES, range_max=RANGE_MAX)
    good = lf.to_map(truth[60])
    auto = ScanMatcher(MatchParams(search="auto"))
    assert not auto.match(auto.field(lf), pts, good).searched
    always = ScanMatcher(MatchParams(search="always"))
    assert always.match(always.field(lf), pts, good).searched
    # turned 0.9 rad away, beyond the refinement's basin: the fit is poor, the search runs
    far = lf.to_map(truth[60] + np.array([0.0, 0.0, 0.9]))
    never = ScanMatcher(MatchParams(search="never"))
    stuck = never.match(never.field(lf), pts, far)
    assert stuck.fit < auto.params.min_fit and not stuck.searched
    assert auto.match(auto.field(lf), pts, far).searched


def test_tracking_without_a_map_beats_drifting_odometry(setting: tuple) -> None:
    _, truth, R, odo = setting
    tracker = PoseTracker()
    est = np.array([tracker.update(R[i], ANGLES, odo[i], range_max=RANGE_MAX).pose for i in range(len(odo))])
    odo_ate = ate(truth, odo)[0].rmse
    track_ate = ate(truth, est)[0].rmse
    assert odo_ate > 0.2
    assert track_ate < 0.05
    # the correction is map -> odom: applied to the odometry it gives the tracked pose
    step = tracker.update(R[-1], ANGLES, odo[-1], range_max=RANGE_MAX)
    assert np.allclose(compose(step.correction, odo[-1]), step.pose)
    assert not step.integrated  # the robot has not moved since the last scan
    assert 10 < tracker.mapper.scans < len(odo)  # scans are integrated only after motion


def test_tracking_in_a_known_map_starting_from_the_true_pose(setting: tuple) -> None:
    g, truth, R, odo = setting
    tracker = PoseTracker(prior=g, initial=truth[0])
    est = np.array([tracker.update(R[i], ANGLES, odo[i], range_max=RANGE_MAX).pose for i in range(len(odo))])
    err = np.hypot(*(est[:, :2] - truth[:, :2]).T)
    assert err.max() < 0.05
    assert tracker.mapper.scans == 0  # a known map is not added to


def test_a_match_never_ends_further_than_the_window_from_its_prior(setting: tuple) -> None:
    g, truth, R, _ = setting
    lf = LikelihoodField.from_grid(g, 1.0)
    matcher = ScanMatcher()
    mf = matcher.field(lf)
    prm = matcher.params
    pts = scan_points(R[5], ANGLES, range_max=RANGE_MAX)
    for dx in (0.2, 0.8, 1.5):  # along the corridor: the refinement would slide back to the truth
        prior = lf.to_map(truth[5] + np.array([dx, 0.0, 0.0]))
        res = matcher.match(mf, pts, prior)
        moved = float(np.hypot(*(res.pose[:2] - prior[:2])))
        assert moved <= prm.linear_window + max(prm.sigmas) + 1e-9
        if dx < prm.linear_window:
            assert np.hypot(*(lf.to_world(res.pose)[:2] - truth[5][:2])) < 0.05  # within reach: found


def _long_corridor() -> tuple[LikelihoodField, np.ndarray]:
    """A 30 m corridor, 2 m wide, with one post in the middle at x = 15 m; and a scan from
    (12, 1, 0) that sees the walls from x = 7 to 17 m and, 0.1 m beyond the post, a person
    standing where the map has nothing (the post itself hidden behind them)."""
    from knowledge.metric.grid import OccupancyGrid

    res = 0.05
    occ = np.zeros((int(2.4 / res), int(30 / res)), dtype=bool)
    occ[: int(0.2 / res), :] = True
    occ[-int(0.2 / res) :, :] = True
    occ[int(1.1 / res) : int(1.3 / res), int(15.0 / res) : int(15.2 / res)] = True  # the post
    grid = OccupancyGrid.from_masks(occ[::-1], res, name="corridor")
    xs = np.arange(7.0, 17.0, 0.1)
    walls = np.concatenate(
        [np.stack([xs, np.full_like(xs, 0.2)], 1), np.stack([xs, np.full_like(xs, 2.2)], 1)]
    )
    person = np.array(
        [[15.3 + dx, 1.2 + dy] for dx in (0.0, 0.05, 0.1) for dy in (-0.1, -0.05, 0.0, 0.05, 0.1)]
    )
    # the same post-sized blob, repeated so it weighs like the legs of a person close by
    pts = np.concatenate([walls, np.repeat(person, 3, axis=0)]) - np.array([12.0, 1.0])
    return LikelihoodField.from_grid(grid, 1.0), pts


def test_the_odometry_prior_keeps_a_corridor_match_from_sliding_onto_a_person() -> None:
    """Along a featureless corridor a blob that looks like a mapped post drags a plain match
    a quarter of a metre back; the prior (Cartographer-style translation weight) keeps the pose where it was,
    and across the corridor, where the walls decide, it still corrects an offset."""
    lf, pts = _long_corridor()
    truth = np.array([12.0, 1.0, 0.0])
    plain = ScanMatcher(MatchParams(angular_window=0.4, min_fit=0.8))
    weighed = ScanMatcher(
        MatchParams(angular_window=0.4, min_fit=0.8, translation_weight=10.0, rotation_weight=2.0)
    )
    slid = lf.to_world(plain.match(plain.field(lf), pts, lf.to_map(truth), search=True).pose)
    assert slid[0] - truth[0] < -0.15  # the person pulled the plain match back along the corridor
    kept = lf.to_world(weighed.match(weighed.field(lf), pts, lf.to_map(truth), search=True).pose)
    assert abs(kept[0] - truth[0]) < 0.05 and abs(kept[1] - truth[1]) < 0.03
    # an offset across the corridor is still corrected with the prior on
    off = truth + np.array([0.0, 0.12, 0.0])
    fixed = lf.to_world(weighed.match(weighed.field(lf), pts, lf.to_map(off)).pose)
    assert abs(fixed[1] - truth[1]) < 0.03
    # per-scan weights override the parameters', and are checked
    again = lf.to_world(
        plain.match(plain.field(lf), pts, lf.to_map(truth), search=True, weights=(10.0, 2.0)).pose
    )
    np.testing.assert_allclose(again, kept, atol=1e-9)
    with pytest.raises(ValueError, match="weights"):
        plain.match(plain.field(lf), pts, lf.to_map(truth), weights=(-1.0, 0.0))
    with pytest.raises(ValueError, match="translation_weight"):
        MatchParams(translation_weight=float("nan"))


def test_the_tracker_weighs_its_prior_by_the_odometry_increment() -> None:
    from knowledge.localization.tracking import TrackingParams

    t = PoseTracker(TrackingParams(prior_translation=0.15, prior_rotation=0.02))
    assert t._prior_weights(np.zeros(3)) == pytest.approx((15.0, 2.0))  # first scan: standing
    t._last_odom = np.zeros(3)
    still = t._prior_weights(np.array([0.01, 0.0, 0.0]))
    fast = t._prior_weights(np.array([0.2, 0.0, 0.3]))
    assert still[0] == pytest.approx(7.5) and fast[0] == pytest.approx(0.15 / 0.21)
    assert fast[1] == pytest.approx(0.02 / 0.31) and fast[1] < still[1]
    with pytest.raises(ValueError, match="prior_translation"):
        TrackingParams(prior_translation=-1.0)


def _correlate_reference(score, pts, x, y, th, res, n_lin, angles, w_t, w_r):  # type: ignore[no-untyped-def]
    """The correlative search as written first: offset by offset, the endpoints summed in order."""
    rows, cols = score.shape
    best, found = -1.0, (0, 0, 0)
    for k, da in enumerate(angles):
        c, s = math.cos(th + da), math.sin(th + da)
        cj = [math.floor((x + c * px - s * py) / res) for px, py in pts]
        ci = [math.floor((y + s * px + c * py) / res) for px, py in pts]
        for di in range(-n_lin, n_lin + 1):
            for dj in range(-n_lin, n_lin + 1):
                tot = 0.0
                for r0, q0 in zip(ci, cj, strict=True):
                    r, q = r0 + di, q0 + dj
                    if 0 <= r < rows and 0 <= q < cols:
                        tot += float(score[r, q])
                if w_t > 0.0 or w_r > 0.0:
                    tot *= math.exp(-w_t * (di * di + dj * dj) * res * res - w_r * da * da)
                if tot > best:
                    best, found = tot, (dj, di, k)
    return (*found, best)


@pytest.mark.parametrize("weights", [(0.0, 0.0), (15.0, 2.0)])
def test_the_correlative_search_kernel_is_the_plain_loop(setting: tuple, weights: tuple) -> None:
    from knowledge.localization.scan_matching import _correlate

    g, truth, R, _ = setting
    lf = LikelihoodField.from_grid(g, 1.0)
    score = lf.score(0.05)
    pts = scan_points(R[60], ANGLES, range_max=RANGE_MAX, step=4)
    angles = np.arange(-6, 7) * 0.02
    # from the true pose and from off it; near the grid's edge some offsets fall outside
    for off in ((0.0, 0.0, 0.0), (0.2, -0.15, 0.1)):
        x, y, th = lf.to_map(truth[60] + np.array(off))
        got = _correlate(score, pts, x, y, th, 0.05, 5, angles, *weights)
        assert tuple(got) == _correlate_reference(score, pts, x, y, th, 0.05, 5, angles, *weights)
    edge = np.zeros_like(score)
    edge[:3, :] = 1.0
    edge[:, -2:] = 0.5
    got = _correlate(edge, pts, 0.1, 0.1, 0.3, 0.05, 4, angles, *weights)
    assert tuple(got) == _correlate_reference(edge, pts, 0.1, 0.1, 0.3, 0.05, 4, angles, *weights)
