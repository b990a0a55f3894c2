"""Matching one laser scan against a likelihood field: where does the scan fit the map best?

Two steps, both on the field's score ``exp(−d²/2σ²)`` (``d``: metres from a beam's endpoint
to the nearest obstacle, :class:`~knowledge.localization.likelihood.LikelihoodField`):

* **Correlative search** (E. Olson, "Real-time correlative scan matching", ICRA 2009, without
  the multi-resolution tables): every pose of a grid around the prior — ``±linear_window``
  metres in steps of one cell, ``±angular_window`` radians in steps of ``angular_step`` — is
  scored by the sum of the scores of the cells its endpoints fall in; the best one wins. It
  finds the right pose from a prior that is off by up to the window, but only to a cell and
  a step.
* **Gauss–Newton refinement** (as Hector SLAM does, Kohlbrecher et al. 2011): minimise
  ``Σ (1 − M(T(ξ)·p_i))²`` with ``M`` the bilinear interpolation of the score, from the
  prior (or the correlative result), first on a wide ``σ`` (a wide basin), then on a narrow
  one (a sharp optimum). Sub-cell accurate, a few hundred microseconds, but it only finds the
  optimum whose basin the prior lies in.

:meth:`ScanMatcher.match` refines the prior; it also refines the search's best pose, and
keeps whichever fits better, when the refined fit is poor or the caller asks
(``search="auto"``), or always, or never. A refinement that ends further from the prior than
the search window (plus the widest ``σ``) is not taken: along a corridor, with a person
walking ahead, it can slide a metre.

**The prior** (``translation_weight``, ``rotation_weight``; 0: none): a match also pays
``translation_weight·|Δt|² + rotation_weight·Δθ²`` for how far it moved from where it started
(``Δt`` metres, ``Δθ`` radians), against the mean squared residual ``mean (1 − M)²`` of its
endpoints — Cartographer's Ceres scan matcher's translation and rotation weights. Where the
scan pins the pose down (walls across the motion) a centimetre of misfit costs far more than
the prior, and the scan wins; along a corridor, where the scan says almost nothing, the
prior keeps the pose where the odometry put it instead of letting a few stray endpoints (a
person's legs, a door jamb) slide it. The correlative search weighs its candidates alike,
``mean score · exp(−translation_weight·|Δt|² − rotation_weight·Δθ²)`` (Cartographer's
real-time correlative scan matcher), and :meth:`ScanMatcher.match` compares the refined
candidates by that product. Poses here are the laser's, in the
field's map frame (:meth:`~knowledge.localization.likelihood.LikelihoodField.to_map`); scan
points are ``(M, 2)`` metres in the laser's frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

from knowledge.localization.likelihood import LikelihoodField

__all__ = ["MatchField", "MatchParams", "MatchResult", "ScanMatcher", "scan_points"]

SEARCH_MODES = ("auto", "always", "never")


def scan_points(
    ranges: npt.ArrayLike,
    angles: npt.ArrayLike,
    *,
    range_max: float,
    range_min: float = 0.0,
    max_range: float = math.inf,
    step: int = 1,
) -> np.ndarray:
    """``(M, 2)`` float64 endpoints in the laser's frame of the beams that hit something
    closer than ``max_range`` (every ``step``-th beam)."""
    r = np.asarray(ranges, dtype=np.float64)[::step]
    a = np.asarray(angles, dtype=np.float64)[::step]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & (r > max(range_min, 0.0)) & (r < range_max * (1.0 - 1e-6)) & (r <= max_range)
    r, a = r[ok], a[ok]
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)


@dataclass(frozen=True)
class MatchParams:
    """How :class:`ScanMatcher` matches.

    Attributes:
        sigmas: metres, the score's ``σ`` of each Gauss–Newton stage, wide to narrow.
        iterations: Gauss–Newton iterations per stage.
        search: ``"auto"`` (search when the refined fit is below ``min_fit``), ``"always"``, ``"never"``.
        min_fit: the mean narrow-``σ`` score of the endpoints below which a fit is poor.
        linear_window: metres, half the side of the search square.
        angular_window: radians, half the searched heading interval.
        angular_step: radians between searched headings.
        translation_weight: per square metre moved from the start (the prior; 0: none).
        rotation_weight: per square radian turned from the start (the prior; 0: none).
    """

    sigmas: tuple[float, ...] = (0.25, 0.1, 0.05)
    iterations: int = 8
    search: str = "auto"
    min_fit: float = 0.5
    linear_window: float = 0.3
    angular_window: float = 0.2
    angular_step: float = 0.01
    translation_weight: float = 0.0
    rotation_weight: float = 0.0

    def __post_init__(self) -> None:
        for name in ("translation_weight", "rotation_weight"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        if not self.sigmas or any(not s > 0 for s in self.sigmas):
            raise ValueError(f"sigmas must be positive metres, got {self.sigmas}")
        if self.iterations < 1:
            raise ValueError(f"iterations must be >= 1, got {self.iterations}")
        if self.search not in SEARCH_MODES:
            raise ValueError(f"search must be one of {SEARCH_MODES}, got {self.search!r}")
        if self.linear_window < 0 or self.angular_window < 0 or not self.angular_step > 0:
            raise ValueError("windows must be >= 0 and angular_step > 0")


class MatchField:
    """A likelihood field with the score arrays the matcher needs (made once per field).

    Args:
        field: the field.
        sigmas: metres, one score array each.
        scores: the ``(rows, cols)`` float32 arrays ``field.score(σ)`` already made (kept up to
            date by their owner, :class:`~knowledge.localization.tracking_field.TrackingField`);
            None: made here.
    """

    def __init__(
        self, field: LikelihoodField, sigmas: tuple[float, ...], scores: list[np.ndarray] | None = None
    ) -> None:
        self.field = field
        self.sigmas = tuple(sigmas)
        if scores is None:
            self.scores = [field.score(s) for s in self.sigmas]
        else:
            if len(scores) != len(self.sigmas) or any(a.shape != field.shape for a in scores):
                raise ValueError("scores must be one array of the field's shape per sigma")
            self.scores = list(scores)

    @property
    def resolution(self) -> float:
        return self.field.resolution


@dataclass(frozen=True)
class MatchResult:
    """What one match found.

    Attributes:
        pose: ``(3,)`` the laser's pose in the field's map frame.
        fit: mean narrow-``σ`` score of the endpoints at ``pose`` (1: every endpoint on an obstacle).
        searched: whether the correlative search ran.
        hessian: ``(3, 3)`` the last Gauss–Newton ``JᵀJ`` (its inverse, scaled, is a covariance).
        points: endpoints used.
    """

    pose: np.ndarray
    fit: float
    searched: bool
    hessian: np.ndarray
    points: int


@numba.njit(cache=True, nogil=True)
def _gn_system(score: np.ndarray, pts: np.ndarray, x: float, y: float, th: float, res: float) -> tuple:
    """``JᵀJ``, ``Jᵀr`` and the mean score of the endpoints at ``(x, y, th)`` (bilinear)."""
    rows, cols = score.shape
    c, s = math.cos(th), math.sin(th)
    H = np.zeros((3, 3))
    b = np.zeros(3)
    total = 0.0
    for i in range(pts.shape[0]):
        px, py = pts[i, 0], pts[i, 1]
        wx = x + c * px - s * py
        wy = y + s * px + c * py
        u = wx / res - 0.5
        v = wy / res - 0.5
        j0 = math.floor(u)
        i0 = math.floor(v)
        if i0 < 0 or j0 < 0 or i0 + 1 >= rows or j0 + 1 >= cols:
            continue
        fu = u - j0
        fv = v - i0
        m00 = score[i0, j0]
        m01 = score[i0, j0 + 1]
        m10 = score[i0 + 1, j0]
        m11 = score[i0 + 1, j0 + 1]
        m = (1 - fv) * ((1 - fu) * m00 + fu * m01) + fv * ((1 - fu) * m10 + fu * m11)
        dmdx = ((1 - fv) * (m01 - m00) + fv * (m11 - m10)) / res
        dmdy = ((1 - fu) * (m10 - m00) + fu * (m11 - m01)) / res
        dth = dmdx * (-s * px - c * py) + dmdy * (c * px - s * py)
        g0, g1, g2 = dmdx, dmdy, dth
        r = 1.0 - m
        total += m
        b[0] += g0 * r
        b[1] += g1 * r
        b[2] += g2 * r
        H[0, 0] += g0 * g0
        H[0, 1] += g0 * g1
        H[0, 2] += g0 * g2
        H[1, 1] += g1 * g1
        H[1, 2] += g1 * g2
        H[2, 2] += g2 * g2
    H[1, 0] = H[0, 1]
    H[2, 0] = H[0, 2]
    H[2, 1] = H[1, 2]
    n = pts.shape[0]
    return H, b, total / n if n else 0.0


@numba.njit(cache=True, nogil=True)
def _correlate(
    score: np.ndarray,
    pts: np.ndarray,
    x: float,
    y: float,
    th: float,
    res: float,
    n_lin: int,
    angles: np.ndarray,
    w_t: float,
    w_r: float,
) -> tuple:
    """The best ``(dx_cells, dy_cells, angle index, weighed score)`` around ``(x, y, th)``:
    the summed score of the endpoints times ``exp(−w_t·|Δt|² − w_r·Δθ²)``."""
    rows, cols = score.shape
    best = -1.0
    bi, bj, bk = 0, 0, 0
    m = pts.shape[0]
    side = 2 * n_lin + 1
    ci = np.empty(m, dtype=np.int64)
    cj = np.empty(m, dtype=np.int64)
    tot = np.empty((side, side))
    for k in range(angles.shape[0]):
        a = th + angles[k]
        c, s = math.cos(a), math.sin(a)
        turn = w_r * angles[k] * angles[k]
        for p in range(m):
            px, py = pts[p, 0], pts[p, 1]
            cj[p] = math.floor((x + c * px - s * py) / res)
            ci[p] = math.floor((y + s * px + c * py) / res)
        # endpoint by endpoint, the block of cells its offsets reach, row by row (each cell
        # read once, in memory order); every offset's sum still adds the endpoints in order
        tot[:, :] = 0.0
        for p in range(m):
            for di in range(-n_lin, n_lin + 1):
                r = ci[p] + di
                if r < 0 or r >= rows:
                    continue
                for dj in range(-n_lin, n_lin + 1):
                    q = cj[p] + dj
                    if 0 <= q < cols:
                        tot[di + n_lin, dj + n_lin] += score[r, q]
        for di in range(-n_lin, n_lin + 1):
            for dj in range(-n_lin, n_lin + 1):
                t = tot[di + n_lin, dj + n_lin]
                if w_t > 0.0 or w_r > 0.0:
                    t *= math.exp(-w_t * (di * di + dj * dj) * res * res - turn)
                if t > best:
                    best = t
                    bi, bj, bk = di, dj, k
    return bj, bi, bk, best


class ScanMatcher:
    """Correlative search and Gauss–Newton refinement (see the module docstring)."""

    def __init__(self, params: MatchParams | None = None) -> None:
        self.params = params or MatchParams()

    def field(self, field: LikelihoodField) -> MatchField:
        """The :class:`MatchField` of ``field`` for these parameters."""
        return MatchField(field, self.params.sigmas)

    def refine(
        self,
        mf: MatchField,
        points: np.ndarray,
        pose: npt.ArrayLike,
        prior: npt.ArrayLike | None = None,
        weights: tuple[float, float] | None = None,
    ) -> tuple[np.ndarray, float, np.ndarray]:
        """Gauss–Newton from ``pose`` over every ``σ`` stage: (pose, fit, last ``JᵀJ``);
        ``prior`` (default ``pose``) is where the prior's weights pull, ``weights`` (translation,
        rotation; default the parameters') how hard."""
        x, y, th = (float(v) for v in np.asarray(pose, dtype=np.float64))
        x0, y0, th0 = (x, y, th) if prior is None else (float(v) for v in np.asarray(prior, dtype=np.float64))
        res = mf.resolution
        H = np.zeros((3, 3))
        fit = 0.0
        # the prior's weights on the summed residual: n endpoints, each carrying 1/n of it
        n = float(points.shape[0])
        w_t, w_r = self._weights(weights)
        W = n * np.array([w_t, w_t, w_r])
        for sigma, score in zip(mf.sigmas, mf.scores, strict=True):
            for _ in range(self.params.iterations):
                H, b, fit = _gn_system(score, points, x, y, th, res)
                # a little damping keeps a flat direction (a corridor's length) where it was
                A = H + np.diag([1e-6, 1e-6, 1e-6]) + 1e-3 * np.diag(np.diag(H))
                if W.any():
                    A = A + np.diag(W)
                    b = b + W * np.array([x0 - x, y0 - y, math.remainder(th0 - th, 2.0 * math.pi)])
                try:
                    d = np.linalg.solve(A, b)
                except np.linalg.LinAlgError:
                    break
                if not np.all(np.isfinite(d)):
                    break
                # never jump further than the stage's σ in one step
                step = math.hypot(d[0], d[1])
                if step > sigma:
                    d[:2] *= sigma / step
                d[2] = max(-0.1, min(0.1, d[2]))
                x += d[0]
                y += d[1]
                th += d[2]
                if step < 1e-4 and abs(d[2]) < 1e-5:
                    break
        H, _, fit = _gn_system(mf.scores[-1], points, x, y, th, res)
        th = math.atan2(math.sin(th), math.cos(th))
        return np.array([x, y, th]), float(fit), H

    def _weights(self, weights: tuple[float, float] | None) -> tuple[float, float]:
        if weights is None:
            return self.params.translation_weight, self.params.rotation_weight
        w_t, w_r = (float(w) for w in weights)
        if not (math.isfinite(w_t) and math.isfinite(w_r) and w_t >= 0 and w_r >= 0):
            raise ValueError(f"the prior's weights must be finite numbers >= 0, got {weights!r}")
        return w_t, w_r

    def search(
        self,
        mf: MatchField,
        points: np.ndarray,
        pose: npt.ArrayLike,
        weights: tuple[float, float] | None = None,
    ) -> np.ndarray:
        """The correlative search's best pose around ``pose`` (on the narrowest score)."""
        prm = self.params
        x, y, th = (float(v) for v in np.asarray(pose, dtype=np.float64))
        res = mf.resolution
        n_lin = round(prm.linear_window / res)
        n_ang = round(prm.angular_window / prm.angular_step)
        angles = np.arange(-n_ang, n_ang + 1) * prm.angular_step
        w_t, w_r = self._weights(weights)
        dj, di, k, _ = _correlate(mf.scores[-1], points, x, y, th, res, n_lin, angles, w_t, w_r)
        return np.array([x + dj * res, y + di * res, th + float(angles[k])])

    def match(
        self,
        mf: MatchField,
        points: np.ndarray,
        prior: npt.ArrayLike,
        *,
        search: bool = False,
        weights: tuple[float, float] | None = None,
    ) -> MatchResult:
        """The pose of the scan ``points`` near ``prior`` (see the module docstring);
        ``search``: search first whatever the mode (the caller knows the prior is weak);
        ``weights``: the prior's (translation, rotation) weights for this scan (default the
        parameters')."""
        prm = self.params
        pts = np.ascontiguousarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise ValueError(f"points must be (M, 2) metres, got shape {pts.shape}")
        start = np.asarray(prior, dtype=np.float64)
        searched = False
        if pts.shape[0] == 0:
            return MatchResult(start.copy(), 0.0, False, np.zeros((3, 3)), 0)
        pose, fit, H = self.refine(mf, pts, start, weights=weights)
        if not self._within(start, pose):
            pose, fit, H = self._stay(mf, pts, start)
        if prm.search == "always" or (prm.search == "auto" and (search or fit < prm.min_fit)):
            cand, cfit, cH = self.refine(mf, pts, self.search(mf, pts, start, weights), start, weights)
            searched = True
            # the candidates compared as the search weighs them: fit times the prior's factor
            mine = cfit * self._prior_factor(start, cand, weights)
            if mine > fit * self._prior_factor(start, pose, weights) and self._within(start, cand):
                pose, fit, H = cand, cfit, cH
        return MatchResult(pose, fit, searched, H, int(pts.shape[0]))

    def _prior_factor(
        self, start: np.ndarray, pose: np.ndarray, weights: tuple[float, float] | None = None
    ) -> float:
        """``exp(−translation_weight·|Δt|² − rotation_weight·Δθ²)`` from ``start`` to ``pose``."""
        w_t, w_r = self._weights(weights)
        if w_t == 0.0 and w_r == 0.0:
            return 1.0
        d2 = (pose[0] - start[0]) ** 2 + (pose[1] - start[1]) ** 2
        a = math.remainder(float(pose[2] - start[2]), 2.0 * math.pi)
        return math.exp(-w_t * d2 - w_r * a * a)

    def _within(self, start: np.ndarray, pose: np.ndarray) -> bool:
        """Whether ``pose`` lies within the search window (plus the widest σ) of ``start``: a
        refinement that slid further (along a corridor, after a person walking ahead) is not
        taken."""
        prm = self.params
        d = math.hypot(pose[0] - start[0], pose[1] - start[1])
        a = abs(math.atan2(math.sin(pose[2] - start[2]), math.cos(pose[2] - start[2])))
        return d <= prm.linear_window + max(prm.sigmas) and a <= prm.angular_window + 0.1

    def fit(self, mf: MatchField, points: np.ndarray, pose: npt.ArrayLike) -> float:
        """The mean narrow-``σ`` score of the scan ``points`` at ``pose`` (the field's map frame)."""
        p = np.asarray(pose, dtype=np.float64)
        pts = np.ascontiguousarray(points, dtype=np.float64)
        if pts.shape[0] == 0:
            return 0.0
        _, _, fit = _gn_system(mf.scores[-1], pts, float(p[0]), float(p[1]), float(p[2]), mf.resolution)
        return float(fit)

    def _stay(
        self, mf: MatchField, pts: np.ndarray, start: np.ndarray
    ) -> tuple[np.ndarray, float, np.ndarray]:
        H, _, fit = _gn_system(
            mf.scores[-1], pts, float(start[0]), float(start[1]), float(start[2]), mf.resolution
        )
        return start.copy(), float(fit), H
