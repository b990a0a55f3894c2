"""Slow, independent definitions of every feature, for tests and benchmark baselines.

Plain Python loops over one scan, written straight from the book's formulas (Appendix A and
B) and the interpretations documented in :mod:`.raw`, :mod:`.polygon` and :mod:`.fourier`,
without sharing code with the fast kernels: coordinates by cos/sin per beam, the shoelace
area, edge lengths by ``math.dist``, eigenvalues by ``numpy.linalg.eigvalsh``, Fourier
coefficients by a direct sum per order, moments by explicit loops. Only the name parser of
:mod:`.registry` and the input cleaning rule are shared. About 0.1 s per scan for the full
family; use a handful of scans.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Sequence

import numpy as np

from knowledge.places.features.batch import MIN_RANGE
from knowledge.places.features.registry import parse_name


def clean_scan(ranges: Sequence[float], max_range: float) -> list[float]:
    """One scan's beam lengths with the documented replacement of invalid readings."""
    out = []
    for r in ranges:
        r = float(r)
        if math.isnan(r) or r > max_range:
            r = max_range
        elif r < MIN_RANGE:
            r = MIN_RANGE
        out.append(r)
    return out


def _mean(v: Sequence[float]) -> float:
    return sum(v) / len(v)


def _std(v: Sequence[float]) -> float:
    m = _mean(v)
    return math.sqrt(sum((a - m) ** 2 for a in v) / len(v))


class _Scan:
    """One cleaned scan and the polygon quantities, computed straightforwardly."""

    def __init__(self, d: list[float], max_range: float):
        self.d = d
        self.M = M = len(d)
        self.max_range = max_range
        self.rho = [2.0 * math.pi * i / M for i in range(M)]
        self.x = [d[i] * math.cos(self.rho[i]) for i in range(M)]
        self.y = [d[i] * math.sin(self.rho[i]) for i in range(M)]
        self.area = 0.5 * sum(
            self.x[i] * self.y[(i + 1) % M] - self.x[(i + 1) % M] * self.y[i] for i in range(M)
        )
        self.perimeter = sum(
            math.dist((self.x[i], self.y[i]), (self.x[(i + 1) % M], self.y[(i + 1) % M])) for i in range(M)
        )
        cx = cy = 0.0
        for i in range(M):
            j = (i + 1) % M
            cross = self.x[i] * self.y[j] - self.x[j] * self.y[i]
            cx += (self.x[i] + self.x[j]) * cross
            cy += (self.y[i] + self.y[j]) * cross
        self.cx, self.cy = cx / (6.0 * self.area), cy / (6.0 * self.area)
        self.cdist = [math.hypot(self.x[i] - self.cx, self.y[i] - self.cy) for i in range(M)]
        self._fourier: dict[int, complex] = {}

    def diffs(self, theta: float | None = None) -> list[float]:
        d, M = self.d, self.M
        if theta is None:
            return [abs(d[i] - d[(i + 1) % M]) for i in range(M)]
        return [abs(min(d[i], theta) - min(d[(i + 1) % M], theta)) for i in range(M)]

    def ratios(self) -> list[float]:
        return [self.d[i] / self.d[(i + 1) % self.M] for i in range(self.M)]

    def lines(self, w: int, eps: float) -> int:
        M = self.M
        fits = []
        for k in range(M):
            idx = [(k + i) % M for i in range(w)]
            if any(self.d[i] >= self.max_range for i in idx):
                fits.append(False)
                continue
            pts = np.array([[self.x[i], self.y[i]] for i in idx])
            cov = np.cov(pts.T, bias=True)
            rms = math.sqrt(max(float(np.linalg.eigvalsh(cov)[0]), 0.0))
            fits.append(rms <= eps)
        on = 0
        for i in range(M):
            if any(fits[(i - o) % M] for o in range(w)):
                on += 1
        return on

    def minima(self) -> tuple[float, float]:
        """(A.9, A.10): the two lowest beams that are minima within ±20° (strictly on the left)."""
        d, M = self.d, self.M
        h = max(1, round(M * 20.0 / 360.0))
        mins = []
        for i in range(M):
            left = all(d[i] < d[(i - k) % M] for k in range(1, h + 1))
            right = all(d[i] <= d[(i + k) % M] for k in range(1, h + 1))
            if left and right:
                mins.append(i)
        if len(mins) < 2:
            return 0.0, 0.0

        def sep(a: int, b: int) -> int:
            g = abs(a - b)
            return min(g, M - g)

        lowest = min(d[i] for i in mins)
        first = [i for i in mins if d[i] == lowest]
        if len(first) >= 2:
            s = min(sep(a, b) for a in first for b in first if a != b)
            r1 = r2 = lowest
        else:
            p1 = first[0]
            rest = [i for i in mins if i != p1]
            second = min(d[i] for i in rest)
            s = min(sep(p1, i) for i in rest if d[i] == second)
            r1, r2 = lowest, second
        angle = s * 2.0 * math.pi / M
        a1, a2 = 0.0, angle
        dist = math.hypot(r1 * math.cos(a1) - r2 * math.cos(a2), r1 * math.sin(a1) - r2 * math.sin(a2))
        return dist, angle

    def fourier(self, n: int) -> complex:
        """c_n of the polygon in arc length, turns paired with their own vertex."""
        if n not in self._fourier:
            self._fourier[n] = self._fourier_direct(n)
        return self._fourier[n]

    def _fourier_direct(self, n: int) -> complex:
        M = self.M
        v = [complex(self.x[i], self.y[i]) for i in range(M)]
        dv = [v[(i + 1) % M] - v[i] for i in range(M)]
        ds = [z / abs(z) for z in dv]
        t = [0.0]
        for i in range(M - 1):
            t.append(t[-1] + abs(dv[i]))
        T = t[-1] + abs(dv[-1])
        total = 0j
        for k in range(M):
            total += (ds[k] - ds[k - 1]) * cmath.exp(-1j * n * 2.0 * math.pi * t[k] / T)
        return -T / (2.0 * math.pi * n) ** 2 * total

    def moment(self, p: int, q: int) -> float:
        xb = _mean(self.x)
        yb = _mean(self.y)
        total = 0.0
        for i in range(self.M):
            total += (self.x[i] - xb) ** p * (self.y[i] - yb) ** q
        return total

    def hu(self, k: int) -> float:
        M = self.M

        def eta(p: int, q: int) -> float:
            return self.moment(p, q) / M ** ((p + q) / 2 + 1)

        n20, n02, n11 = eta(2, 0), eta(0, 2), eta(1, 1)
        n30, n03, n21, n12 = eta(3, 0), eta(0, 3), eta(2, 1), eta(1, 2)
        if k == 1:
            return n20 + n02
        if k == 2:
            return (n20 - n02) ** 2 + 4 * n11**2
        if k == 3:
            return (n30 - 3 * n12) ** 2 + (3 * n21 - n03) ** 2
        if k == 4:
            return (n30 + n12) ** 2 + (n21 + n03) ** 2
        if k == 5:
            return (n30 - 3 * n12) * (n30 + n12) * ((n30 + n12) ** 2 - 3 * (n21 + n03) ** 2) + (
                3 * n21 - n03
            ) * (n21 + n03) * (3 * (n30 + n12) ** 2 - (n21 + n03) ** 2)
        if k == 6:
            return (n20 - n02) * ((n30 + n12) ** 2 - (n21 + n03) ** 2) + 4 * n11 * (n30 + n12) * (n21 + n03)
        return (3 * n21 - n03) * (n30 + n12) * ((n30 + n12) ** 2 - 3 * (n21 + n03) ** 2) - (n30 - 3 * n12) * (
            n21 + n03
        ) * (3 * (n30 + n12) ** 2 - (n21 + n03) ** 2)


