"""The feature extractor: a plan of compiled kernels built once, run over chunks of scans.

:class:`FeatureExtractor` parses its names once and turns them into three plans (numeric
arrays of parameters and output columns): set A (:mod:`.raw`), the polygon's shape and
moments (:mod:`.polygon`) and its Fourier descriptors (:mod:`.fourier_plan`, computed in
:mod:`.fourier`). Each chunk of scans is cleaned into a float64 buffer, then the two
kernels (set A; set B with the Fourier part) run over it scan by scan if their plans are
not empty, doing only the work the requested features need and writing straight into
their output columns. Chunks bound the memory: 256 scans of 360 beams, 0.7 MB per buffer,
which stays in the CPU's L2 cache between the kernels.

The kernels are compiled by numba on first use (10–20 s on this 2-core machine) and cached
on disk next to the modules (``__pycache__``), so later processes load them in under a
second. They are single-threaded and release the GIL.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from knowledge.places.features import fourier_plan, polygon, raw
from knowledge.places.features.batch import beam_directions, check_max_range, clean_chunk
from knowledge.places.features.registry import (
    FeatureSpec,
    default_feature_names,
    parse_name,
    validate_feature_names,
)

#: Elements (scans × beams) per chunk: 256 scans of 360 beams.
DEFAULT_CHUNK_ELEMENTS = 92_160


class FeatureExtractor:
    """Computes a fixed list of features for batches of 360° scans.

    Args:
        names: feature names (see :mod:`.registry`); duplicates are allowed.
        max_range: the sensor's maximum range in metres (a beam of that length hit nothing).
        chunk_size: scans per chunk; by default 92 160 beams' worth (256 scans of 360).
        dtype: output dtype, float32 by default (float64 for tests that need every digit).

    Raises:
        ValueError: naming every unknown feature name, or for a bad ``max_range``.
    """

    def __init__(
        self,
        names: Sequence[str],
        *,
        max_range: float,
        chunk_size: int | None = None,
        dtype: type[np.floating] = np.float32,
    ) -> None:
        validate_feature_names(names)
        self.names: tuple[str, ...] = tuple(names)
        self.max_range = check_max_range(max_range)
        if chunk_size is not None and (int(chunk_size) != chunk_size or chunk_size < 1):
            raise ValueError(f"chunk_size must be a positive number of scans, got {chunk_size!r}")
        self.chunk_size = chunk_size
        self.dtype = np.dtype(dtype)
        if self.dtype.kind != "f":
            raise ValueError(f"dtype must be a floating-point type, got {self.dtype}")
        unique: dict[str, tuple[FeatureSpec, int]] = {}  # spec and its first column
        self._fanout: list[tuple[int, np.ndarray]] = []  # duplicates: (source column, copies)
        copies: dict[str, list[int]] = {}
        for col, name in enumerate(self.names):
            spec = parse_name(name)
            key = f"{spec.family}{spec.params}"
            if key in unique:
                copies.setdefault(key, []).append(col)
            else:
                unique[key] = (spec, col)
        for key, cols in copies.items():
            self._fanout.append((unique[key][1], np.array(cols, dtype=np.intp)))

        def part(families: frozenset[str]) -> tuple[list[FeatureSpec], list[int]]:
            chosen = [(spec, col) for spec, col in unique.values() if spec.family in families]
            return [spec for spec, _ in chosen], [col for _, col in chosen]

        self._raw = raw.make_plan(*part(raw.FAMILIES))
        self._polygon = polygon.make_plan(*part(polygon.FAMILIES))
        self._fourier = fourier_plan.make_plan(*part(fourier_plan.FAMILIES))
        self._min_beams = self._raw.min_beams

    def __repr__(self) -> str:
        return f"FeatureExtractor({len(self.names)} features, max_range={self.max_range})"

    def __call__(self, ranges: np.ndarray) -> np.ndarray:
        """Features of ``ranges`` (S, M) or (M,), metres → (S, F) or (F,) in ``dtype``.

        Raises:
            ValueError: for input that is not 1-D/2-D numbers, or with too few beams.
        """
        arr = np.asarray(ranges)
        if arr.dtype.kind not in "fiu":
            raise ValueError(f"ranges must be numbers (metres), got dtype {arr.dtype}")
        single = arr.ndim == 1
        if single:
            arr = arr[None, :]
        if arr.ndim != 2:
            raise ValueError(f"ranges must be (scans, beams) or (beams,), got shape {np.shape(ranges)}")
        S, M = arr.shape
        need = self._min_beams
        if need > M:
            raise ValueError(f"scans need at least {need} beams over 360° for these features, got {M}")
        F = len(self.names)
        out = np.empty((S, F), dtype=self.dtype)
        if arr.dtype not in (np.float32, np.float64):
            arr = arr.astype(np.float64)
        chunk = max(1, min(S, self.chunk_size or DEFAULT_CHUNK_ELEMENTS // M))
        d = np.empty((chunk, M))
        direct = self.dtype == np.float64
        block = out if direct else np.empty((chunk, F))
        cos, sin = beam_directions(M)
        h = raw.minima_scale(M)
        run_raw, run_polygon = self._raw.active, self._polygon.active or self._fourier.active
        for start in range(0, S, chunk):
            stop = min(S, start + chunk)
            n = stop - start
            dc = d[:n]
            clean_chunk(np.ascontiguousarray(arr[start:stop]), self.max_range, dc)
            res = out[start:stop] if direct else block[:n]
            if run_raw:
                raw.raw_chunk(dc, cos, sin, self.max_range, h, self._raw, res)
            if run_polygon:
                polygon.polygon_chunk(dc, cos, sin, self._polygon, self._fourier, res)
            if not direct:
                out[start:stop] = res
        for src, copies in self._fanout:
            out[:, copies] = out[:, [src]]
        return out[0] if single else out


def compute_features(
    ranges: np.ndarray, names: Sequence[str] | None = None, *, max_range: float
) -> np.ndarray:
    """One-shot :class:`FeatureExtractor` call; ``names=None`` means the full default family."""
    return FeatureExtractor(names if names is not None else default_feature_names(), max_range=max_range)(
        ranges
    )
