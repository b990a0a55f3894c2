"""Single-valued scan features for place classification (book Sect. 3.4, 4.4, App. A and B).

Set A (A.1–A.16) is computed from the raw beams, set B (B.1–B.16 and Ma/Mi) from the
polygon Pol(z) of the beam end points. Parameterised families (max-range and gap thresholds,
line windows, Fourier orders, Hu invariants) make up the book's "more than 300 simple
features"; :func:`default_feature_names` lists them (309 names).

Input: ``(S, M)`` beam lengths in metres, beam i at angle i·2π/M (a full turn), or a single
``(M,)`` scan. See :mod:`.batch` for how NaN, inf, out-of-range and non-positive readings are
cleaned, :mod:`.raw`, :mod:`.polygon` and :mod:`.fourier` for the formulas and the
interpretations where the book is ambiguous.

Example::

    fx = FeatureExtractor(["A.1", "A.7[gap=0.5m]", "B.6[n=-3]"], max_range=30.0)
    X = fx(ranges)          # (S, 3) float32
"""

from knowledge.places.features.batch import MIN_RANGE
from knowledge.places.features.extractor import FeatureExtractor, compute_features
from knowledge.places.features.registry import (
    default_feature_names,
    describe,
    parse_name,
    validate_feature_names,
)

__all__ = [
    "MIN_RANGE",
    "FeatureExtractor",
    "compute_features",
    "default_feature_names",
    "describe",
    "parse_name",
    "validate_feature_names",
]
