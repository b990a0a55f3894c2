"""Laws of the scan features, checked on generated scans (hypothesis).

* rotating the robot by a whole number of beams (np.roll) changes no feature;
* computing a subset of the features gives the same columns as computing all of them;
* every feature is finite, whatever the readings.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from knowledge.places.features import FeatureExtractor, default_feature_names
from knowledge.places.features.synthetic import random_scans

MAX_RANGE = 10.0
NAMES = default_feature_names()
FULL = FeatureExtractor(NAMES, max_range=MAX_RANGE, dtype=np.float64)

# Readings: arbitrary lengths, repeated "round" values (ties, plateaus), max-range beams and
# invalid readings (NaN, inf, 0, negative) that the extractor must clean.
reading = st.one_of(
    st.floats(0.05, MAX_RANGE, allow_nan=False),
    st.sampled_from([0.5, 1.0, 2.0, MAX_RANGE]),
    st.sampled_from([float("nan"), float("inf"), 0.0, -1.0, 1e6]),
)


@st.composite
def scans(draw: st.DrawFn) -> np.ndarray:
    """Either readings as above (many ties) or a smooth random profile (no ties)."""
    M = draw(st.sampled_from([24, 45, 90]))
    if draw(st.booleans()):
        return np.array(draw(st.lists(reading, min_size=M, max_size=M)), dtype=np.float64)
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    phi = np.arange(M) * 2 * np.pi / M
    k = np.arange(1, 6)[:, None]
    profile = 3.0 + (rng.normal(size=(5, 1)) * np.cos(k * phi + rng.uniform(0, 6, size=(5, 1)))).sum(axis=0)
    return np.clip(profile, 0.05, MAX_RANGE)


def _close(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-feature agreement up to rounding: relative 1e-7, absolute 1e-9 of the scale."""
    scale = np.maximum(np.abs(a), np.abs(b))
    return np.abs(a - b) <= 1e-7 * scale + 1e-12


@settings(max_examples=60, deadline=None)
@given(scan=scans(), shift=st.integers(1, 1000))
def test_rotation_by_whole_beams_changes_nothing(scan: np.ndarray, shift: int) -> None:
    base = FULL(scan)
    rotated = FULL(np.roll(scan, shift))
    assert np.all(np.isfinite(base))
    ok = _close(base, rotated)
    assert ok.all(), {NAMES[j]: (base[j], rotated[j]) for j in np.where(~ok)[0][:5]}


@settings(max_examples=30, deadline=None)
@given(
    batch=st.lists(scans(), min_size=1, max_size=3),
    pick=st.lists(st.integers(0, len(NAMES) - 1), min_size=1, max_size=40),
)
def test_requested_subset_equals_full_computation(batch: list[np.ndarray], pick: list[int]) -> None:
    M = len(batch[0])
    ranges = np.stack([b[:M] if len(b) >= M else np.resize(b, M) for b in batch])
    names = [NAMES[j] for j in pick]
    subset = FeatureExtractor(names, max_range=MAX_RANGE, dtype=np.float64)(ranges)
    full = FULL(ranges)[:, pick]
    ok = _close(subset, full)
    assert ok.all(), [names[j] for j in np.where(~ok.all(axis=0))[0]]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), shift=st.integers(1, 359))
def test_rotation_of_realistic_scans(seed: int, shift: int) -> None:
    scan, _ = random_scans(1, rng=np.random.default_rng(seed), max_range=MAX_RANGE)
    base = FULL(scan[0])
    rotated = FULL(np.roll(scan[0], shift))
    ok = _close(base, rotated)
    assert ok.all(), {NAMES[j]: (base[j], rotated[j]) for j in np.where(~ok)[0][:5]}
