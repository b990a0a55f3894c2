"""Set A: features of the raw beams (book Appendix A, A.1–A.16), vectorised over scans.

Each kernel takes a :class:`~.batch.ScanBatch` of C scans and the specs of the features it
serves, and returns a (C, len(specs)) float64 array, one column per spec. Standard
deviations are population ones (1/M), as printed.

Interpretations (the book leaves these open):

* **A.3/A.4** clip every beam at θ (``length_θ``, A.3) before differencing.
* **A.8, beams on lines.** The book cites Sack & Burgard's comparison of line extractors
  without fixing one. We use a sliding-window criterion that vectorises: a window of ``w``
  consecutive beams (cyclic) *fits a line* if all its beams hit something (``d < max_range``;
  points on the max-range circle are not walls) and the RMS orthogonal distance of its end
  points to their total-least-squares line is at most ε (the square root of the smaller
  eigenvalue of the points' 2×2 covariance). A beam *lies on a line* if at least one fitting
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

from collections.abc import Callable, Sequence

import numpy as np
from scipy.ndimage import minimum_filter1d

from knowledge.places.features.batch import ScanBatch, mean_std
from knowledge.places.features.registry import FeatureSpec

Kernel = Callable[[ScanBatch, Sequence[FeatureSpec]], np.ndarray]

#: A.9/A.10 look for minima at this angular scale: a beam is a local minimum if no beam
#: within ±20° is shorter.
MINIMA_SCALE_DEG = 20.0


def _out(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    return np.empty((batch.d.shape[0], len(specs)), dtype=np.float64)


def diff_kernel(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    """A.1 (average) and A.2 (standard deviation) of ``|d_i − d_{i+1}|``."""
    mean, std = mean_std(batch.absdiff)
    out = _out(batch, specs)
    for j, spec in enumerate(specs):
        out[:, j] = mean if spec.family == "A.1" else std
    return out


def clipped_kernel(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    """A.3/A.4: average and standard deviation of the differences of beams clipped at θ.

    With ``lo = min(d_i, d_{i+1})`` the clipped difference ``|min(d_i, θ) − min(d_{i+1}, θ)|``
    equals ``clip(θ − lo, 0, |d_i − d_{i+1}|)``: one subtraction and one clip per θ.
    """
    lo = np.minimum(batch.d, batch.d_next)
    absdiff = batch.absdiff
    buf = np.empty_like(lo)
    out = _out(batch, specs)
    for theta in dict.fromkeys(s.params[0] for s in specs):
        cols = [j for j, s in enumerate(specs) if s.params[0] == theta]
        np.subtract(theta, lo, out=buf)
        np.maximum(buf, 0.0, out=buf)
        np.minimum(buf, absdiff, out=buf)
        if any(specs[j].family == "A.4" for j in cols):
            mean, std = mean_std(buf)
            for j in cols:
                out[:, j] = mean if specs[j].family == "A.3" else std
        else:
            out[:, cols] = buf.mean(axis=1)[:, None]
    return out


def beams_kernel(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    """A.5, A.6 (mean, std of d), A.13, A.14 (the same of d / d_max) and A.16 (kurtosis).

    ``mean(d / d_max) = mean(d) / d_max`` and likewise for the standard deviation.
    """
    mean, std = batch.beam_stats
    out = _out(batch, specs)
    dmax = None
    for j, spec in enumerate(specs):
        fam = spec.family
        if fam in ("A.13", "A.14"):
            if dmax is None:
                dmax = batch.d.max(axis=1)
            out[:, j] = (mean if fam == "A.13" else std) / dmax
        elif fam == "A.16":
            dev2 = batch.d - mean[:, None]
            dev2 *= dev2
            m4 = np.einsum("ij,ij->i", dev2, dev2) / batch.M
            flat = std <= 1e-9 * mean
            safe = np.where(flat, 1.0, std)
            out[:, j] = np.where(flat, 0.0, m4 / safe**4) - 3.0
        else:
            out[:, j] = mean if fam == "A.5" else std
    return out


def gaps_kernel(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    """A.7: number of consecutive pairs with ``|d_i − d_{i+1}| > θ``."""
    absdiff = batch.absdiff
    out = _out(batch, specs)
    for j, spec in enumerate(specs):
        out[:, j] = np.count_nonzero(absdiff > spec.params[0], axis=1)
    return out


def ratio_kernel(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    """A.11 (average) and A.12 (standard deviation) of ``d_i / d_{i+1}``."""
    mean, std = mean_std(batch.ratio)
    out = _out(batch, specs)
    for j, spec in enumerate(specs):
        out[:, j] = mean if spec.family == "A.11" else std
    return out


def rgaps_kernel(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    """A.15: number of consecutive pairs with ``d_i / d_{i+1} > θ``."""
    ratio = batch.ratio
    out = _out(batch, specs)
    for j, spec in enumerate(specs):
        out[:, j] = np.count_nonzero(ratio > spec.params[0], axis=1)
    return out


def _dilate(fit: np.ndarray, w: int) -> np.ndarray:
    """``covered[..., i] = any(fit[..., i−w+1 .. i])`` cyclically along the last axis.

    Doubling: ``span`` beams are OR-ed after each step, so log2(w) rolls instead of w.
    """
    covered = fit
    span = 1
    while 2 * span <= w:
        covered = covered | np.roll(covered, span, axis=-1)
        span *= 2
    if span < w:
        covered = covered | np.roll(covered, w - span, axis=-1)
    return covered


def lines_kernel(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    """A.8: number of beams on lines (see the module doc for the window criterion).

    Window sums come from cumulative sums of x, y, x², y², xy and the miss count; the points
    of max-range beams are zeroed first (their windows are rejected anyway), which keeps the
    sums small. With the w²-scaled central moments ``a = wΣx² − (Σx)²`` etc. the smaller
    eigenvalue of the covariance is ``2(ac − b²) / (w²(a + c + √((a − c)² + 4b²)))``, free of
    the cancellation of ``tr/2 − √…``.
    """
    M = batch.M
    C = batch.d.shape[0]
    hit = batch.hit
    x, y = batch.xy
    windows = sorted({int(s.params[0]) for s in specs})
    pad = windows[-1] - 1
    # rows: x, y, x², y², xy, miss; column 0 is the zero before the first cumulative sum
    cs = np.empty((C, 6, M + pad + 1))
    cs[:, :, 0] = 0.0
    body = cs[:, :, 1 : M + 1]
    np.multiply(x, hit, out=body[:, 0])
    np.multiply(y, hit, out=body[:, 1])
    np.multiply(body[:, 0], body[:, 0], out=body[:, 2])
    np.multiply(body[:, 1], body[:, 1], out=body[:, 3])
    np.multiply(body[:, 0], body[:, 1], out=body[:, 4])
    np.logical_not(hit, out=body[:, 5], casting="unsafe")
    cs[:, :, M + 1 :] = cs[:, :, 1 : pad + 1]
    np.cumsum(cs, axis=2, out=cs)
    out = _out(batch, specs)
    for w in windows:
        S = cs[:, :, w : w + M] - cs[:, :, :M]
        sx, sy = S[:, 0], S[:, 1]
        a = np.maximum(w * S[:, 2] - sx * sx, 0.0)
        c = np.maximum(w * S[:, 3] - sy * sy, 0.0)
        b = w * S[:, 4] - sx * sy
        diff = a - c
        big = a + c + np.sqrt(diff * diff + 4.0 * b * b)  # 2·w²·λ_max
        det = np.maximum(a * c - b * b, 0.0)
        lmin = np.divide(2.0 / (w * w) * det, big, out=np.zeros_like(det), where=big > 0)
        complete = S[:, 5] < 0.5
        cols = [j for j, spec in enumerate(specs) if int(spec.params[0]) == w]
        eps2 = np.array([specs[j].params[1] ** 2 for j in cols])
        fit = complete[:, None, :] & (lmin[:, None, :] <= eps2[None, :, None])  # (C, E, M)
        out[:, cols] = np.count_nonzero(_dilate(fit, w), axis=2)
    return out


def minima_scale(M: int) -> int:
    """Half-width h in beams of the window in which an A.9/A.10 local minimum is the shortest."""
    return max(1, round(M * MINIMA_SCALE_DEG / 360.0))


def _window_minima(d: np.ndarray, h: int) -> np.ndarray:
    """Beams shorter than the h beams before them and not longer than the h after (C, M) bool."""
    M = d.shape[1]
    fwd = minimum_filter1d(d, size=h, axis=1, mode="wrap", origin=-(h // 2))  # min d[j..j+h−1]
    before = np.roll(fwd, h, axis=1)  # min d[i−h..i−1]
    after = np.roll(fwd, -1, axis=1) if M > 1 else fwd  # min d[i+1..i+h]
    return (d < before) & (d <= after)


def minima_kernel(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    """A.9 (distance, m) and A.10 (angle, rad) between the two lowest local minima."""
    d = batch.d
    C, M = d.shape
    is_min = _window_minima(d, minima_scale(M))
    n_min = np.count_nonzero(is_min, axis=1)
    vals = np.where(is_min, d, np.inf)
    m1 = vals.min(axis=1)
    cand1 = is_min & (d == m1[:, None])
    tied = np.count_nonzero(cand1, axis=1) >= 2
    big = 2 * M
    # tied lowest minima: smallest cyclic gap between consecutive candidates
    nxt = np.where(np.concatenate([cand1, cand1], axis=1), np.arange(2 * M), big)
    nxt = np.minimum.accumulate(nxt[:, ::-1], axis=1)[:, ::-1]
    gap = nxt[:, 1 : M + 1] - np.arange(M)
    gap_min = np.where(cand1, gap, big).min(axis=1)
    # a unique lowest minimum p1: the nearest (in angle) of the second-lowest ones
    rows = np.arange(C)
    p1 = np.argmax(cand1, axis=1)
    vals[rows, p1] = np.inf
    m2 = vals.min(axis=1)
    cand2 = is_min & (vals == m2[:, None])
    sep = np.abs(np.arange(M) - p1[:, None])
    sep = np.minimum(sep, M - sep)
    sep_min = np.where(cand2, sep, big).min(axis=1)
    ok = n_min >= 2
    angle = np.where(ok, np.where(tied, gap_min, sep_min) * batch.step, 0.0)
    r1 = np.where(ok, m1, 0.0)
    r2 = np.where(ok & ~tied, m2, r1)
    s = np.sin(0.5 * angle)
    dist = np.sqrt((r1 - r2) ** 2 + 4.0 * r1 * r2 * s * s)
    out = _out(batch, specs)
    for j, spec in enumerate(specs):
        out[:, j] = dist if spec.family == "A.9" else angle
    return out


KERNELS: dict[str, Kernel] = {
    "diff": diff_kernel,
    "clipped": clipped_kernel,
    "beams": beams_kernel,
    "gaps": gaps_kernel,
    "lines": lines_kernel,
    "minima": minima_kernel,
    "ratio": ratio_kernel,
    "rgaps": rgaps_kernel,
}
