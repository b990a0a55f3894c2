"""The motion model, the semantic observation and Monte Carlo localization in a small test world."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.localization_world import ANGLES, RANGE_MAX, drifting_odometry, labels, path, scans, world

from knowledge.localization.likelihood import LikelihoodField
from knowledge.localization.mcl import MclParams, ParticleFilter
from knowledge.localization.motion import MotionNoise, odometry_increment, sample_motion
from knowledge.localization.se2 import compose, wrap
from knowledge.localization.semantic import SemanticMap, confusion_matrix

CLASSES = ("room", "corridor")


@pytest.fixture(scope="module")
def setting() -> tuple:
    g = world()
    truth = path()
    return g, truth, scans(g, truth), drifting_odometry(truth, drift=0.01, scale=1.01)


def test_odometry_increment_by_hand() -> None:
    assert odometry_increment([0, 0, 0], [1, 1, math.pi / 2]) == pytest.approx(
        (math.pi / 4, math.sqrt(2), math.pi / 4)
    )
    # turning on the spot has no first turn (its direction would be noise)
    assert odometry_increment([1, 1, 0.2], [1.001, 1, 0.5]) == pytest.approx((0.0, 0.001, 0.3))


def test_motion_without_noise_is_the_odometry_increment_in_each_particle_frame() -> None:
    particles = np.array([[0.0, 0.0, 0.0], [5.0, -1.0, math.pi / 2]])
    out = sample_motion(
        particles, [1, 1, 0.3], [2, 1.5, 0.1], MotionNoise(0, 0, 0, 0), np.random.default_rng(0)
    )
    inc = compose([0, 0, -0.3], [1.0, 0.5, 0.1])  # ⊖(1, 1, 0.3) ⊕ (2, 1.5, 0.1), by hand
    for p, q in zip(particles, out, strict=True):
        assert np.allclose(q, compose(p, inc), atol=1e-9)


def test_motion_noise_is_centred_and_grows_with_the_motion() -> None:
    rng = np.random.default_rng(1)
    start = np.zeros((20_000, 3))
    noise = MotionNoise(0.1, 0.0005, 0.1, 0.01)
    short = sample_motion(start, [0, 0, 0], [0.2, 0, 0], noise, rng)
    long = sample_motion(start, [0, 0, 0], [2.0, 0, 0], noise, rng)
    assert np.mean(long[:, 0]) == pytest.approx(2.0, abs=0.02)
    assert np.std(long[:, 0]) == pytest.approx(math.sqrt(0.1) * 2.0, rel=0.05)
    assert np.std(long[:, 1]) > 5 * np.std(short[:, 1])


def test_confusion_matrix_by_hand() -> None:
    true = ["room", "room", "room", "corridor"]
    pred = ["room", "room", "corridor", "corridor"]
    c = confusion_matrix(true, pred, CLASSES, smoothing=1.0)
    # room: 2+1 room, 1+1 corridor -> 3/5, 2/5; corridor: 0+1, 1+1 -> 1/3, 2/3
    assert np.allclose(c, [[0.6, 0.4], [1 / 3, 2 / 3]])
    assert np.allclose(confusion_matrix([], [], CLASSES), 0.5)  # nothing seen: uniform


def test_semantic_map_reads_label_images_and_scores_cells() -> None:
    codes = np.array([[1, 1, 0], [2, 2, 7]], dtype=np.uint8)  # image orientation: row 0 on top
    sm = SemanticMap.from_codes(codes, {1: "room", 2: "corridor"}, CLASSES, [[0.9, 0.1], [0.2, 0.8]])
    assert sm.labels.tolist() == [[1, 1, -1], [0, 0, -1]]  # map orientation: row 0 at the bottom
    rows, cols = np.array([0, 1, 1, 5]), np.array([0, 0, 2, 0])
    ll = sm.log_likelihood(rows, cols, observed=1)  # the classifier says corridor
    assert np.allclose(np.exp(ll), [0.8, 0.1, 0.5, 0.5])
    with pytest.raises(ValueError):
        SemanticMap(sm.labels, CLASSES, [[0.5, 0.6], [0.5, 0.5]])


def _run(pf: ParticleFilter, truth: np.ndarray, R: np.ndarray, odo: np.ndarray, **kw: object) -> np.ndarray:
    errs = []
    for i in range(len(odo)):
        pf.update(odo[i], R[i], ANGLES, range_max=RANGE_MAX, **kw)  # type: ignore[arg-type]
        e = pf.estimate()
        errs.append(math.hypot(e.pose[0] - truth[i, 0], e.pose[1] - truth[i, 1]))
    return np.array(errs)


def test_global_localization_converges(setting: tuple) -> None:
    g, truth, R, odo = setting
    pf = ParticleFilter(
        LikelihoodField.from_grid(g),
        MclParams(particles=3000, initial_particles=20_000),
        rng=np.random.default_rng(3),
    )
    pf.init_uniform()
    errs = _run(pf, truth, R, odo)
    assert errs[-30:].max() < 0.3
    e = pf.estimate()
    assert e.share > 0.9 and e.covariance[0, 0] < 0.05
    assert abs(wrap(e.pose[2] - truth[-1, 2])) < 0.1


def test_tracking_stays_and_a_kidnapped_robot_is_found_again(setting: tuple) -> None:
    g, truth, R, odo = setting
    prm = MclParams(particles=3000, alpha_fast=0.2, alpha_slow=0.01)
    pf = ParticleFilter(LikelihoodField.from_grid(g), prm, rng=np.random.default_rng(4))
    pf.init_pose(truth[0])
    assert _run(pf, truth[:40], R[:40], odo[:40]).max() < 0.3
    # carried off: the filter believes the robot is 4 m away in the corridor
    pf.init_pose(truth[0] + np.array([4.0, 0.0, 0.0]))
    errs = _run(pf, truth, R, odo)
    assert errs[:5].min() > 2.0
    assert errs[-20:].max() < 0.3
    assert pf.injected > 0


def test_the_semantic_term_alone_moves_the_weight_to_places_of_the_observed_class(setting: tuple) -> None:
    g, _, R, odo = setting
    lf = LikelihoodField.from_grid(g)
    sm = SemanticMap.from_codes(labels(g), {1: "room", 2: "corridor"}, CLASSES, [[0.8, 0.2], [0.2, 0.8]])
    prm = MclParams(particles=4000, laser=False, alpha_fast=0.0)
    pf = ParticleFilter(lf, prm, semantic=sm, rng=np.random.default_rng(5))
    pf.init_uniform()
    corridor_share_before = np.mean(pf.particles[:, 1] < 3.0)
    for i in range(15):  # along the corridor: the classifier says corridor
        pf.update(odo[i], R[i], ANGLES, range_max=RANGE_MAX, proba=[0.1, 0.9])
    corridor_share_after = np.mean(pf.particles[:, 1] < 3.0)
    assert corridor_share_before < 0.4
    assert corridor_share_after > 0.7
