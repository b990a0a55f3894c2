"""The associative Markov network (Sect. 4.6.1): grid edges, α-expansion (checked move by move
against brute force) and max-margin learning on synthetic grids."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from knowledge.errors import NotFittedError
from knowledge.places.amn import AMN, alpha_expansion, class_features, energy, expansion_move, grid_edges


def test_grid_edges_counts_and_order() -> None:
    cells = np.array([(r, c) for r in range(3) for c in range(3)])
    e8 = grid_edges(cells)
    assert len(e8) == 6 + 6 + 4 + 4
    assert len(grid_edges(cells, connectivity=4)) == 12
    d = np.abs(cells[e8[:, 0]] - cells[e8[:, 1]])
    assert np.all(d.max(axis=1) == 1)
    assert len({tuple(sorted(p)) for p in e8.tolist()}) == len(e8)  # no edge twice
    # a hole and a separate island: no edges across the gap
    sparse = np.array([(0, 0), (0, 2), (5, 5), (6, 6)])
    assert sorted(map(tuple, grid_edges(sparse).tolist())) == [(2, 3)]


def _random_problem(
    seed: int, n: int = 7, k: int = 3
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    unary = rng.normal(size=(n, k))
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.5]
    edges = np.array(pairs, dtype=np.intp).reshape(-1, 2)
    lam = rng.uniform(0, 1.5, k)
    labels = rng.integers(0, k, n)
    return unary, edges, lam, labels


@pytest.mark.parametrize("seed", range(8))
def test_expansion_move_is_the_best_of_all_expansions(seed: int) -> None:
    unary, edges, lam, labels = _random_problem(seed)
    for alpha in range(unary.shape[1]):
        best = min(
            energy(unary, edges, lam, np.where(np.array(mask, bool), alpha, labels))
            for mask in itertools.product((0, 1), repeat=len(labels))
        )
        got = expansion_move(unary, edges, lam, labels, alpha)
        assert np.all((got == labels) | (got == alpha))
        assert energy(unary, edges, lam, got) == pytest.approx(best, abs=1e-9)


@pytest.mark.parametrize("seed", range(5))
def test_alpha_expansion_energy_never_increases(seed: int) -> None:
    rng = np.random.default_rng(seed)
    cells = np.array([(r, c) for r in range(12) for c in range(12)])
    edges = grid_edges(cells)
    unary = rng.normal(size=(len(cells), 4))
    lam = rng.uniform(0, 2, 4)
    init = rng.integers(0, 4, len(cells))
    res = alpha_expansion(unary, edges, lam, init=init, max_sweeps=20)
    assert res.energies[0] == pytest.approx(energy(unary, edges, lam, init))
    assert all(b <= a + 1e-9 for a, b in itertools.pairwise(res.energies))
    assert res.energies[-1] == pytest.approx(energy(unary, edges, lam, res.labels))
    assert res.energies[-1] < res.energies[0]
    # a local minimum w.r.t. every expansion: no single move lowers it further
    for alpha in range(4):
        again = expansion_move(unary, edges, lam, res.labels, alpha)
        assert energy(unary, edges, lam, again) >= res.energies[-1] - 1e-9


def _two_regions(seed: int, size: int = 24, noise: float = 1.2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A square grid, left part class 0 and right part class 1 with a bump; noisy 2-column evidence."""
    rng = np.random.default_rng(seed)
    cells = np.array([(r, c) for r in range(size) for c in range(size)])
    truth = (cells[:, 1] > size // 2 + (cells[:, 0] > size // 2) * 3).astype(np.intp)
    evidence = np.eye(2)[truth] + rng.normal(0, noise, (len(cells), 2))
    return cells, evidence, truth


def test_map_is_smoother_and_more_accurate_than_per_cell_argmax() -> None:
    cells, evidence, truth = _two_regions(0)
    edges = grid_edges(cells)
    per_cell = np.argmax(evidence, axis=1)
    res = alpha_expansion(evidence, edges, np.array([0.6, 0.6]))

    def disagreeing(y: np.ndarray) -> int:
        return int(np.sum(y[edges[:, 0]] != y[edges[:, 1]]))

    assert np.mean(per_cell == truth) < 0.85
    assert np.mean(res.labels == truth) > np.mean(per_cell == truth) + 0.08
    assert disagreeing(res.labels) < disagreeing(per_cell) / 3


def test_learned_amn_beats_per_cell_argmax_on_a_new_grid() -> None:
    cells, X_train, y_train = _two_regions(1)
    edges = grid_edges(cells)
    amn = AMN(epochs=40).fit(X_train, edges, y_train, 2)
    assert np.all(amn.w_edge_ >= 0) and np.any(amn.w_edge_ > 0), "the grid must earn an edge reward"
    assert amn.history_[-1] < amn.history_[0]
    cells, X_test, y_test = _two_regions(2)
    per_cell = np.argmax(amn.scores(X_test), axis=1)
    res = amn.predict(X_test, grid_edges(cells))
    assert np.mean(res.labels == y_test) > np.mean(per_cell == y_test) + 0.05


def test_errors() -> None:
    with pytest.raises(NotFittedError):
        AMN().scores(np.zeros((2, 2)))
    with pytest.raises(ValueError, match=">= 0"):
        alpha_expansion(np.zeros((2, 2)), np.array([[0, 1]]), np.array([-1.0, 0.0]))
    with pytest.raises(ValueError, match="labels must be"):
        AMN().fit(np.zeros((2, 2)), np.array([[0, 1]]), np.array([0, 3]), 2)
    assert len(alpha_expansion(np.zeros((0, 3)), np.zeros((0, 2)), np.ones(3)).labels) == 0


def test_class_features_lay_out_eq_4_9_and_the_tied_form() -> None:
    rng = np.random.default_rng(4)
    X = rng.normal(size=(5, 6))
    F = class_features(X, 3, tied=False)
    W = rng.normal(size=(3, 7))
    assert np.allclose(F @ W.ravel(), X @ W[:, :6].T + W[:, 6])  # w_n^k · (x_i, 1)
    T = class_features(X, 3, tied=True)  # blocks of 2 columns, one per class
    w = np.array([0.5, -2.0, 1.0, 0.0, 3.0])
    expected = np.stack([X[:, 2 * k : 2 * k + 2] @ w[:2] + w[2 + k] for k in range(3)], axis=1)
    assert np.allclose(T @ w, expected)
    with pytest.raises(ValueError, match="equal blocks"):
        class_features(np.zeros((2, 5)), 3, tied=True)


def test_tied_amn_learns_from_distances_and_smooths() -> None:
    """Distances to each class (lower = nearer), as the NN transform gives them."""
    cells, evidence, y_train = _two_regions(5)
    dist = 1.0 - evidence  # the true class is nearer
    edges = grid_edges(cells)
    amn = AMN(tied=True, epochs=40, step=0.2).fit(dist, edges, y_train, 2)
    assert amn.w_node_.shape == (1 + 2,)
    assert amn.w_node_[0] < 0, "a larger distance to a class must lower its score"
    cells, evidence, y_test = _two_regions(6)
    per_cell = np.argmin(1.0 - evidence, axis=1)
    res = amn.predict(1.0 - evidence, grid_edges(cells))
    assert np.mean(res.labels == y_test) > np.mean(per_cell == y_test) + 0.05
