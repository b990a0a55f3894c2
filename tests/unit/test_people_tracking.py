"""People tracking: constant-velocity Kalman filter, births, deaths, stable ids."""

from __future__ import annotations

import numpy as np
import pytest

from knowledge.people.tracking import (
    PeopleTracker,
    TrackerConfig,
    cv_process_noise,
    kalman_predict,
    kalman_update,
)

DT = 0.1


def test_kalman_prediction_follows_constant_velocity() -> None:
    x = np.array([1.0, 2.0, 0.5, -0.25])
    P = np.diag([0.01, 0.01, 0.1, 0.1])
    x2, P2 = kalman_predict(x, P, 2.0, accel_std=1.0)
    np.testing.assert_allclose(x2, [2.0, 1.5, 0.5, -0.25])
    # position uncertainty grows with the velocity's and the process noise
    assert P2[0, 0] == pytest.approx(0.01 + 4 * 0.1 + 1.0 * 2.0**4 / 4)
    assert np.all(np.linalg.eigvalsh(P2) > 0)
    Q = cv_process_noise(0.5, 2.0)
    np.testing.assert_allclose(Q, Q.T)
    assert Q[2, 2] == pytest.approx(4.0 * 0.25)


def test_kalman_update_pulls_towards_the_measurement_by_the_gain() -> None:
    x = np.zeros(4)
    P = np.diag([1.0, 1.0, 1.0, 1.0])
    x2, P2 = kalman_update(x, P, np.array([1.0, 0.0]), meas_std=1.0)
    assert x2[0] == pytest.approx(0.5)  # equal prior and measurement variances
    assert P2[0, 0] == pytest.approx(0.5)


def test_tracks_a_walker_and_estimates_its_velocity() -> None:
    tr = PeopleTracker()
    v = np.array([1.0, 0.5])
    for k in range(40):
        t = k * DT
        states = tr.update([np.array([1.0, -1.0]) + v * t], t)
    assert len(states) == 1
    assert states[0].id == 1
    np.testing.assert_allclose(states[0].velocity, v, atol=0.05)
    np.testing.assert_allclose(states[0].position, np.array([1.0, -1.0]) + v * 39 * DT, atol=0.05)


def test_births_need_confirmation_and_one_off_clutter_never_becomes_a_track() -> None:
    cfg = TrackerConfig(confirm_hits=3, tentative_misses=1)
    tr = PeopleTracker(cfg)
    assert tr.update([[2.0, 0.0]], 0.0) == []
    assert len(tr.tracks(include_tentative=True)) == 1
    assert tr.update([[2.0, 0.0], [5.0, 5.0]], 0.1) == []  # the person again, plus clutter
    states = tr.update([[2.0, 0.0]], 0.2)
    assert [s.id for s in states] == [1]
    assert states[0].hits == 3
    # the clutter's tentative track was dropped after one miss
    assert len(tr.tracks(include_tentative=True)) == 1


def test_a_track_dies_after_max_misses_and_coasts_until_then() -> None:
    cfg = TrackerConfig(confirm_hits=2, max_misses=4)
    tr = PeopleTracker(cfg)
    for k in range(5):
        tr.update([[0.1 * k, 0.0]], k * DT)  # walking at 1 m/s along x
    for m in range(1, 5):
        states = tr.update([], (4 + m) * DT)
        assert len(states) == 1 and states[0].misses == m
        assert states[0].position[0] == pytest.approx(0.4 + 0.1 * m, abs=0.05)  # coasting on
    assert tr.update([], 9 * DT) == []
    # a new person later gets a new id: ids are never reused
    tr.update([[3.0, 3.0]], 1.0)
    assert [s.id for s in tr.update([[3.0, 3.0]], 1.1)] == [2]


