"""FDR feature selection (Sect. 4.6.3, eq. 4.12-4.13, Fig. 4.6) on data whose informative
features are known."""

from __future__ import annotations

import numpy as np
import pytest

from knowledge.places.fdr import correlations, fisher_ratios, select_features


def _data(n: int = 600, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Columns: 0 strong, 1 = 3·col0 + tiny noise (a duplicate), 2 weaker but independent,
    3-5 noise. Three classes."""
    rng = np.random.default_rng(seed)
    y = rng.integers(0, 3, n)
    strong = y * 4.0 + rng.normal(0, 1, n)
    dup = 3.0 * strong + rng.normal(0, 0.01, n)
    weak = (y == 1) * 4.0 + rng.normal(0, 1, n)
    noise = rng.normal(0, 1, (n, 3))
    return np.column_stack([strong, dup, weak, noise]), y


def test_fdr_matches_the_two_class_formula() -> None:
    x = np.array([0.0, 2.0, 4.0, 10.0, 11.0, 12.0])
    y = np.array([0, 0, 0, 1, 1, 1])
    mu0, mu1, v0, v1 = 2.0, 11.0, np.var([0, 2, 4]), np.var([10, 11, 12])
    expected = 2 * (mu0 - mu1) ** 2 / (v0 + v1)  # both orders (i, j) of eq. 4.12
    assert fisher_ratios(x[:, None], y)[0] == pytest.approx(expected)


def test_fdr_ranks_informative_above_noise_and_constant_is_zero() -> None:
    X, y = _data()
    X = np.column_stack([X, np.full(len(y), 7.0)])
    s = fisher_ratios(X, y)
    assert s[0] > s[2] > max(s[3:6])
    assert s[6] == 0.0


def test_correlation_is_centred_pearson() -> None:
    X, _ = _data()
    R = correlations(X)
    assert R[0, 1] == pytest.approx(1.0, abs=1e-4)
    assert np.allclose(R, np.corrcoef(X.T), atol=1e-9)


def test_selection_skips_the_correlated_duplicate() -> None:
    X, y = _data()
    sel = select_features(X, y, 2)
    assert sel.indices[0] in (0, 1)
    assert sel.indices[1] == 2, "the second pick must be the independent feature, not the duplicate"
    assert len(set(sel.indices.tolist())) == 2
    # without the penalty the duplicate (same FDR) is picked second: the penalty is what matters
    plain = select_features(X, y, 2, w2=0.0)
    assert set(plain.indices.tolist()) == {0, 1}


def test_selection_never_repeats_and_scores_fdr() -> None:
    X, y = _data(seed=3)
    sel = select_features(X, y, X.shape[1])
    assert sorted(sel.indices.tolist()) == list(range(X.shape[1]))
    assert np.allclose(sel.fdr, fisher_ratios(X, y)[sel.indices])
    assert sel.scores[0] == pytest.approx(1.0)


def test_bad_arguments() -> None:
    X, y = _data()
    with pytest.raises(ValueError, match="n_select"):
        select_features(X, y, 0)
    with pytest.raises(ValueError, match="two classes"):
        fisher_ratios(X, np.zeros(len(y)))
    with pytest.raises(ValueError, match="NaN"):
        fisher_ratios(np.full((4, 1), np.nan), np.array([0, 0, 1, 1]))
