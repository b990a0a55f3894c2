"""Poses, trajectory errors (ATE/RPE against hand-computed cases and evo) and scan matching
by ranges for reference poses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from knowledge.localization.reference import match_scans
from knowledge.localization.se2 import between, compose, inverse, transform_points, wrap
from knowledge.localization.trajectory import align, associate, ate, path_pairs, rpe

finite = st.floats(-50, 50, allow_nan=False)
angle = st.floats(-math.pi, math.pi, allow_nan=False)
pose = st.tuples(finite, finite, angle)


@settings(max_examples=50, deadline=None)
@given(pose, pose)
def test_compose_inverse_and_between_round_trip(a: tuple[float, ...], b: tuple[float, ...]) -> None:
    assert np.allclose(compose(a, inverse(a)), 0.0, atol=1e-9)
    d = between(a, b)
    back = compose(a, d)
    assert np.allclose(back[:2], b[:2], atol=1e-9)
    assert abs(wrap(back[2] - b[2])) < 1e-9


def test_compose_by_hand() -> None:
    # a quarter turn at (1, 0), then 2 m ahead: (1, 2) facing +y, then a quarter turn more
    assert np.allclose(compose([1.0, 0.0, math.pi / 2], [2.0, 0.0, math.pi / 2]), [1.0, 2.0, math.pi])
    assert np.allclose(
        transform_points([1.0, 0.0, math.pi / 2], [[1.0, 0.0], [0.0, 1.0]]), [[1.0, 1.0], [0.0, 0.0]]
    )


def test_ate_by_hand() -> None:
    ref = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]])
    # the same path moved by 0.3 m in y: zero after alignment, 0.3 everywhere without
    est = ref + np.array([0.0, 0.3, 0.0])
    s, err, _ = ate(ref, est)
    assert s.rmse == pytest.approx(0.0, abs=1e-9)
    s, err, _ = ate(ref, est, aligned=False)
    assert s.rmse == pytest.approx(0.3) and s.max == pytest.approx(0.3)
    # one pose off by 0.4 m in x, the others exact, no alignment: RMS = sqrt(0.16 / 4) = 0.2
    est = ref.copy()
    est[3, 0] += 0.4
    s, err, _ = ate(ref, est, aligned=False)
    assert s.rmse == pytest.approx(0.2) and s.mean == pytest.approx(0.1) and s.median == pytest.approx(0.0)
    assert np.allclose(err, [0, 0, 0, 0.4])


def test_align_recovers_a_rigid_motion() -> None:
    rng = np.random.default_rng(1)
    ref = np.column_stack([rng.uniform(-5, 5, (30, 2)), rng.uniform(-3, 3, 30)])
    T = np.array([3.0, -2.0, 0.7])
    moved = compose(inverse(T), ref)  # the estimate lives in another frame
    assert np.allclose(align(ref, moved), T, atol=1e-9)
    assert ate(ref, moved)[0].rmse < 1e-9


def test_rpe_by_hand() -> None:
    # a straight 4 m path, 1 m steps; the estimate's second metre is 0.1 m too long
    ref = np.array([[float(i), 0.0, 0.0] for i in range(5)])
    est = ref.copy()
    est[2:, 0] += 0.1
    assert path_pairs(ref, 1.0) == [(0, 1), (1, 2), (2, 3), (3, 4)]
    t, r = rpe(ref, est, 1.0)
    assert t.n == 4 and t.max == pytest.approx(0.1) and t.mean == pytest.approx(0.025)
    assert r.max == pytest.approx(0.0)
    assert path_pairs(ref, 2.0) == [(0, 2), (2, 4)]


def test_associate_pairs_nearest_within_tolerance() -> None:
    a = [0.0, 1.0, 2.0, 3.0]
    b = [0.004, 1.02, 2.001, 2.002, 9.0]
    assert associate(a, b, 0.01).tolist() == [[0, 0], [2, 2]]
    assert associate(a, [], 0.01).shape == (0, 2)


def test_ate_and_rpe_agree_with_evo() -> None:
    evo = pytest.importorskip("evo")
    from evo.core import metrics
    from evo.core.trajectory import PoseTrajectory3D

    del evo
    rng = np.random.default_rng(7)
    n = 200
    th = np.cumsum(rng.normal(0, 0.1, n))
    xy = np.cumsum(np.column_stack([np.cos(th), np.sin(th)]) * 0.3, axis=0)
    ref = np.column_stack([xy, wrap(th)])
    est = compose([0.5, -1.0, 0.3], ref + rng.normal(0, [0.05, 0.05, 0.02], (n, 3)))

    def traj(p: np.ndarray) -> PoseTrajectory3D:
        q = np.column_stack([np.cos(p[:, 2] / 2), np.zeros(n), np.zeros(n), np.sin(p[:, 2] / 2)])
        return PoseTrajectory3D(np.column_stack([p[:, :2], np.zeros(n)]), q, np.arange(n, dtype=float))

    t_ref, t_est = traj(ref), traj(est)
    t_est.align(t_ref, correct_scale=False)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((t_ref, t_est))
    assert ate(ref, est)[0].rmse == pytest.approx(ape.get_statistic(metrics.StatisticsType.rmse), rel=1e-6)
    for delta in (1.0, 5.0):
        rel = metrics.RPE(
            metrics.PoseRelation.translation_part, delta, metrics.Unit.meters, pairs_from_reference=True
        )
        rel.process_data((traj(ref), traj(est)))
        ours, _ = rpe(ref, est, delta)
        assert ours.rmse == pytest.approx(rel.get_statistic(metrics.StatisticsType.rmse), rel=1e-6)


def test_match_scans_in_order_with_repeats_and_strangers() -> None:
    a, b, c = np.array([1.0, 2.0]), np.array([1.0, 2.5]), np.array([3.0, 3.0])
    raw = [a, a, b, c, a, b]
    # printed with other digits: equal as numbers
    ref = [np.array([1.000000, 2.50]), np.array([1.0, 2.0]), np.array([9.0, 9.0]), np.array([1.0, 2.5])]
    assert match_scans(raw, ref) == [(2, 0), (4, 1), (5, 3)]
    assert match_scans(raw, []) == []


def test_convergence_and_distance_driven() -> None:
    from knowledge.localization.evaluation import convergence, odometry_distance

    assert convergence([2.0, 0.3, 0.9, 0.4, 0.2]) == 3  # below 0.5 from the 4th on
    assert convergence([0.1, 0.2]) == 0
    assert convergence([0.1, 0.7]) is None  # ends above: not converged
    assert convergence([]) is None
    assert np.allclose(odometry_distance([[0, 0, 0], [3, 4, 1], [3, 5, 0]]), [0.0, 5.0, 6.0])