def test_two_people_crossing_keep_their_ids(rng: np.random.Generator) -> None:
    """Two people walk across each other (an X); near the crossing their detections merge."""
    tr = PeopleTracker()
    a0, va = np.array([0.0, -2.0]), np.array([1.0, 1.0])
    b0, vb = np.array([0.0, 2.0]), np.array([1.0, -1.0])
    ids_a: set[int] = set()
    ids_b: set[int] = set()
    for k in range(41):
        t = k * DT
        pa = a0 + va * t + rng.normal(0, 0.02, 2)
        pb = b0 + vb * t + rng.normal(0, 0.02, 2)
        dets = [(pa + pb) / 2] if np.linalg.norm(pa - pb) < 0.3 else [pa, pb]  # one blob when close
        states = tr.update(dets, t)
        if 2 <= k < 10 or k > 30:
            assert len(states) == 2
        for s in states:
            truth_a = a0 + va * t
            truth_b = b0 + vb * t
            near_a = np.linalg.norm(s.position - truth_a) < np.linalg.norm(s.position - truth_b)
            if np.linalg.norm(truth_a - truth_b) > 0.8:  # not ambiguous
                (ids_a if near_a else ids_b).add(s.id)
    assert ids_a == {1} or ids_a == {2}
    assert ids_b == {1, 2} - ids_a


def test_time_must_not_go_backwards_and_inputs_must_be_finite() -> None:
    tr = PeopleTracker()
    tr.update([[0.0, 0.0]], 1.0)
    with pytest.raises(ValueError, match="backwards"):
        tr.update([[0.0, 0.0]], 0.5)
    with pytest.raises(ValueError, match="finite"):
        tr.update([[np.nan, 0.0]], 2.0)
    tr.reset()
    assert tr.update([[0.0, 0.0]], 0.0) == []


def test_config_is_checked() -> None:
    with pytest.raises(ValueError, match="gate"):
        TrackerConfig(gate=0.0)
    with pytest.raises(ValueError, match="confirm_hits"):
        TrackerConfig(confirm_hits=0)
    with pytest.raises(ValueError, match="confirm_evidence"):
        TrackerConfig(confirm_evidence=4)  # more than confirm_hits
    with pytest.raises(ValueError, match="confirm_travel"):
        TrackerConfig(confirm_travel=0.0)


def test_detections_that_may_not_give_birth_feed_only_confirmed_tracks() -> None:
    tr = PeopleTracker(TrackerConfig(confirm_hits=3))
    for k in range(5):  # furniture: never starts a track
        assert tr.update([[1.0, 0.0]], k * DT, births=[False]) == []
    assert tr.tracks(include_tentative=True) == []
    for k in range(5, 8):  # a person walks in: born, confirmed after three scans
        out = tr.update([[3.0, 0.1 * k]], k * DT, births=[True])
    assert [t.id for t in out] == [1]
    out = tr.update([[3.0, 0.8]], 8 * DT, births=[False])  # then stands on a "static" cell
    assert out[0].misses == 0 and out[0].hits == 4
    # a no-birth detection does not feed a tentative track either
    tr2 = PeopleTracker(TrackerConfig(confirm_hits=2, tentative_misses=2))
    tr2.update([[0.0, 0.0]], 0.0)
    tr2.update([[0.0, 0.0]], DT, births=[False])
    assert [t.hits for t in tr2.tracks(include_tentative=True)] == [1]
    with pytest.raises(ValueError, match="one per detection"):
        tr2.update([[0.0, 0.0]], 2 * DT, births=[True, False])


def test_confirmation_waits_for_evidence_or_travel() -> None:
    cfg = TrackerConfig(confirm_hits=3, confirm_evidence=2)
    tr = PeopleTracker(cfg)
    for k in range(6):  # hits without evidence: tentative for ever
        assert tr.update([[1.0, 0.0]], k * DT, evidence=[False]) == []
    assert tr.update([[1.0, 0.0]], 6 * DT, evidence=[True]) == []  # one piece of evidence
    assert [t.id for t in tr.update([[1.0, 0.0]], 7 * DT, evidence=[True])] == [1]  # two
    # or it walked confirm_travel metres from where it was born
    tr = PeopleTracker(TrackerConfig(confirm_hits=3, confirm_evidence=3, confirm_travel=0.3))
    out = []
    for k in range(8):
        out = tr.update([[0.0, 0.06 * k]], k * DT, evidence=[False])
        if out:
            break
    assert out and out[0].travelled >= 0.3
    assert k >= 5  # not before it had walked that far