def _feature(s: _Scan, family: str, params: tuple[float, ...]) -> float:
    d, M = s.d, s.M
    if family in ("A.1", "A.2"):
        return _mean(s.diffs()) if family == "A.1" else _std(s.diffs())
    if family in ("A.3", "A.4"):
        v = s.diffs(params[0])
        return _mean(v) if family == "A.3" else _std(v)
    if family == "A.5":
        return _mean(d)
    if family == "A.6":
        return _std(d)
    if family == "A.7":
        return float(sum(1 for v in s.diffs() if v > params[0]))
    if family == "A.8":
        return float(s.lines(int(params[0]), params[1]))
    if family in ("A.9", "A.10"):
        return s.minima()[0 if family == "A.9" else 1]
    if family in ("A.11", "A.12"):
        return _mean(s.ratios()) if family == "A.11" else _std(s.ratios())
    if family in ("A.13", "A.14"):
        dn = [v / max(d) for v in d]
        return _mean(dn) if family == "A.13" else _std(dn)
    if family == "A.15":
        return float(sum(1 for i in range(M) if d[i] / d[(i + 1) % M] > params[0]))
    if family == "A.16":
        m, sd = _mean(d), _std(d)
        if sd <= 1e-9 * m:
            return -3.0
        return sum((v - m) ** 4 for v in d) / (M * sd**4) - 3.0
    if family == "B.1":
        return s.area
    if family == "B.2":
        return s.perimeter
    if family == "B.3":
        return s.area / s.perimeter
    if family == "B.4":
        return _mean(s.cdist)
    if family == "B.5":
        return _std(s.cdist)
    if family == "B.6":
        c1 = abs(s.fourier(1))
        return abs(s.fourier(int(params[0]))) / c1
    if family in ("B.7", "B.8", "B.7/B.8"):
        a, b = abs(s.fourier(1)), abs(s.fourier(-1))
        major, minor = a + b, abs(a - b)
        if family == "B.7":
            return major
        if family == "B.8":
            return minor
        return major / max(minor, major * 1e-6)
    if family == "B.9":
        return s.hu(int(params[0]))
    if family in ("B.10", "B.11"):
        m20, m02, m11 = s.moment(2, 0), s.moment(0, 2), s.moment(1, 1)
        if family == "B.10":
            return s.area / (m20 + m02)
        return math.sqrt((m20 - m02) ** 2 + 4 * m11**2) / (m20 + m02)
    if family == "B.12":
        return 4 * math.pi * s.area / math.sqrt(s.perimeter)
    if family == "B.13":
        return s.perimeter**2 / s.area
    if family == "B.14":
        return 4 * math.pi * s.area / s.perimeter**2
    if family in ("B.15", "B.16"):
        dn = [v / max(s.cdist) for v in s.cdist]
        return _mean(dn) if family == "B.15" else _std(dn)
    raise ValueError(f"no reference for {family}")


def reference_features(ranges: Sequence[float], names: Sequence[str], *, max_range: float) -> np.ndarray:
    """The features ``names`` of one scan ``ranges`` (M,), float64, computed slowly."""
    scan = _Scan(clean_scan(ranges, max_range), max_range)
    values = []
    for name in names:
        spec = parse_name(name)
        values.append(_feature(scan, spec.family, spec.params))
    return np.array(values, dtype=np.float64)
