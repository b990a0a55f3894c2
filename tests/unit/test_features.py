"""Scan features: agreement with the slow reference, names, input handling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from knowledge.places.features import (
    MIN_RANGE,
    FeatureExtractor,
    compute_features,
    default_feature_names,
    describe,
    parse_name,
    validate_feature_names,
)
from knowledge.places.features.reference import reference_features
from knowledge.places.features.registry import FAMILIES, format_name
from knowledge.places.features.synthetic import random_scans

MAX_RANGE = 30.0
NAMES = default_feature_names()


def _fast64(ranges: np.ndarray, names: list[str] | None = None, max_range: float = MAX_RANGE) -> np.ndarray:
    return FeatureExtractor(names or NAMES, max_range=max_range, dtype=np.float64)(ranges)


def _assert_match(fast: np.ndarray, ref: np.ndarray, names: list[str]) -> None:
    bad = []
    for j, name in enumerate(names):
        if not np.allclose(fast[..., j], ref[..., j], rtol=1e-9, atol=1e-12):
            bad.append(f"{name}: fast {fast[..., j]} reference {ref[..., j]}")
    assert not bad, "\n".join(bad[:10])


# ------------------------------------------------------------------ the family and its names
def test_default_family_has_more_than_300_unique_valid_names() -> None:
    assert len(NAMES) > 300
    assert len(set(NAMES)) == len(NAMES)
    validate_feature_names(NAMES)
    again = default_feature_names()
    assert again == NAMES  # stable order
    families = {parse_name(n).family for n in NAMES}
    assert families == set(FAMILIES)  # every family of App. A and B, plus Ma/Mi
    assert sum(n.startswith("B.6[") for n in NAMES) == 200
    assert sum(n.startswith("B.9[") for n in NAMES) == 7


def test_names_are_canonical_and_described() -> None:
    for name in NAMES:
        spec = parse_name(name)
        assert format_name(spec.family, spec.params) == name
        text = describe(name)
        assert text.startswith(name + ": ")
    assert describe("A.7[gap=0.5m]") == (
        "A.7[gap=0.5m]: number of gaps: consecutive beams differing by more than 0.5 m [count]"
    )
    assert "0.02 m" in describe("A.8[w=10,eps=0.02m]") and " 10 " in describe("A.8[w=10,eps=0.02m]")
    assert "4πA/√P" in describe("B.12") and "4πA/P²" in describe("B.14")


def test_unknown_names_are_all_listed() -> None:
    bad = ["A.17", "A.7", "A.7[gap=0.5]", "B.6[n=1]", "B.6[n=0.5]", "A.1[x=1]", "B.9[phi=8]", "Z"]
    with pytest.raises(ValueError) as info:
        validate_feature_names(["A.1", *bad, "B.1"])
    listing = str(info.value).split("Names look like")[0]
    for name in bad:
        assert repr(name) in listing
    assert "'A.1'" not in listing and "'B.1'" not in listing
    assert "8 unknown" in listing
    with pytest.raises(ValueError, match=r"A\.17"):
        FeatureExtractor(["A.17"], max_range=MAX_RANGE)
    with pytest.raises(ValueError, match="no feature names"):
        FeatureExtractor([], max_range=MAX_RANGE)


def test_parameters_outside_the_grid_and_other_spellings() -> None:
    rng = np.random.default_rng(3)
    scans, _ = random_scans(5, rng=rng)
    X = compute_features(
        scans, ["A.7[gap=0.33m]", "A.7[gap=0.50m]", "A.7[gap=0.5m]", "B.6[n=-150]"], max_range=30
    )
    expected = (np.abs(scans - np.roll(scans, -1, axis=1)) > 0.33).sum(axis=1)
    np.testing.assert_array_equal(X[:, 0], expected)
    np.testing.assert_array_equal(X[:, 1], X[:, 2])
    assert np.all(np.isfinite(X[:, 3]))


# ------------------------------------------------------------------ agreement with the reference
def _reference_scans() -> np.ndarray:
    rng = np.random.default_rng(2024)
    realistic, _ = random_scans(6, rng=rng, max_range=MAX_RANGE)
    noise = rng.uniform(0.2, 12.0, size=(2, 360))
    noise[:, rng.integers(360, size=40)] = MAX_RANGE  # max-range beams
    return np.concatenate([realistic, noise])


@pytest.mark.slow
def test_every_feature_matches_the_reference() -> None:
    scans = _reference_scans()
    fast = _fast64(scans)
    ref = np.stack([reference_features(s, NAMES, max_range=MAX_RANGE) for s in scans])
    _assert_match(fast, ref, NAMES)
    # the scans exercise the features: lines, minima, gaps and max-range beams occur
    col = {n: j for j, n in enumerate(NAMES)}
    assert fast[:, col["A.8[w=10,eps=0.05m]"]].max() > 100
    assert fast[:, col["A.9"]].min() > 0
    assert fast[:, col["A.7[gap=1m]"]].max() > 0


def test_reference_agreement_with_another_beam_count() -> None:
    rng = np.random.default_rng(7)
    scans, _ = random_scans(3, rng=rng, num_beams=90, max_range=8.0)
    names = [n for n in NAMES if not n.startswith("B.6[") or abs(parse_name(n).params[0]) <= 12]
    fast = _fast64(scans, names, max_range=8.0)
    ref = np.stack([reference_features(s, names, max_range=8.0) for s in scans])
    _assert_match(fast, ref, names)


def test_float32_output_is_the_float64_result_rounded() -> None:
    scans = _reference_scans()[:3]
    X32 = compute_features(scans, max_range=MAX_RANGE)
    assert X32.dtype == np.float32 and X32.shape == (3, len(NAMES))
    np.testing.assert_array_equal(X32, _fast64(scans).astype(np.float32))


# ------------------------------------------------------------------ input handling
def test_single_scan_and_batch_agree() -> None:
    scans = _reference_scans()[:3]
    fx = FeatureExtractor(NAMES, max_range=MAX_RANGE)
    batch = fx(scans)
    single = fx(scans[1])
    assert single.shape == (len(NAMES),)
    np.testing.assert_array_equal(single, batch[1])
    # chunking does not change anything
    np.testing.assert_array_equal(FeatureExtractor(NAMES, max_range=MAX_RANGE, chunk_size=1)(scans), batch)
    assert fx(np.empty((0, 360))).shape == (0, len(NAMES))


def test_invalid_readings_are_cleaned() -> None:
    rng = np.random.default_rng(11)
    scan = rng.uniform(0.5, 6.0, size=360)
    dirty, clean = scan.copy(), scan.copy()
    dirty[[3, 40, 41]] = [np.nan, np.inf, 1e9]
    clean[[3, 40, 41]] = MAX_RANGE
    dirty[[100, 101, 250]] = [0.0, -2.0, -np.inf]
    clean[[100, 101, 250]] = MIN_RANGE
    fd, fc = _fast64(dirty), _fast64(clean)
    np.testing.assert_array_equal(fd, fc)
    assert np.all(np.isfinite(fd))
    # ratios stay bounded by max_range / MIN_RANGE
    col = NAMES.index("A.11")
    assert fd[col] <= MAX_RANGE / MIN_RANGE
    # integer input is accepted
    assert np.all(np.isfinite(compute_features(np.full(36, 2), ["A.1", "B.1"], max_range=5)))


def test_all_invalid_scan_is_finite() -> None:
    for scan in (np.full(360, np.nan), np.zeros(360), np.full(360, MAX_RANGE)):
        f = _fast64(scan)
        assert np.all(np.isfinite(f)), [n for n, v in zip(NAMES, f, strict=True) if not np.isfinite(v)]


@pytest.mark.parametrize(
    ("ranges", "kwargs", "match"),
    [
        (np.ones((2, 3, 4)), {"max_range": 5.0}, "shape"),
        (np.array(["a"] * 10), {"max_range": 5.0}, "numbers"),
        (np.ones((2, 10)), {"max_range": 5.0}, "at least 20 beams"),
        (np.ones((2, 360)), {"max_range": float("inf")}, "max_range"),
        (np.ones((2, 360)), {"max_range": 0.0}, "max_range"),
    ],
)
def test_bad_input_is_a_value_error(ranges: np.ndarray, kwargs: dict[str, float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        compute_features(ranges, NAMES, **kwargs)


def test_duplicate_names_give_duplicate_columns() -> None:
    scans = _reference_scans()[:2]
    X = compute_features(scans, ["B.6[n=3]", "A.1", "B.6[n=3]", "A.1"], max_range=MAX_RANGE)
    np.testing.assert_array_equal(X[:, 0], X[:, 2])
    np.testing.assert_array_equal(X[:, 1], X[:, 3])


def test_subset_equals_full_columns() -> None:
    scans = _reference_scans()
    full = _fast64(scans)
    rng = np.random.default_rng(5)
    for size in (1, 5, 40, 150):
        pick = sorted(rng.choice(len(NAMES), size=size, replace=False))
        names = [NAMES[j] for j in pick]
        np.testing.assert_allclose(_fast64(scans, names), full[:, pick], rtol=1e-10, atol=1e-13)


def test_ma_mi_cap_is_finite() -> None:
    # a scan that degenerates to a thin sliver: the Fourier ellipse is nearly a segment
    M = 360
    scan = np.full(M, MIN_RANGE)
    scan[0] = scan[180] = 20.0
    f = compute_features(scan, ["B.7", "B.8", "B.7/B.8"], max_range=MAX_RANGE)
    assert np.all(np.isfinite(f)) and f[2] >= 1.0 and f[2] <= 1e6
    assert math.isclose(f[2], f[0] / max(f[1], f[0] * 1e-6), rel_tol=1e-5)