def test_min_travel_keeps_a_track_that_stays_put_tentative_whatever_its_evidence() -> None:
    cfg = TrackerConfig(confirm_hits=3, confirm_evidence=1, min_travel=0.2)
    tr = PeopleTracker(cfg)
    for k in range(10):  # a table leg with evidence at every scan: never confirmed
        assert tr.update([[1.0, 0.0]], k * DT, evidence=[True]) == []
    assert len(tr.tracks(include_tentative=True)) == 1
    tr = PeopleTracker(cfg)  # a walker: confirmed once it has moved 0.2 m
    out, k = [], 0
    for k in range(10):
        out = tr.update([[0.0, 0.05 * k]], k * DT, evidence=[True])
        if out:
            break
    assert out and out[0].travelled >= 0.2 and k >= 4
    # without min_travel the same table leg is confirmed after confirm_hits scans
    tr = PeopleTracker(TrackerConfig(confirm_hits=3, confirm_evidence=1))
    assert [len(tr.update([[1.0, 0.0]], k * DT, evidence=[True])) for k in range(3)] == [0, 0, 1]
    with pytest.raises(ValueError, match="min_travel"):
        TrackerConfig(min_travel=-0.1)


def test_a_hidden_track_coasts_up_to_max_occluded_seconds() -> None:
    cfg = TrackerConfig(confirm_hits=2, max_misses=2, max_occluded=1.05)
    for hidden, survives in ((True, 10), (False, 2)):
        tr = PeopleTracker(cfg)
        tr.update([[2.0, 0.0]], 0.0)
        assert [t.id for t in tr.update([[2.0, 0.0]], DT)] == [1]
        n = 0
        for k in range(2, 30):  # nobody seen from now on
            out = tr.update([], k * DT, occluded=lambda p, h=hidden: np.full(len(p), h))
            if not out:
                break
            n += 1
        # hidden: coasts while t - last_seen <= 1.05 s (10 scans); in plain view: max_misses scans
        assert n == survives
    # a detection after the occlusion takes the track up again, with its id
    tr = PeopleTracker(cfg)
    tr.update([[2.0, 0.0]], 0.0)
    tr.update([[2.0, 0.0]], DT)
    for k in range(2, 8):
        tr.update([], k * DT, occluded=lambda p: np.ones(len(p), dtype=bool))
    out = tr.update([[2.05, 0.0]], 8 * DT)
    assert [(t.id, t.misses) for t in out] == [(1, 0)]
    with pytest.raises(ValueError, match="max_occluded"):
        TrackerConfig(max_occluded=-1.0)


def test_a_track_confirmed_where_one_vanished_continues_it() -> None:
    cfg = TrackerConfig(confirm_hits=3, confirm_evidence=3, max_misses=1, revive_radius=1.0, revive_for=5.0)
    tr = PeopleTracker(cfg)
    for k in range(4):  # a walker with evidence: confirmed as 1
        out = tr.update([[0.2 * k, 0.0]], k * DT, evidence=[True])
    assert [t.id for t in out] == [1]
    for k in range(4, 7):  # out of sight: deleted after max_misses
        out = tr.update([], k * DT)
    assert out == []
    # back 0.8 m from where it was last seen, standing (no evidence): continues track 1
    for k in range(7, 10):
        out = tr.update([[1.4, 0.0]], k * DT, evidence=[False])
    assert [t.id for t in out] == [1]
    # somewhere else, or too late: no evidence, no track
    tr2 = PeopleTracker(cfg)
    for k in range(4):
        tr2.update([[0.2 * k, 0.0]], k * DT, evidence=[True])
    for k in range(4, 7):
        tr2.update([], k * DT)
    for k in range(7, 12):
        out = tr2.update([[3.0, 0.0]], k * DT, evidence=[False])
    assert out == []
    with pytest.raises(ValueError, match="revive_radius"):
        TrackerConfig(revive_radius=-1.0)
