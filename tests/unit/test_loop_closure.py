"""The pose graph and loop closure on simulated scans round a ring of corridors.

The graph is fed odometry here, not the tracker's poses: the drift it must remove is the
odometry's, so the search windows are the odometry's too (:data:`ODOMETRY_LOOPS`), wider than
the defaults made for the tracker's bounded drift.
"""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest
from support.loop_world import drifting_odometry, path, points, scans, world

from knowledge.localization.loop_closure import LoopParams, propose
from knowledge.localization.pose_graph import PoseGraph, PoseGraphParams
from knowledge.localization.se2 import between, wrap
from knowledge.localization.trajectory import ate

#: Windows for raw odometry that drifts up to 0.01 rad and 0.05 m per metre.
ODOMETRY_LOOPS = LoopParams(
    drift_rate=0.05, max_radius=3.0, angular_window=0.15, angular_drift_rate=0.008, max_angular_window=0.6
)
ODOMETRY = PoseGraphParams(
    odom_translation=0.05, odom_rotation=0.05, odom_rotation_per_metre=0.01, loops=ODOMETRY_LOOPS
)


@pytest.fixture(scope="module")
def ring() -> tuple:
    """The ring, 1.3 laps of true poses (10 cm apart) and their scans' endpoints."""
    g = world()
    truth = path(laps=1.3)
    return g, truth, points(scans(g, truth))


def feed(graph: PoseGraph, poses: np.ndarray, pts: list[np.ndarray]) -> PoseGraph:
    for i, (p, q) in enumerate(zip(poses, pts, strict=True)):
        graph.add(0.1 * i, p, q)
    return graph


def test_a_loop_is_closed_and_the_drift_removed(ring: tuple) -> None:
    _, truth, pts = ring
    odo = drifting_odometry(truth, drift=0.006, scale=1.02)
    graph = feed(PoseGraph(ODOMETRY), odo, pts)
    assert graph.loops, [c.reason for c in graph.checks]
    # every accepted loop agrees with the true relative pose of its two keyframes (to the
    # distortion of its local map, laid at the drifting estimates: 2 % of 4 m, at a corner)
    for j, k, rel in graph.loops:
        true = between(truth[graph.keyframes[j].scan], truth[graph.keyframes[k].scan])
        err = between(true, rel)
        assert np.hypot(err[0], err[1]) < 0.15 and abs(err[2]) < 0.05
    before = ate(truth, odo)[0].rmse
    after = ate(truth, graph.corrected())[0].rmse
    assert before > 0.5
    assert after < 0.4 * before and after < 0.25
    # where the robot came back to its start, its estimate is back there too (the odometry: 2 m off)
    k = next(k for _, k, _ in graph.loops)
    scan = graph.keyframes[k].scan
    assert np.hypot(*(odo[scan, :2] - truth[scan, :2])) > 1.0
    assert np.hypot(*(graph.estimates[k, :2] - truth[scan, :2])) < 0.3
    # bounded and reported: one time per optimisation, within the budget
    assert len(graph.optimisations) >= 1
    assert max(graph.optimisations) < ODOMETRY.max_seconds + 0.2


def test_one_wrong_loop_does_not_wreck_the_map(ring: tuple) -> None:
    _, truth, pts = ring
    odo = drifting_odometry(truth, drift=0.006, scale=1.02)
    graph = feed(PoseGraph(ODOMETRY), odo, pts)
    good = ate(truth, graph.corrected())[0].rmse
    # a loop that says the last keyframe is 6 m back along the corridor, where it was not
    k = len(graph) - 1
    est = graph.estimates
    j = int(np.argmin(np.hypot(*(est[: k - 60, :2] - (est[k, :2] - [6.0, 0.0])).T)))
    gauss = copy.deepcopy(graph)
    gauss.params = replace(ODOMETRY, robust="none")
    for g in (graph, gauss):
        g.add_loop(j, k, [0.0, 0.0, 0.0])
        g.optimise()
    robust = ate(truth, graph.corrected())[0].rmse
    plain = ate(truth, gauss.corrected())[0].rmse
    assert robust < good + 0.05, (good, robust)
    assert plain > good + 0.3, (good, plain)  # a Gaussian loop edge bends the map to it


