"""Probabilistic relaxation labeling (book eq. 4.6–4.8) on small synthetic maps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from knowledge.labels import CORRIDOR, DOORWAY, IPA_CODES, ROOM, read_label_image
from knowledge.places.relaxation import (
    DIRECTIONS,
    CompatibilityStats,
    argmax_labels,
    compatibility,
    relax,
)

CLASSES = (ROOM, CORRIDOR, DOORWAY)


def office(rows: int = 60, cols: int = 90) -> tuple[np.ndarray, np.ndarray]:
    """A corridor between two rows of rooms, with doorways: ``(labels, occupied)``."""
    lab = np.zeros((rows, cols), np.uint8)
    occ = np.ones((rows, cols), bool)
    occ[2:-2, 2:-2] = False
    lab[2:-2, 2:-2] = ROOM
    mid = rows // 2
    lab[mid - 4 : mid + 4, 2:-2] = CORRIDOR
    occ[mid - 5, 2:-2] = True
    occ[mid + 4, 2:-2] = True
    for c0 in range(8, cols - 12, 25):
        occ[mid - 5, c0 : c0 + 6] = False
        occ[mid + 4, c0 : c0 + 6] = False
        lab[mid - 7 : mid - 3, c0 : c0 + 6] = DOORWAY
        lab[mid + 3 : mid + 7, c0 : c0 + 6] = DOORWAY
    for c in range(20, cols - 2, 25):  # walls between rooms
        occ[2 : mid - 5, c] = True
        occ[mid + 5 : -2, c] = True
    lab[occ] = 0
    return lab, occ


def noisy_histograms(lab: np.ndarray, rng: np.random.Generator, flip: float = 0.2) -> np.ndarray:
    """One-hot truth blurred with noise, and a fraction of cells confidently wrong."""
    col = {ROOM: 0, CORRIDOR: 1, DOORWAY: 2}
    idx = np.vectorize(lambda v: col.get(int(v), 0))(lab)
    onehot = np.eye(3, dtype=np.float32)[idx]
    P = 0.5 * onehot + 0.5 * rng.dirichlet([1, 1, 1], size=lab.shape).astype(np.float32)
    wrong = rng.random(lab.shape) < flip
    P[wrong] = np.eye(3, dtype=np.float32)[rng.integers(0, 3, int(wrong.sum()))] * 0.7 + 0.1
    return np.concatenate([P, np.zeros((*lab.shape, 1), np.float32)], axis=2)


def isolated(labels: np.ndarray, free: np.ndarray) -> int:
    """Free cells whose label no free 8-neighbour shares."""
    pad = np.pad(labels.astype(np.int16), 1, constant_values=-1)
    padf = np.pad(free, 1)
    rows, cols = labels.shape
    same = np.zeros(labels.shape, bool)
    for dr, dc in DIRECTIONS:
        nb = pad[1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols]
        nf = padf[1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols]
        same |= (nb == labels) & nf
    return int((free & ~same).sum())


@pytest.fixture(scope="module")
def stats() -> CompatibilityStats:
    lab, occ = office()
    return CompatibilityStats.from_label_images([(lab, occ)], CLASSES)


# ---------------------------------------------------------------------- eq. 4.8
def test_compatibility_by_hand() -> None:
    # p(k) < p(k|k'): (1 - p/c) / (1 - p); otherwise c/p - 1
    assert compatibility(np.array([0.5]), np.array([[0.75]]))[0, 0] == pytest.approx((1 - 0.5 / 0.75) / 0.5)
    assert compatibility(np.array([0.5]), np.array([[0.25]]))[0, 0] == pytest.approx(-0.5)
    assert compatibility(np.array([0.2]), np.array([[0.2]]))[0, 0] == pytest.approx(0.0)
    assert compatibility(np.array([0.2]), np.array([[1.0]]))[0, 0] == pytest.approx(1.0)
    assert compatibility(np.array([0.2]), np.array([[0.0]]))[0, 0] == pytest.approx(-1.0)


def test_counts_and_r_on_a_strip_by_hand() -> None:
    # one row: wall room room corridor wall; only horizontal pairs exist
    lab = np.array([[0, ROOM, ROOM, CORRIDOR, 0]], np.uint8)
    occ = np.array([[True, False, False, False, True]])
    s = CompatibilityStats.from_label_images([(lab, occ)], (ROOM, CORRIDOR))
    # labels room=0, corridor=1, wall=2; ordered pairs (i, j):
    # W-R R-W R-R R-R R-C C-R C-W W-C
    expected_counts = np.array([[2, 1, 1], [1, 0, 1], [1, 1, 0]], float)
    np.testing.assert_array_equal(s.counts[0], expected_counts)
    np.testing.assert_allclose(s.prior[0], [0.5, 0.25, 0.25])
    # p(k | k'): columns normalised
    np.testing.assert_allclose(s.conditional[0][:, 0], [0.5, 0.25, 0.25])
    np.testing.assert_allclose(s.conditional[0][:, 1], [0.5, 0.0, 0.5])
    np.testing.assert_allclose(s.conditional[0][:, 2], [0.5, 0.5, 0.0])
    two_thirds = (1 - 0.25 / 0.5) / (1 - 0.25)
    expected_r = np.array([[0, 0, 0], [0, -1, two_thirds], [0, two_thirds, -1]])
    np.testing.assert_allclose(s.r[0], expected_r, atol=1e-6)


def test_walls_deep_inside_or_outside_are_not_counted() -> None:
    lab = np.array([[0, ROOM, ROOM, CORRIDOR, 0]], np.uint8)
    occ = np.array([[True, False, False, False, True]])
    wide_lab = np.pad(lab, ((3, 3), (5, 5)))
    wide_occ = np.pad(occ, ((3, 3), (5, 5)), constant_values=True)
    a = CompatibilityStats.from_label_images([(lab, occ)], (ROOM, CORRIDOR))
    b = CompatibilityStats.from_label_images([(wide_lab, wide_occ)], (ROOM, CORRIDOR))
    # the walls touching labelled cells are now 3x3 rings: more wall pairs, but an unlimited
    # margin does not change the counts further
    wider = CompatibilityStats.from_label_images(
        [(np.pad(wide_lab, 20), np.pad(wide_occ, 20, constant_values=True))], (ROOM, CORRIDOR)
    )
    np.testing.assert_array_equal(b.counts, wider.counts)
    assert b.counts[0, 2, 2] > a.counts[0, 2, 2]


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3),
    st.lists(st.floats(0.0, 1.0), min_size=9, max_size=9),
)
def test_r_lies_in_bounds_and_has_the_sign_of_the_evidence(prior: list[float], cond: list[float]) -> None:
    p = np.array(prior)
    c = np.array(cond).reshape(3, 3)
    r = compatibility(p, c)
    assert np.all(r >= -1) and np.all(r <= 1)
    seen = p[:, None] > 0
    assert np.all(r[seen & (c > p[:, None])] > 0)
    assert np.all(r[seen & (c < p[:, None])] < 0)


def test_r_bounds_and_self_compatibility_on_training_map(stats: CompatibilityStats) -> None:
    assert stats.r.min() >= -1 and stats.r.max() <= 1
    # a label's neighbours mostly share it
    assert np.all(np.diag(stats.r[0]) > 0)
    assert stats.label_names == ("room", "corridor", "doorway", "wall")


def test_unknown_label_code_is_an_error() -> None:
    lab, occ = office()
    lab[10, 10] = 4
    with pytest.raises(ValueError, match="not among the classes"):
        CompatibilityStats.from_label_images([(lab, occ)], CLASSES)


def test_per_direction_counts_sum_to_pooled() -> None:
    lab, occ = office()
    pooled = CompatibilityStats.from_label_images([(lab, occ)], CLASSES)
    per = CompatibilityStats.from_label_images([(lab, occ)], CLASSES, per_direction=True)
    assert per.per_direction and not pooled.per_direction
    np.testing.assert_array_equal(per.counts.sum(axis=0), pooled.counts[0])
    # a pair seen from i towards d is the transposed pair seen from j towards -d
    for d, (dr, dc) in enumerate(DIRECTIONS):
        e = next(i for i, (a, b) in enumerate(DIRECTIONS) if (a, b) == (-dr, -dc))
        np.testing.assert_array_equal(per.counts[d], per.counts[e].T)


def test_arrays_round_trip_through_npz(tmp_path: Path, stats: CompatibilityStats) -> None:
    path = tmp_path / "model.npz"
    np.savez(path, allow_pickle=False, **stats.to_arrays())
    with np.load(path, allow_pickle=False) as z:
        back = CompatibilityStats.from_arrays(dict(z))
    assert back.classes == stats.classes
    np.testing.assert_array_equal(back.r, stats.r)
    with pytest.raises(ValueError, match="missing"):
        CompatibilityStats.from_arrays({})


# ---------------------------------------------------------------------- relaxation
def test_relaxation_cleans_a_noisy_map(stats: CompatibilityStats, rng: np.random.Generator) -> None:
    lab, occ = office()
    free = ~occ
    P0 = noisy_histograms(lab, rng)
    before = argmax_labels(P0, stats)
    P = relax(P0, stats, free_mask=free, iterations=50)
    after = argmax_labels(P, stats)
    acc_before = (before == lab)[free].mean()
    acc_after = (after == lab)[free].mean()
    assert acc_before < 0.9
    assert acc_after > acc_before + 0.05
    assert isolated(after, free) < isolated(before, free) / 5


def test_histograms_stay_normalised_and_walls_stay_walls(
    stats: CompatibilityStats, rng: np.random.Generator
) -> None:
    lab, occ = office()
    P0 = noisy_histograms(lab, rng)
    P0[occ] = rng.random((int(occ.sum()), 4))  # whatever the classifier says there is ignored
    P = relax(P0, stats, free_mask=~occ, iterations=20)
    assert P.dtype == np.float32 and P.shape == P0.shape
    np.testing.assert_allclose(P.sum(axis=2), 1.0, atol=1e-5)
    assert np.all(P >= 0)
    np.testing.assert_array_equal(P[occ, 3], 1.0)
    np.testing.assert_array_equal(P[~occ, 3], 0.0)
    assert np.all(argmax_labels(P, stats)[occ] == 0)
    # the classifier's output has no wall column worth reading: empty rows are no label
    P0[occ] = 0
    assert np.all(argmax_labels(P0, stats)[occ] == 0)
    assert np.all(argmax_labels(P, stats, free_mask=np.zeros(occ.shape, bool)) == 0)


def test_flips_and_rotations_commute_with_pooled_relaxation(
    stats: CompatibilityStats, rng: np.random.Generator
) -> None:
    lab, occ = office(40, 50)
    P0 = noisy_histograms(lab, rng)
    P = relax(P0, stats, free_mask=~occ, iterations=10)
    for f in (np.fliplr, np.flipud, lambda a: np.rot90(a, 1, axes=(0, 1))):
        Pf = relax(np.ascontiguousarray(f(P0)), stats, free_mask=np.ascontiguousarray(f(~occ)), iterations=10)
        np.testing.assert_allclose(Pf, f(P), atol=1e-5)


def test_backends_agree(stats: CompatibilityStats, rng: np.random.Generator) -> None:
    lab, occ = office(40, 50)
    P0 = noisy_histograms(lab, rng)
    a = relax(P0, stats, free_mask=~occ, iterations=15, backend="cv2")
    b = relax(P0, stats, free_mask=~occ, iterations=15, backend="numpy")
    np.testing.assert_allclose(a, b, atol=1e-5)


def test_per_direction_with_equal_tables_equals_pooled(
    stats: CompatibilityStats, rng: np.random.Generator
) -> None:
    same = CompatibilityStats(stats.classes, np.repeat(stats.counts, 8, axis=0))
    assert same.per_direction
    lab, occ = office(40, 50)
    P0 = noisy_histograms(lab, rng)
    a = relax(P0, stats, free_mask=~occ, iterations=10)
    b = relax(P0, same, free_mask=~occ, iterations=10)
    np.testing.assert_allclose(a, b, atol=1e-5)


def test_per_direction_statistics_see_direction(rng: np.random.Generator) -> None:
    # horizontal stripes of two labels: rows agree along a row, alternate across rows
    lab = np.where((np.arange(30)[:, None] // 3) % 2 == 0, ROOM, CORRIDOR).repeat(30, axis=1).astype(np.uint8)
    occ = np.zeros(lab.shape, bool)
    s = CompatibilityStats.from_label_images([(lab, occ)], (ROOM, CORRIDOR), per_direction=True)
    left = next(i for i, d in enumerate(DIRECTIONS) if tuple(d) == (0, -1))
    up = next(i for i, d in enumerate(DIRECTIONS) if tuple(d) == (-1, 0))
    assert s.r_for(left)[0, 1] == pytest.approx(-1.0)  # a left neighbour never differs
    assert s.r_for(up)[0, 1] > -1.0  # across rows it may
    P0 = noisy_histograms(lab, rng, flip=0.1)[..., [0, 1, 3]]
    P = relax(P0, s, free_mask=~occ, iterations=30)
    assert (argmax_labels(P, s) == lab).mean() > (argmax_labels(P0, s) == lab).mean()


def test_map_border_counts_as_wall() -> None:
    lab, occ = office(30, 40)
    free = np.ones(lab.shape, bool)
    s = CompatibilityStats.from_label_images([(lab, occ)], CLASSES)
    rng = np.random.default_rng(3)
    P0 = rng.dirichlet([1, 1, 1, 1], size=lab.shape).astype(np.float32)
    P = relax(P0, s, free_mask=free, iterations=5, border="wall")
    # the same map inside a ring of occupied cells
    Pp = relax(np.pad(P0, ((1, 1), (1, 1), (0, 0))), s, free_mask=np.pad(free, 1), iterations=5)
    np.testing.assert_allclose(P, Pp[1:-1, 1:-1], atol=1e-6)
    # missing neighbours that contribute nothing change border cells only (after one step)
    a = relax(P0, s, free_mask=free, iterations=1, border="wall")
    b = relax(P0, s, free_mask=free, iterations=1, border="none")
    np.testing.assert_allclose(a[1:-1, 1:-1], b[1:-1, 1:-1], atol=1e-6)
    assert np.abs(a[0] - b[0]).max() > 1e-4


def test_zero_iterations_returns_normalised_input(stats: CompatibilityStats) -> None:
    lab, occ = office(20, 30)
    P0 = np.zeros((*lab.shape, 3), np.float32)  # no wall column, all-zero rows
    P0[..., 1] = 2.0
    P0[0, 0] = 0
    P = relax(P0, stats, free_mask=~occ, iterations=0)
    assert P.shape == (*lab.shape, 4)
    np.testing.assert_allclose(P[~occ, 1], 1.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"o": 0.2}, "1/8"),
        ({"iterations": -1}, "iterations"),
        ({"border": "mirror"}, "border"),
        ({"backend": "torch"}, "backend"),
    ],
)
def test_bad_arguments(stats: CompatibilityStats, kwargs: dict[str, object], match: str) -> None:
    lab, occ = office(20, 30)
    P0 = np.ones((*lab.shape, 4), np.float32)
    with pytest.raises(ValueError, match=match):
        relax(P0, stats, free_mask=~occ, **kwargs)  # type: ignore[arg-type]


def test_bad_histograms(stats: CompatibilityStats) -> None:
    free = np.ones((5, 5), bool)
    with pytest.raises(ValueError, match="shape"):
        relax(np.ones((5, 5, 7), np.float32), stats, free_mask=free)
    bad = np.ones((5, 5, 4), np.float32)
    bad[2, 2, 0] = -1
    with pytest.raises(ValueError, match="non-negative"):
        relax(bad, stats, free_mask=free)


@pytest.mark.data
def test_statistics_of_the_ipa_labelled_maps(shared_data: Path) -> None:
    folder = shared_data / "ipa" / "labeled"
    samples = []
    for lp in sorted(folder.glob("*.labels.png"))[:2]:
        lab = read_label_image(lp, IPA_CODES)
        occ = read_label_image(lp.with_name(lp.name.replace(".labels", ".map"))) < 250
        samples.append((lab, occ))
    s = CompatibilityStats.from_label_images(samples, CLASSES)
    assert np.all(np.diag(s.r[0]) > 0)
    # rooms and corridors rarely touch directly (doorways sit between them)
    room, corridor = 0, 1
    assert s.r[0][room, corridor] < 0
