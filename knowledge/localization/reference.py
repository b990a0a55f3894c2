"""Reference poses for a raw log: match its scans to the scans of a corrected copy.

A SLAM tool that corrects a log (GMapping on the MIT CSAIL log) writes out some of the raw
scans again with corrected poses, but with its own clock or with timestamps printed too
coarsely to match on (``1.13486e+09``). The scans themselves are the same numbers:
:func:`match_scans` pairs each reference scan with the raw scan whose ranges are equal as
numbers, in order — the reference is a subsequence of the raw log, so the ``k``-th reference
scan is matched to the first equal raw scan after the one the ``(k−1)``-th got. A reference
scan with no equal raw scan after the last match stays unmatched.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__all__ = ["match_scans", "scan_key"]


def scan_key(ranges: npt.ArrayLike) -> bytes:
    """The ranges as float32 bytes: equal for scans whose ranges are equal as numbers
    (``6.08`` and ``6.080000`` alike)."""
    return np.ascontiguousarray(np.asarray(ranges, dtype=np.float32)).tobytes()


def match_scans(scans: Sequence[npt.ArrayLike], reference: Sequence[npt.ArrayLike]) -> list[tuple[int, int]]:
    """``(raw index, reference index)`` pairs of equal scans, both increasing (see the module
    docstring)."""
    where: dict[bytes, list[int]] = {}
    for i, r in enumerate(scans):
        where.setdefault(scan_key(r), []).append(i)
    pairs: list[tuple[int, int]] = []
    last = -1
    for j, r in enumerate(reference):
        idx = where.get(scan_key(r))
        if not idx:
            continue
        k = bisect.bisect_right(idx, last)
        if k < len(idx):
            last = idx[k]
            pairs.append((last, j))
    return pairs
