"""The nearest-neighbour transform τ_M (eq. 4.10-4.11) against brute-force distances."""

from __future__ import annotations

import numpy as np
import pytest

from knowledge.errors import NotFittedError
from knowledge.places.nn_transform import NNTransform


def _brute(train: np.ndarray, y: np.ndarray, query: np.ndarray, M: int) -> np.ndarray:
    mean, std = train.mean(0), train.std(0)
    T, Q = (train - mean) / std, (query - mean) / std
    cols = []
    for c in np.unique(y):
        d = np.linalg.norm(Q[:, None, :] - T[y == c][None, :, :], axis=2)
        cols.append(np.sort(d, axis=1)[:, :M])
    return np.hstack(cols)


@pytest.mark.parametrize("M", [1, 3])
def test_transform_is_the_distance_to_the_m_nearest_of_each_class(M: int) -> None:
    rng = np.random.default_rng(1)
    X = rng.normal(size=(120, 4)) * [1.0, 10.0, 0.1, 3.0]
    y = rng.choice(["room", "corridor", "doorway"], 120)
    Q = rng.normal(size=(30, 4))
    nn = NNTransform(M).fit(X, y)
    out = nn.transform(Q)
    assert out.shape == (30, 3 * M)
    assert np.allclose(out, _brute(X, y, Q, M))


def test_training_transform_leaves_each_instance_out() -> None:
    rng = np.random.default_rng(2)
    X = rng.normal(size=(60, 3))
    y = np.repeat([0, 1], 30)
    nn = NNTransform(1).fit(X, y)
    plain = nn.transform(X)
    loo = nn.transform_training()
    own = np.where(y == 0, 0, 1)
    assert np.allclose(plain[np.arange(60), own], 0.0)  # each finds itself
    assert np.all(loo[np.arange(60), own] > 0.0)
    other = 1 - own
    assert np.allclose(loo[np.arange(60), other], plain[np.arange(60), other])
    # the left-out distance is the distance to the nearest *other* instance of the class
    for i in (0, 45):
        same = np.flatnonzero((y == y[i]) & (np.arange(60) != i))
        Z = (X - X.mean(0)) / X.std(0)
        assert loo[i, own[i]] == pytest.approx(np.min(np.linalg.norm(Z[same] - Z[i], axis=1)))


def test_separable_by_a_line_after_the_transform() -> None:
    """Fig. 4.5: a ring around a blob is not linearly separable; after τ, t_0 < t_1 separates it."""
    rng = np.random.default_rng(3)
    angle = rng.uniform(0, 2 * np.pi, 200)
    ring = np.column_stack([np.cos(angle), np.sin(angle)]) * 3 + rng.normal(0, 0.1, (200, 2))
    blob = rng.normal(0, 0.5, (200, 2))
    X = np.vstack([ring, blob])
    y = np.repeat([0, 1], 200)
    nn = NNTransform(1).fit(X[::2], y[::2])
    t = nn.transform(X[1::2])
    assert np.mean((t[:, 0] > t[:, 1]).astype(int) == y[1::2]) > 0.97


def test_errors() -> None:
    with pytest.raises(NotFittedError):
        NNTransform().transform(np.zeros((1, 2)))
    with pytest.raises(ValueError, match="more than n_neighbors"):
        NNTransform(2).fit(np.zeros((4, 2)), [0, 0, 1, 1])
    nn = NNTransform().fit(np.arange(8.0).reshape(4, 2), [0, 0, 1, 1])
    with pytest.raises(ValueError, match="expected"):
        nn.transform(np.zeros((1, 3)))