def test_an_optimisation_stops_at_its_time_bound(ring: tuple) -> None:
    _, truth, pts = ring
    odo = drifting_odometry(truth, drift=0.006, scale=1.02)
    graph = feed(PoseGraph(replace(ODOMETRY, loops=replace(ODOMETRY_LOOPS, max_candidates=1))), odo, pts)
    assert graph.loops and max(graph.iterations) >= 2
    before = graph.estimates
    graph.params = replace(graph.params, max_seconds=1e-9)
    graph.add_loop(0, len(graph) - 1, [0.0, 0.0, 0.0])
    graph.optimise()
    # out of time before the first iteration: the estimates it had are kept, and it says so
    assert graph.iterations[-1] == 0
    after = graph.estimates
    assert np.allclose(after[:, :2], before[:, :2], rtol=0, atol=1e-9)
    assert np.allclose(wrap(after[:, 2] - before[:, 2]), 0.0, atol=1e-9)
    with pytest.raises(ValueError, match="two keyframes"):
        graph.add_loop(3, 3, [0.0, 0.0, 0.0])


def test_a_wrong_candidate_is_rejected_and_the_right_one_taken(ring: tuple) -> None:
    _, truth, pts = ring
    graph = feed(PoseGraph(ODOMETRY, close_loops=False), truth, pts)
    kf = graph.keyframes
    est = graph.estimates
    # the last keyframe is on the second lap, on the bottom corridor near x = 12.5 m
    k = len(kf) - 1
    here = est[k]
    travel = graph.travel
    # the keyframe of the first lap at the same place, and one 6 m further along the corridor
    older = np.nonzero(travel[k] - travel >= ODOMETRY_LOOPS.min_travel)[0]
    same = int(older[np.argmin(np.hypot(*(est[older, :2] - here[:2]).T))])
    wrong = int(older[np.argmin(np.hypot(*(est[older, :2] - (here[:2] - [6.0, 0.0])).T))])
    assert np.hypot(*(est[wrong, :2] - here[:2])) > 5.0
    right = graph.check(k, same)
    assert right.accepted, right.reason
    assert right.relative is not None
    assert np.allclose(right.relative, between(est[same], here), atol=0.05)
    # the drift said the robot was where ``wrong`` is: the scan does not fit there
    bad = graph.check(k, wrong, prior=est[wrong] + [0.3, 0.0, 0.05])
    assert not bad.accepted
    assert bad.reason.startswith(("fit", "inliers", "outside")), bad.reason
    assert graph.loops == [] and graph.optimisations == []


def test_a_log_with_no_loop_changes_nothing(ring: tuple) -> None:
    _, truth, pts = ring
    n = int(0.8 * len(truth) / 1.3)  # four fifths of one lap: it never comes back
    odo = drifting_odometry(truth[:n], drift=0.006, scale=1.02)
    graph = feed(PoseGraph(ODOMETRY), odo, pts[:n])
    assert len(graph) > 50
    assert graph.loops == [] and graph.optimisations == []
    # the same poses, to the rounding of taking each apart from its keyframe and back
    assert np.allclose(graph.corrected(), odo, rtol=0, atol=1e-9)
    assert np.allclose(graph.estimates, odo[[kf.scan for kf in graph.keyframes]], rtol=0, atol=1e-9)


def test_odometry_that_jumps_once_makes_no_false_loop(ring: tuple) -> None:
    _, truth, pts = ring
    # along the bottom corridor, then the odometry jumps 11 m back (the robot did not move)
    stop = int(np.nonzero(truth[:, 0] > 13.0)[0][0])
    end = int(np.nonzero(truth[:, 1] > 6.0)[0][0])  # on up the right corridor
    odo = truth[:end].copy()
    odo[stop:, 0] -= 11.0
    graph = feed(PoseGraph(ODOMETRY), odo, pts[:end])
    # the jump put the estimate on keyframes of 20 m of path back: they were proposed...
    assert graph.checks, "the jump should have proposed candidates"
    # ...and none fitted
    assert graph.loops == [], [c.reason for c in graph.checks if c.accepted]
    assert all(not c.accepted for c in graph.checks)
    assert np.allclose(graph.corrected(), odo, rtol=0, atol=1e-9)


def test_candidates_are_near_and_far_back_along_the_path() -> None:
    # a straight line out and back: keyframe 40 is back at keyframe 0's place
    xs = np.r_[np.arange(0, 20) * 0.5, 10.0 - np.arange(0, 21) * 0.5]
    est = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], axis=1)
    travel = np.arange(len(xs)) * 0.5
    prm = LoopParams(min_travel=10.0, max_candidates=2, candidate_spacing=3.0)
    got = propose(40, est, travel, prm)
    assert [j for j, _, _ in got] == [0]  # keyframe 0 only: the others are too close along the path
    assert got[0][1] == pytest.approx(0.0) and got[0][2] == pytest.approx(20.0)
    assert propose(25, est, travel, prm) == []  # keyframe 25 (x = 7.5) is 10 m back from 15 only: too far
    with pytest.raises(ValueError, match="min_fit"):
        LoopParams(min_fit=1.5)
