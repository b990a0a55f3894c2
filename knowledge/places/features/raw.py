"""Set A: features of the raw beams (book Appendix A, A.1–A.16), compiled scan by scan.

:func:`make_plan` turns the requested specs into a :class:`RawPlan` (parameters and output
columns); :func:`raw_chunk` computes them for a chunk of cleaned scans in one pass per scan,
with only the requested groups' work done. Standard deviations are population ones (1/M),
as printed, and two-pass.

Interpretations (the book leaves these open):

* **A.3/A.4** clip every beam at θ (``length_θ``, A.3) before differencing.
* **A.8, beams on lines.** The book cites Sack & Burgard's comparison of line extractors
  without fixing one. We use a sliding-window criterion: a window of ``w`` consecutive
  beams (cyclic) *fits a line* if all its beams hit something (``d < max_range``; points on
  the max-range circle are not walls) and the RMS orthogonal distance of its end points to
  their total-least-squares line is at most ε (the square root of the smaller eigenvalue of
  the points' 2×2 covariance). A beam *lies on a line* if at least one fitting
  window contains it, so a straight wall seen by L ≥ w beams contributes all L of them, the
  way a split-and-merge extractor with minimum segment size w and tolerance ε would.
* **A.9/A.10, "two global minima".** The beam profile of a scan in a doorframe has two deep
  valleys, one per door post (book Fig. A.2). We take the *local minima at a 20° scale*: a
  beam is one if no beam within ±20° (rounded to whole beams, at least one) is shorter and
  the beams in the 20° before it are strictly longer (so a run of equal lengths counts
  once, at its first beam). Plain neighbour minima do not work: sensor noise or grid quantisation
  puts several of them on the same door post, a few beams apart. The two lowest of these
  minima are used (ties: the pair with the smallest angular separation, which keeps the
  result rotation invariant). In a doorway they are the two posts (A.9 ≈ the door width,
  A.10 ≈ π), in a corridor the feet of the two walls (A.9 ≈ the corridor width). The
  reference C++ code (ipa_room_segmentation) takes the two shortest beams instead, which are
  nearly always neighbours on the same post. A.9 is the distance between the two end points
  (m); A.10 the angle between the two beams folded into [0, π] (rad), since the raw
  |ρ1 − ρ2| would change when a rotation moves one beam past angle 0. A scan with fewer than
  two such minima (a constant scan, a robot off-centre in a round room) gives 0 for both.
* **A.15** counts ``d_i / d_{i+1} > θ`` exactly as printed: only one direction of a jump
  (a drop to a nearer beam, counter-clockwise) is counted.
* **A.16** is the excess kurtosis; for a constant scan (σ ≤ 1e-9·mean) the first term is
  taken as 0, giving −3, a value no other scan reaches (the kurtosis is ≥ −2).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numba
import numpy as np

from knowledge.places.features.batch import FASTMATH, array_max, mean_std, window_min
from knowledge.places.features.registry import FeatureSpec

#: A.9/A.10 look for minima at this angular scale: a beam is a local minimum if no beam
#: within ±20° is shorter.
MINIMA_SCALE_DEG = 20.0

#: Families of set A without parameters, in the order of :attr:`RawPlan.single`.
SINGLE = ("A.1", "A.2", "A.5", "A.6", "A.9", "A.10", "A.11", "A.12", "A.13", "A.14", "A.16")
_A1, _A2, _A5, _A6, _A9, _A10, _A11, _A12, _A13, _A14, _A16 = range(len(SINGLE))
#: Families :func:`make_plan` serves.
FAMILIES = frozenset((*SINGLE, "A.3", "A.4", "A.7", "A.8", "A.15"))


class RawPlan(NamedTuple):
    """Parameters and output columns of the requested set-A features (−1: not requested).

    ``single`` holds the columns of :data:`SINGLE`. A.3/A.4 share the thresholds
    ``clip_theta`` (columns ``clip_mean``/``clip_std``); A.7 and A.15 have one column per
    threshold. A.8: ``line_w`` the distinct windows (ascending); the features of window
    ``line_w[i]`` are entries ``line_start[i]`` to ``line_start[i + 1]`` of ``line_eps2`` (ε²,
    ascending) and ``line_col``.
    """

    single: np.ndarray
    clip_theta: np.ndarray
    clip_mean: np.ndarray
    clip_std: np.ndarray
    gap_theta: np.ndarray
    gap_col: np.ndarray
    rgap_theta: np.ndarray
    rgap_col: np.ndarray
    line_w: np.ndarray
    line_start: np.ndarray
    line_eps2: np.ndarray
    line_col: np.ndarray

    @property
    def active(self) -> bool:
        sizes = (self.clip_theta.size, self.gap_col.size, self.rgap_col.size, self.line_col.size)
        return bool((self.single >= 0).any()) or any(sizes)

    @property
    def min_beams(self) -> int:
        """Fewest beams a scan needs: 3, or the longest line window."""
        return max(3, int(self.line_w.max(initial=0)))


def make_plan(specs: Sequence[FeatureSpec], columns: Sequence[int]) -> RawPlan:
    """The plan for the set-A features ``specs`` written to output ``columns``."""
    single = np.full(len(SINGLE), -1, dtype=np.int64)
    clip: dict[float, list[int]] = {}
    gaps: list[tuple[float, int]] = []
    rgaps: list[tuple[float, int]] = []
    lines: list[tuple[int, float, int]] = []
    for spec, col in zip(specs, columns, strict=True):
        fam = spec.family
        if fam in ("A.3", "A.4"):
            clip.setdefault(spec.params[0], [-1, -1])[0 if fam == "A.3" else 1] = col
        elif fam == "A.7":
            gaps.append((spec.params[0], col))
        elif fam == "A.15":
            rgaps.append((spec.params[0], col))
        elif fam == "A.8":
            lines.append((int(spec.params[0]), spec.params[1] ** 2, col))
        else:
            single[SINGLE.index(fam)] = col
    lines.sort()
    windows = sorted({w for w, _, _ in lines})

    def ints(v: Sequence[int]) -> np.ndarray:
        return np.array(v, dtype=np.int64)

    def floats(v: Sequence[float]) -> np.ndarray:
        return np.array(v, dtype=np.float64)

    return RawPlan(
        single=single,
        clip_theta=floats(list(clip)),
        clip_mean=ints([c[0] for c in clip.values()]),
        clip_std=ints([c[1] for c in clip.values()]),
        gap_theta=floats([t for t, _ in gaps]),
        gap_col=ints([c for _, c in gaps]),
        rgap_theta=floats([t for t, _ in rgaps]),
        rgap_col=ints([c for _, c in rgaps]),
        line_w=ints(windows),
        line_start=ints([[w for w, _, _ in lines].index(w) for w in windows] + [len(lines)]),
        line_eps2=floats([e for _, e, _ in lines]),
        line_col=ints([c for _, _, c in lines]),
    )


def minima_scale(M: int) -> int:
    """Half-width h in beams of the window in which an A.9/A.10 local minimum is the shortest
    (h < M for every M ≥ 3)."""
    return max(1, round(M * MINIMA_SCALE_DEG / 360.0))


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _diff_features(d: np.ndarray, plan: RawPlan, ad: np.ndarray, lo: np.ndarray, out: np.ndarray) -> None:
    """A.1–A.4 and A.7 from ``|d_i − d_{i+1}|`` (``d`` has M + 1 beams, the first repeated).

    With ``lo = min(d_i, d_{i+1})`` the clipped difference ``|min(d_i, θ) − min(d_{i+1}, θ)|``
    of A.3/A.4 equals ``min(max(θ − lo, 0), |d_i − d_{i+1}|)``.
    """
    M = ad.size
    for i in range(M):
        ad[i] = abs(d[i] - d[i + 1])
        lo[i] = min(d[i], d[i + 1])
    if plan.single[_A1] >= 0 or plan.single[_A2] >= 0:
        mean, std = mean_std(ad)
        if plan.single[_A1] >= 0:
            out[plan.single[_A1]] = mean
        if plan.single[_A2] >= 0:
            out[plan.single[_A2]] = std
    for j in range(plan.clip_theta.size):
        theta = plan.clip_theta[j]
        total = 0.0
        for i in range(M):
            total += min(max(theta - lo[i], 0.0), ad[i])
        mean = total / M
        if plan.clip_mean[j] >= 0:
            out[plan.clip_mean[j]] = mean
        if plan.clip_std[j] >= 0:
            var = 0.0
            for i in range(M):
                dev = min(max(theta - lo[i], 0.0), ad[i]) - mean
                var += dev * dev
            out[plan.clip_std[j]] = math.sqrt(var / M)
    for j in range(plan.gap_theta.size):
        theta = plan.gap_theta[j]
        count = 0
        for i in range(M):
            count += ad[i] > theta
        out[plan.gap_col[j]] = count


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _ratio_features(d: np.ndarray, plan: RawPlan, ratio: np.ndarray, out: np.ndarray) -> None:
    """A.11, A.12 (mean, std of ``d_i / d_{i+1}``) and A.15 (counts of ratios above θ)."""
    M = ratio.size
    for i in range(M):
        ratio[i] = d[i] / d[i + 1]
    if plan.single[_A11] >= 0 or plan.single[_A12] >= 0:
        mean, std = mean_std(ratio)
        if plan.single[_A11] >= 0:
            out[plan.single[_A11]] = mean
        if plan.single[_A12] >= 0:
            out[plan.single[_A12]] = std
    for j in range(plan.rgap_theta.size):
        theta = plan.rgap_theta[j]
        count = 0
        for i in range(M):
            count += ratio[i] > theta
        out[plan.rgap_col[j]] = count


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _beam_features(d: np.ndarray, plan: RawPlan, out: np.ndarray) -> None:
    """A.5, A.6 (mean, std of d), A.13, A.14 (the same of d / d_max) and A.16 (kurtosis)."""
    M = d.size
    mean, std = mean_std(d)
    if plan.single[_A5] >= 0:
        out[plan.single[_A5]] = mean
    if plan.single[_A6] >= 0:
        out[plan.single[_A6]] = std
    if plan.single[_A13] >= 0 or plan.single[_A14] >= 0:
        dmax = array_max(d)
        if plan.single[_A13] >= 0:
            out[plan.single[_A13]] = mean / dmax
        if plan.single[_A14] >= 0:
            out[plan.single[_A14]] = std / dmax
    if plan.single[_A16] >= 0:
        m4 = 0.0
        for i in range(M):
            dev2 = (d[i] - mean) ** 2
            m4 += dev2 * dev2
        m4 /= M
        out[plan.single[_A16]] = (0.0 if std <= 1e-9 * mean else m4 / std**4) - 3.0


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _line_features(
    d: np.ndarray,
    cos: np.ndarray,
    sin: np.ndarray,
    max_range: float,
    plan: RawPlan,
    cs: np.ndarray,
    lmin: np.ndarray,
    tmp: np.ndarray,
    out: np.ndarray,
) -> None:
    """A.8: number of beams on lines (see the module doc for the window criterion).

    Window sums come from cumulative sums ``cs`` (6, M + w_max) of x, y, x², y², xy and the
    miss count over the beams 0..M + w_max − 2 (cyclic); the points of max-range beams are
    zeroed (their windows are rejected anyway), which keeps the sums small. With the
    w²-scaled central moments ``a = wΣx² − (Σx)²`` etc. the smaller eigenvalue of the
    covariance is ``(a + c − √((a − c)² + 4b²)) / (2w²)``; its rounding error, ~1e-16 of the
    window's spread λ_max, is below that of the moments from the cumulative sums and far
    below any ε² of interest. A beam lies on a line for ε iff the smallest eigenvalue of the
    windows containing it is ≤ ε²: one sliding minimum per w serves every ε. Scratch:
    ``lmin`` (2(M + w_max)), ``tmp`` (2, M + w_max).
    """
    M = d.size
    sx = sy = sxx = syy = sxy = miss = 0.0
    cs[:, 0] = 0.0
    for j in range(M + plan.line_w[-1] - 1):
        i = j if j < M else j - M
        if d[i] < max_range:
            px = d[i] * cos[i]
            py = d[i] * sin[i]
        else:
            px = py = 0.0
            miss += 1.0
        sx += px
        sy += py
        sxx += px * px
        syy += py * py
        sxy += px * py
        cs[0, j + 1] = sx
        cs[1, j + 1] = sy
        cs[2, j + 1] = sxx
        cs[3, j + 1] = syy
        cs[4, j + 1] = sxy
        cs[5, j + 1] = miss
    for wi in range(plan.line_w.size):
        w = plan.line_w[wi]
        scale = 0.5 / (w * w)
        # 1-D row slices: contiguous, and indices numba can prove ≥ 0 (both needed to vectorise)
        x0, x1, y0, y1 = cs[0], cs[0, w:], cs[1], cs[1, w:]
        xx0, xx1, yy0, yy1 = cs[2], cs[2, w:], cs[3], cs[3, w:]
        xy0, xy1, miss0, miss1 = cs[4], cs[4, w:], cs[5], cs[5, w:]
        # lmin[w − 1 + k]: the window starting at beam k (∞ if a beam missed), with the last
        # w − 1 windows repeated in front, so that beam i's windows are lmin[i .. i + w − 1]
        window = lmin[w - 1 :]
        for k in range(M):
            Sx = x1[k] - x0[k]
            Sy = y1[k] - y0[k]
            a = max(w * (xx1[k] - xx0[k]) - Sx * Sx, 0.0)
            c = max(w * (yy1[k] - yy0[k]) - Sy * Sy, 0.0)
            b = w * (xy1[k] - xy0[k]) - Sx * Sy
            diff = a - c
            value = max(scale * (a + c - math.sqrt(diff * diff + 4.0 * b * b)), 0.0)
            window[k] = value if miss1[k] - miss0[k] < 0.5 else np.inf
        for j in range(w - 1):
            lmin[j] = lmin[M + j]
        best = lmin[M + w - 1 :]
        window_min(lmin[: M + w - 1], w, tmp, best[:M])
        for j in range(plan.line_start[wi], plan.line_start[wi + 1]):
            eps2 = plan.line_eps2[j]
            count = 0
            for i in range(M):
                count += best[i] <= eps2
            out[plan.line_col[j]] = count


@numba.njit(cache=True, nogil=True)
def _minima_features(
    dd: np.ndarray, M: int, h: int, step: float, tmp: np.ndarray, near: np.ndarray, found: np.ndarray
) -> tuple[float, float]:
    """A.9 (distance, m) and A.10 (angle, rad) between the two lowest local minima.

    ``dd`` holds the beams with h beams of cyclic context on both sides: ``dd[j] = d[(j − h) mod M]``,
    j ≤ M + 2h. Scratch: ``tmp`` (2, ≥ M + 2h + 1), ``near`` (M + h + 1,), ``found`` (M,) for
    the indices of the minima.
    """
    # near[j] = min(dd[j .. j + h − 1]): beam i's h predecessors are near[i], its successors near[i + h + 1]
    window_min(dd, h, tmp, near)
    beam, after = dd[h:], near[h + 1 :]
    n = 0
    for i in range(M):
        v = beam[i]
        if v < near[i] and v <= after[i]:
            found[n] = i
            n += 1
    if n < 2:
        return 0.0, 0.0
    m1 = np.inf
    for j in range(n):
        m1 = min(m1, dd[found[j] + h])
    # the lowest minima: tied ones give the smallest cyclic gap between consecutive ones
    first = prev = -1
    gap = 2 * M
    for j in range(n):
        i = found[j]
        if dd[i + h] == m1:
            if prev >= 0:
                gap = min(gap, i - prev)
            else:
                first = i
            prev = i
    if prev != first:
        gap = min(gap, first + M - prev)
        angle = gap * step
        r1 = r2 = m1
    else:  # a unique lowest minimum p1: the nearest (in angle) of the second-lowest ones
        p1 = first
        m2 = np.inf
        for j in range(n):
            if found[j] != p1:
                m2 = min(m2, dd[found[j] + h])
        sep = 2 * M
        for j in range(n):
            i = found[j]
            if i != p1 and dd[i + h] == m2:
                g = abs(i - p1)
                sep = min(sep, min(g, M - g))
        angle = sep * step
        r1, r2 = m1, m2
    s = math.sin(0.5 * angle)
    return math.sqrt((r1 - r2) ** 2 + 4.0 * r1 * r2 * s * s), angle


@numba.njit(cache=True, nogil=True)
def raw_chunk(
    d: np.ndarray, cos: np.ndarray, sin: np.ndarray, max_range: float, h: int, plan: RawPlan, out: np.ndarray
) -> None:
    """The plan's set-A features of the cleaned scans ``d`` (S, M) into ``out`` (S, F).

    ``cos``, ``sin`` (M,) are the beam directions, ``h`` the A.9/A.10 half-window
    (:func:`minima_scale`).
    """
    S, M = d.shape
    step = 2.0 * math.pi / M
    sg = plan.single
    want_diff = sg[_A1] >= 0 or sg[_A2] >= 0 or plan.clip_theta.size > 0 or plan.gap_theta.size > 0
    want_ratio = sg[_A11] >= 0 or sg[_A12] >= 0 or plan.rgap_theta.size > 0
    want_beams = sg[_A5] >= 0 or sg[_A6] >= 0 or sg[_A13] >= 0 or sg[_A14] >= 0 or sg[_A16] >= 0
    want_minima = sg[_A9] >= 0 or sg[_A10] >= 0
    wmax = plan.line_w[-1] if plan.line_w.size > 0 else 1
    dd = np.empty(M + 2 * h + 1)
    buf = np.empty((3, M), dtype=np.float64)
    found = np.empty(M, dtype=np.int64)
    cs = np.empty((6, M + wmax))
    lmin = np.empty(2 * (M + wmax))
    tmp = np.empty((2, M + max(2 * h + 1, wmax)))
    for s in range(S):
        row = out[s]
        scan = d[s]
        for j in range(h):  # (h < M: no modulo needed)
            dd[j] = scan[M - h + j]
        for j in range(M):
            dd[h + j] = scan[j]
        for j in range(h + 1):
            dd[h + M + j] = scan[j]
        nxt = dd[h : h + M + 1]  # d_0 .. d_{M−1}, d_0
        if want_diff:
            _diff_features(nxt, plan, buf[0], buf[1], row)
        if want_ratio:
            _ratio_features(nxt, plan, buf[2], row)
        if want_beams:
            _beam_features(scan, plan, row)
        if plan.line_w.size > 0:
            _line_features(scan, cos, sin, max_range, plan, cs, lmin, tmp, row)
        if want_minima:
            dist, angle = _minima_features(dd, M, h, step, tmp, lmin[: M + h + 1], found)
            if sg[_A9] >= 0:
                row[sg[_A9]] = dist
            if sg[_A10] >= 0:
                row[sg[_A10]] = angle
