"""The semantic observation as a likelihood per class (argmax or the whole histogram), draws of
particles in proportion to it (the semantic proposal), and how the filter uses both."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.localization_world import ANGLES, RANGE_MAX, drifting_odometry, labels, path, scans, world

from knowledge.localization.likelihood import LikelihoodField
from knowledge.localization.mcl import MclParams, ParticleFilter, history_scores
from knowledge.localization.semantic import SemanticMap

CLASSES = ("room", "corridor")
CONFUSION = [[0.8, 0.2], [0.3, 0.7]]  # rows: true room, true corridor


@pytest.fixture(scope="module")
def setting() -> tuple:
    g = world()
    truth = path()
    sm = SemanticMap.from_codes(labels(g), {1: "room", 2: "corridor"}, CLASSES, CONFUSION)
    return g, LikelihoodField.from_grid(g), sm, truth, scans(g, truth), drifting_odometry(truth, drift=0.01)


def _in_corridor(P: np.ndarray) -> np.ndarray:
    return P[:, 1] < 3.0  # map frame: the test world's grid has no offset, corridor below y = 3 m


def test_class_likelihood_by_hand() -> None:
    sm = SemanticMap(np.zeros((2, 2), dtype=np.int8), CLASSES, np.asarray(CONFUSION))
    # argmax: the histogram says corridor -> the corridor column, 1/K for no class
    assert np.allclose(sm.class_likelihood([0.4, 0.6]), [0.2, 0.7, 0.5])
    # histogram: 0.4 * room column + 0.6 * corridor column
    assert np.allclose(
        sm.class_likelihood([0.4, 0.6], "histogram"), [0.4 * 0.8 + 0.6 * 0.2, 0.4 * 0.3 + 0.6 * 0.7, 0.5]
    )
    # an unnormalised histogram is normalised; a certain one is the argmax column
    assert np.allclose(sm.class_likelihood([0.0, 2.0], "histogram"), [0.2, 0.7, 0.5])
    with pytest.raises(ValueError):
        sm.class_likelihood([0.5, 0.5], "votes")
    with pytest.raises(ValueError):
        sm.class_likelihood([0.0, 0.0])
    with pytest.raises(ValueError):
        MclParams(semantic_observation="votes")


def test_classes_at_marks_cells_without_class_and_outside_with_k() -> None:
    sm = SemanticMap(np.array([[0, 1], [-1, 0]], dtype=np.int8), CLASSES, np.asarray(CONFUSION))
    y = sm.classes_at(np.array([0, 0, 1, 1, 5, -1]), np.array([0, 1, 0, 1, 0, 0]))
    assert y.tolist() == [0, 1, 2, 0, 2, 2]


def test_semantic_draw_puts_the_particles_in_proportion_to_the_likelihood(setting: tuple) -> None:
    _, lf, sm, *_ = setting
    pf = ParticleFilter(lf, MclParams(particles=100), semantic=sm, rng=np.random.default_rng(0))
    free = lf.free
    rows = np.nonzero(free)[0]
    n_corr = np.sum((rows + 0.5) * lf.resolution < 3.0)
    n_room = rows.size - n_corr
    lik = np.array([0.2, 0.7, 0.5])  # the scan says corridor
    P = pf.semantic_draw(40_000, lik)
    expected = n_corr * 0.7 / (n_corr * 0.7 + n_room * 0.2)
    assert np.mean(_in_corridor(P)) == pytest.approx(expected, abs=0.01)
    assert expected > 0.5 > n_corr / rows.size  # more than the uniform share, by a margin
    # every particle on a free cell, headings all around
    r = np.floor(P[:, 1] / lf.resolution).astype(int)
    c = np.floor(P[:, 0] / lf.resolution).astype(int)
    assert free[r, c].all()
    assert P[:, 2].min() < -3.0 and P[:, 2].max() > 3.0
    with pytest.raises(ValueError):
        pf.semantic_draw(10, [0.5, 0.5])


def test_the_initial_semantic_draw_holds_the_first_observation_once(setting: tuple) -> None:
    _, lf, sm, _, R, odo = setting
    prm = MclParams(particles=5000, laser=False, semantic_proposal=True, alpha_fast=0.0)
    pf = ParticleFilter(lf, prm, semantic=sm, rng=np.random.default_rng(1))
    pf.init_uniform()
    uniform_share = np.mean(_in_corridor(pf.particles))
    assert pf.update(odo[0], R[0], ANGLES, range_max=RANGE_MAX, proba=[0.1, 0.9])
    # drawn in proportion to Pr(corridor | y), and not weighted by it a second time
    assert np.mean(_in_corridor(pf.particles)) > uniform_share + 0.2
    assert np.allclose(pf.weights, 1.0 / 5000)
    # without the proposal the same first update weighs the uniform particles instead
    plain = ParticleFilter(lf, MclParams(particles=5000, laser=False, alpha_fast=0.0), semantic=sm)
    plain.init_uniform()
    plain.update(odo[0], R[0], ANGLES, range_max=RANGE_MAX, proba=[0.1, 0.9])
    w = plain.weights
    assert np.sum(w[_in_corridor(plain.particles)]) / np.sum(
        w[~_in_corridor(plain.particles)]
    ) == pytest.approx(
        np.mean(_in_corridor(plain.particles)) * 0.7 / (np.mean(~_in_corridor(plain.particles)) * 0.2),
        rel=1e-6,
    )


def test_semantic_distance_skips_repeated_labels_but_not_a_change_of_class(setting: tuple) -> None:
    _, lf, sm, _, R, odo = setting
    prm = MclParams(
        particles=2000, laser=False, semantic_distance=100.0, alpha_fast=0.0, resample_threshold=0.0
    )
    pf = ParticleFilter(lf, prm, semantic=sm, rng=np.random.default_rng(2))
    pf.init_uniform()
    pf.update(odo[0], R[0], ANGLES, range_max=RANGE_MAX, proba=[0.1, 0.9])  # the first label counts
    corr = _in_corridor(pf.particles)
    ratio = pf.weights[corr][0] / pf.weights[~corr][0]
    assert ratio == pytest.approx(0.7 / 0.2)
    i = 1
    while not pf.update(odo[i], R[i], ANGLES, range_max=RANGE_MAX, proba=[0.2, 0.8]):  # same class again
        i += 1
    corr = _in_corridor(pf.particles)
    w = pf.weights
    # no second corridor factor (the motion moves a few particles across the wall: medians)
    assert np.median(w[corr]) / np.median(w[~corr]) == pytest.approx(0.7 / 0.2, rel=0.01)
    i += 1
    while not pf.update(odo[i], R[i], ANGLES, range_max=RANGE_MAX, proba=[0.9, 0.1]):  # now room
        i += 1
    corr = _in_corridor(pf.particles)
    w = pf.weights
    assert np.median(w[corr]) / np.median(w[~corr]) == pytest.approx((0.7 * 0.3) / (0.2 * 0.8), rel=0.01)


def test_recovery_draws_its_random_particles_from_the_semantic_proposal(setting: tuple) -> None:
    _, lf, sm, _, R, odo = setting
    shares = {}
    for proposal in (False, True):
        prm = MclParams(particles=4000, laser=False, semantic_proposal=proposal)
        pf = ParticleFilter(lf, prm, semantic=sm, rng=np.random.default_rng(3))
        pf.init_pose([3.0, 6.0, 0.0])  # everything in the left room
        pf.update(odo[0], R[0], ANGLES, range_max=RANGE_MAX, proba=[0.05, 0.95])
        pf._w_slow, pf._w_fast = 1.0, 0.5  # the scans stopped fitting: half of them drawn anew
        pf._resample()
        assert 1700 < pf.injected < 2300
        shares[proposal] = np.mean(_in_corridor(pf.particles))
    n = lf.free.sum()
    rows = np.nonzero(lf.free)[0]
    corr = np.mean((rows + 0.5) * lf.resolution < 3.0)
    assert shares[False] == pytest.approx(0.5 * corr, abs=0.03)
    assert shares[True] == pytest.approx(0.5 * corr * 0.7 / (corr * 0.7 + (1 - corr) * 0.2), abs=0.03)
    assert n > 0 and math.isfinite(shares[True])


def _labels_along(truth: np.ndarray) -> list[list[float]]:
    """A classifier that is right: room above the corridor wall (y = 3 m), corridor below."""
    return [[0.9, 0.1] if t[1] > 3.05 else [0.1, 0.9] for t in truth]


def test_the_history_proposal_keeps_the_places_whose_past_labels_fit(setting: tuple) -> None:
    _, lf, sm, truth, R, odo = setting
    prm = MclParams(particles=2000, laser=False, semantic_proposal=True, proposal_history=10.0)
    pf = ParticleFilter(lf, prm, semantic=sm, rng=np.random.default_rng(6))
    pf.init_pose(truth[0])
    proba = _labels_along(truth)
    i = 0
    while truth[i, 1] < 3.6:  # along the corridor and 0.6 m into the middle room
        pf.update(odo[i], R[i], ANGLES, range_max=RANGE_MAX, proba=proba[i])
        i += 1
    assert proba[i - 1][0] > 0.5 and 4 <= len(pf._history) <= 11
    assert pf._likelihood is not None
    now = pf.semantic_draw(4000, pf._likelihood)  # the current label only: mostly the rooms
    hist = pf.history_draw(4000)  # and corridor labels behind: not deep in a room

    def deep_in_a_room(P: np.ndarray) -> float:
        return float(np.mean(P[:, 1] > 5.5))  # over 2.5 m from the corridor wall

    def facing_up(P: np.ndarray) -> float:  # away from the corridor, as the robot drives
        return float(np.mean(np.abs(wrap_angle(P[:, 2] - math.pi / 2)) < math.pi / 4))

    assert deep_in_a_room(now) > 0.35 and deep_in_a_room(hist) < 0.2
    assert facing_up(now) < 0.3 and facing_up(hist) > 0.4


def wrap_angle(a: np.ndarray) -> np.ndarray:
    return (a + math.pi) % (2 * math.pi) - math.pi


def test_semantic_recovery_draws_new_particles_when_the_labels_stop_fitting(setting: tuple) -> None:
    _, lf, sm, truth, R, odo = setting
    injected = {}
    for recovery in (False, True):
        prm = MclParams(particles=2000, semantic_weight=0.0, semantic_recovery=recovery)
        pf = ParticleFilter(lf, prm, semantic=sm, rng=np.random.default_rng(7))
        pf.init_pose(truth[0])
        for i in range(55):  # along the corridor: corridor for 2 m, then the classifier says room
            pf.update(odo[i], R[i], ANGLES, range_max=RANGE_MAX, proba=[0.1, 0.9] if i < 20 else [0.9, 0.1])
        injected[recovery] = pf.injected
    assert injected[False] == 0  # the scans fit all along
    assert injected[True] > 100


def test_history_scores_by_hand() -> None:
    labels = np.array([[0, 0, 1, 1], [0, 0, 1, -1]], dtype=np.int8)  # 1 m cells, row 0 at y 0-1
    loglik = np.log(np.array([[0.8, 0.2, 0.5], [0.3, 0.7, 0.5]]))  # two labels: room, then corridor
    rel = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])  # 1 m behind and 1 m ahead of the candidate
    cand = np.array([[1.5, 0.5, 0.0], [2.5, 1.5, 0.0], [1.5, 0.5, math.pi], [3.5, 1.5, 0.0]])
    got = history_scores(cand, rel, loglik, labels, 1.0)
    # (1.5, 0.5) facing +x: behind (0.5, 0.5) room -> 0.8, ahead (2.5, 0.5) corridor -> 0.7
    # (2.5, 1.5): behind (1.5, 1.5) room 0.8, ahead (3.5, 1.5) no class 0.5
    # facing -x: behind (2.5, 0.5) corridor -> 0.2, ahead (0.5, 0.5) room -> 0.3
    # (3.5, 1.5): behind (2.5, 1.5) corridor 0.2, ahead (4.5, 1.5) outside 0.5
    want = np.log([0.8 * 0.7, 0.8 * 0.5, 0.2 * 0.3, 0.2 * 0.5])
    assert np.allclose(got, want)


def test_history_reset_redraws_the_particles_whose_past_labels_do_not_fit(setting: tuple) -> None:
    _, lf, sm, truth, R, odo = setting
    proba = _labels_along(truth)
    out = {}
    for reset in (0.0, 1.0):
        for start in ("right", "wrong"):
            prm = MclParams(
                particles=2000,
                laser=False,
                semantic_proposal=True,
                proposal_history=10.0,
                alpha_fast=0.0,  # no augmented recovery: what is drawn anew is the reset's
                resample_threshold=1.0,
                history_reset=reset,
            )
            pf = ParticleFilter(lf, prm, semantic=sm, rng=np.random.default_rng(8))
            # the robot drives 5.5 m along the corridor; the filter believes it in the left room
            pf.init_pose(truth[0] if start == "right" else [0.5, 8.0, 0.0])
            i = 0
            while truth[i, 0] < 6.3:
                pf.update(odo[i], R[i], ANGLES, range_max=RANGE_MAX, proba=proba[i])
                i += 1
            l_p, l_q = pf.history_fit()
            out[reset, start] = (l_p / l_q, pf.injected, float(np.mean(_in_corridor(pf.particles))))
    # where the particles are right their labels fit as well as the best places do
    assert out[0.0, "right"][0] > 0.9 and out[1.0, "right"][1] == 0
    # in the room, the corridor's labels fit far worse there
    assert out[0.0, "wrong"][0] < 0.5
    # without the reset nothing leaves the room; with it most particles are in the corridor
    assert out[0.0, "wrong"][1] == 0 and out[0.0, "wrong"][2] < 0.05
    assert out[1.0, "wrong"][1] > 1000 and out[1.0, "wrong"][2] > 0.8
    with pytest.raises(ValueError):
        MclParams(history_reset=-1.0)
