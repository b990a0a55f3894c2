"""CLEAR-MOT as the leg_tracker benchmark scores it: hand-computed sequences for each rule,
and the counts of the ``motmetrics`` package where the rules coincide (one annotated person)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from knowledge.people.clearmot import MotFrame, clear_mot, detection_scores


def fr(truth: list[tuple[int, float, float]], est: list[tuple[int, float, float]]) -> MotFrame:
    return MotFrame.of(truth, est)


def test_perfect_tracking_scores_mota_one_and_motp_the_mean_distance() -> None:
    frames = [fr([(1, 0.0, 0.0), (2, 5.0, 0.0)], [(10, 0.1, 0.0), (11, 5.0, 0.3)]) for _ in range(4)]
    r = clear_mot(frames)
    assert (r.valid, r.id_switches, r.misses, r.false_positives, r.objects) == (8, 0, 0, 0, 8)
    assert r.mota == 1.0
    assert r.motp == pytest.approx(0.2)


def test_misses_and_false_positives_count_per_frame() -> None:
    frames = [
        fr([(1, 0.0, 0.0)], []),  # miss
        fr([], [(5, 3.0, 3.0)]),  # false positive, no annotation at all
        fr([(1, 0.0, 0.0)], [(5, 3.0, 3.0)]),  # too far: a miss and a false positive
        fr([(1, 0.0, 0.0)], [(6, 0.5, 0.0)]),  # matched
    ]
    r = clear_mot(frames)
    assert (r.valid, r.misses, r.false_positives, r.objects, r.frames) == (1, 2, 2, 3, 4)
    assert r.mota == pytest.approx(1 - 4 / 3)
    assert r.motp == pytest.approx(0.5)


def test_the_match_distance_is_strict() -> None:
    assert clear_mot([fr([(1, 0.0, 0.0)], [(2, 0.75, 0.0)])]).misses == 1
    assert clear_mot([fr([(1, 0.0, 0.0)], [(2, 0.7499, 0.0)])]).valid == 1
    assert clear_mot([fr([(1, 0.0, 0.0)], [(2, 0.9, 0.0)])], threshold=1.0).valid == 1


def test_a_new_track_on_a_tracked_person_is_a_switch() -> None:
    # the person keeps id 1; the tracker's id changes from 10 to 11 (gt side of rule 4)
    frames = [fr([(1, 0.0, 0.0)], [(10, 0.0, 0.0)]), fr([(1, 0.1, 0.0)], [(11, 0.1, 0.0)])]
    r = clear_mot(frames)
    assert (r.valid, r.id_switches) == (1, 1)
    assert r.mota == pytest.approx(0.5)


def test_a_track_that_jumps_to_another_person_is_a_switch_from_its_side() -> None:
    # track 10 follows person 1, then person 2 (never matched before): the estimate side of rule 4
    frames = [
        fr([(1, 0.0, 0.0), (2, 3.0, 0.0)], [(10, 0.0, 0.0)]),
        fr([(1, 0.0, 0.0), (2, 3.0, 0.0)], [(10, 3.0, 0.0)]),
    ]
    r = clear_mot(frames)
    assert (r.valid, r.id_switches, r.misses) == (1, 1, 2)


def test_a_kept_correspondence_wins_over_a_nearer_newcomer() -> None:
    # person 1 matched to track 10 at 0.5 m; track 11 appears at 0.05 m: 10 keeps the person
    frames = [
        fr([(1, 0.0, 0.0)], [(10, 0.5, 0.0)]),
        fr([(1, 0.0, 0.0)], [(10, 0.5, 0.0), (11, 0.05, 0.0)]),
    ]
    r = clear_mot(frames, keep_events=True)
    assert (r.valid, r.id_switches, r.false_positives) == (2, 0, 1)
    assert r.motp == pytest.approx(0.5)
    assert [e[1:] for e in r.events] == [(1, 0, 0, 0), (1, 0, 0, 1)]


def test_the_hungarian_step_minimises_the_sum_over_all_pairs_then_drops_far_ones() -> None:
    # tracks at 0 and 1.4, people at 0.7 and 2.1: the optimal assignment pairs (0, 0.7) and
    # (1.4, 2.1), both 0.7 m: both matched (a greedy nearest-first would do the same here)
    r = clear_mot([fr([(1, 0.7, 0.0), (2, 2.1, 0.0)], [(10, 0.0, 0.0), (11, 1.4, 0.0)])])
    assert r.valid == 2 and r.motp == pytest.approx(0.7)
    # one track between two people, 0.3 m and 0.5 m away: it takes the nearer
    r = clear_mot([fr([(1, 0.3, 0.0), (2, -0.5, 0.0)], [(10, 0.0, 0.0)])])
    assert (r.valid, r.misses) == (1, 1) and r.motp == pytest.approx(0.3)


def test_a_correspondence_is_forgotten_once_either_id_is_matched_elsewhere() -> None:
    # 10↔1, then 10↔2 (switch, 10's side), then 11↔1: 1's old partner 10 went to 2, so the
    # pair (10, 1) was forgotten and 11↔1 is counted valid (motmetrics would count a switch)
    frames = [
        fr([(1, 0.0, 0.0), (2, 3.0, 0.0)], [(10, 0.0, 0.0)]),
        fr([(1, 0.0, 0.0), (2, 3.0, 0.0)], [(10, 3.0, 0.0)]),
        fr([(1, 0.0, 0.0), (2, 3.0, 0.0)], [(10, 3.0, 0.0), (11, 0.0, 0.0)]),
    ]
    r = clear_mot(frames, keep_events=True)
    assert [e[1:3] for e in r.events] == [(1, 0), (0, 1), (2, 0)]


def test_objects_are_valid_plus_switches_plus_misses_on_random_sequences(rng: np.random.Generator) -> None:
    for _ in range(30):
        frames = []
        for _ in range(20):
            g = rng.choice(6, size=rng.integers(0, 4), replace=False)
            e = rng.choice(8, size=rng.integers(0, 5), replace=False)
            frames.append(
                fr(
                    [(int(i), *rng.uniform(0, 3, 2)) for i in g],
                    [(int(i), *rng.uniform(0, 3, 2)) for i in e],
                )
            )
        r = clear_mot(frames)
        assert r.objects == r.valid + r.id_switches + r.misses
        assert r.false_positives == sum(f.estimate.shape[0] for f in frames) - r.matches


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match="unique"):
        MotFrame.of([(1, 0.0, 0.0), (1, 1.0, 0.0)], [])
    with pytest.raises(ValueError, match="finite"):
        MotFrame.of([], [(1, math.nan, 0.0)])
    with pytest.raises(ValueError, match="threshold"):
        clear_mot([], threshold=0.0)
    with pytest.raises(ValueError, match="distance"):
        detection_scores([], distance=-1.0)
    r = clear_mot([])
    assert math.isnan(r.mota) and math.isnan(r.motp) and r.as_dict()["mota_pct"] is None


def test_detection_precision_and_recall_match_one_to_one_within_the_distance() -> None:
    frames = [
        (np.array([[0.0, 0.0], [2.0, 0.0]]), np.array([[0.1, 0.0], [0.2, 0.0], [5.0, 5.0]])),
        (np.array([[0.0, 0.0]]), np.zeros((0, 2))),
        (np.zeros((0, 2)), np.array([[1.0, 1.0]])),
        (np.array([[0.0, 0.0]]), np.array([[0.5, 0.0]])),  # exactly at the distance: found
    ]
    d = detection_scores(frames)
    assert (d.true_positives, d.false_positives, d.false_negatives, d.frames) == (2, 3, 2, 4)
    assert d.precision == pytest.approx(2 / 5) and d.recall == pytest.approx(2 / 4)


def test_one_person_agrees_with_motmetrics(rng: np.random.Generator) -> None:
    """One annotated person, a track around it with noise, dropouts and id changes, and
    clutter tracks: the same counts as the motmetrics package. (With several people the
    benchmark also counts a switch from the track's side, and forgets a correspondence as
    soon as either id is matched elsewhere: tests above.)"""
    mm = pytest.importorskip("motmetrics")
    for trial in range(40):
        acc = mm.MOTAccumulator(auto_id=True)
        frames = []
        gt_id, track_id = 1, 100
        for _ in range(60):
            if rng.random() < 0.08:
                track_id += 1
            truth = [(gt_id, *rng.uniform(0, 4, 2))] if rng.random() < 0.8 else []
            est = []
            if truth and rng.random() < 0.7:
                est.append((track_id, truth[0][1] + rng.normal(0, 0.4), truth[0][2] + rng.normal(0, 0.4)))
            for k in range(int(rng.integers(0, 3))):
                est.append((1000 + k, *rng.uniform(0, 4, 2)))
            fr = MotFrame.of(truth, est)
            frames.append(fr)
            d = np.hypot(
                fr.truth[:, None, 0] - fr.estimate[None, :, 0], fr.truth[:, None, 1] - fr.estimate[None, :, 1]
            )
            acc.update(fr.truth_ids.tolist(), fr.estimate_ids.tolist(), np.where(d < 0.75, d, np.nan))
        r = clear_mot(frames)
        s = mm.metrics.create().compute(
            acc,
            metrics=["num_objects", "num_false_positives", "num_misses", "num_switches", "mota", "motp"],
            name="x",
        )
        row = s.iloc[0]
        got = (r.objects, r.false_positives, r.misses, r.id_switches)
        want = tuple(
            int(row[k]) for k in ("num_objects", "num_false_positives", "num_misses", "num_switches")
        )
        assert got == want, f"trial {trial}"
        assert r.mota == pytest.approx(float(row["mota"]))
        assert r.motp == pytest.approx(float(row["motp"]))
