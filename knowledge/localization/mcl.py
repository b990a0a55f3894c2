"""Monte Carlo localization in a known occupancy map, with the place classifier as an extra
observation (book Sect. 6.3, eq. 6.3).

The belief over the laser's pose is a set of weighted particles (``(N, 3)`` poses in the
map frame of a :class:`~knowledge.localization.likelihood.LikelihoodField`). Each
:meth:`ParticleFilter.update` with the laser's odometry pose and its scan:

1. **motion**: every particle moves by the odometry increment since the last update, with
   sampled noise (:func:`~knowledge.localization.motion.sample_motion`);
2. once the robot has moved ``update_distance`` or turned ``update_angle`` since the last
   measurement (as AMCL does: a robot standing still would count the same scan again and
   again), **weighting** by the terms of eq. 6.3, in logarithms:

   * ``Pr(z_t | m, x_t)``, the laser: the likelihood field model over ``beams`` beams —
     each endpoint ``d`` metres from the nearest obstacle has ``z_hit·exp(−d²/2σ²) +
     z_rand/max_range`` (outside the map: ``d`` = the field's clipping distance); the sum of
     the beams' logarithms is multiplied by ``beam_weight`` (< 1: neighbouring beams are not
     independent, and a filter that believes they are becomes overconfident);
   * ``Pr(x_t | m)``: a particle on an occupied or unknown cell gets ``log(off_map)``, one
     outside the map is dropped (weight 0) — "we weight the particles inversely
     proportional to the occupancy probability at x_t in m";
   * the semantic term ``Pr(z_t | y_t)`` (:class:`~knowledge.localization.semantic.SemanticMap`)
     when a semantic map and the scan's class histogram are given, times ``semantic_weight``:
     from the histogram's most probable class (the book's) or from the whole histogram
     (``semantic_observation``), at every update or after ``semantic_distance`` metres or a
     change of class;

   each term can be switched off (``laser=False`` is the book's experiment: odometry, map
   and place labels only);
3. **resampling** (low-variance, Thrun et al. Table 4.4) when the effective sample size
   ``1/Σw²`` falls below ``resample_threshold·N`` (adaptive resampling); with
   ``initial_particles`` more than ``particles`` (a wide uniform start), the first resampling
   draws down to ``particles``;
4. **recovery** (augmented MCL, Table 8.3): short- and long-term averages of the per-beam
   likelihood (``alpha_fast``, ``alpha_slow``); when the short one falls below the long one
   (the scans stopped fitting: the robot was carried away), a share ``1 − w_fast/w_slow``
   of the resampled particles is drawn anew, uniformly over the free cells. This is what
   finds a kidnapped robot again. With ``semantic_recovery`` the averages are of the
   per-beam likelihood times the label's ``Pr(z_t | y)`` at each particle (the whole
   measurement, as Table 8.3 has it): particles in places whose class keeps disagreeing
   with the classifier also call for new ones.

**The semantic proposal** (``semantic_proposal``): what limits global localization with
10,000 particles is that often none starts near the true pose, and no weighting of the
particles there can fix that. The labels can say where to draw new particles: the initial
draw of :meth:`ParticleFilter.init_uniform` (made at the first measurement update) and
recovery's random particles come from ``q(x) ∝ Pr(z_t | y(x))`` over the free cells instead
of uniformly (:meth:`ParticleFilter.semantic_draw`; a semantic *sensor resetting*, Lenser
and Veloso 2000, Thrun et al. Sect. 8.3.4). The initial draw is the posterior of the uniform
prior after the first label, so that update does not weigh by the label again (the filter
stays consistent: proposal × weight = prior × likelihood). With ``proposal_history`` the
draw also fits the labels of the last metres at the places odometry puts them behind each
candidate (:meth:`ParticleFilter.history_draw`): one label can raise the density of
particles at most by the inverse of its class's share of the map (1.3× in CSAIL's rooms,
2.3× in its corridors), a sequence of labels by much more. Recovery's particles are, as in
augmented MCL, a heuristic: they enter with the weight of the others.

**The label-history reset** (``history_reset``): recovery draws new particles only when the
short-term average of the fit falls below the long-term one, and in global localization the
long-term average still holds the low fit of the uniform start tens of metres later (it moves
by ``alpha_slow`` = 0.001 per update): a filter that converged on a wrong place the laser
fits well (a corridor like the true one) is not told. The label history is: at each
resampling (once half of ``proposal_history`` has labels) a share ``1 − (L_p/L_q)^T`` of the
particles is drawn anew from the history proposal, ``L_p`` the per-label likelihood of the
history's labels at the particles (the weighted geometric mean of ``Pr(z_j | y)``) and ``L_q``
the same at the places the proposal draws (:meth:`ParticleFilter.history_fit`) — a sensor
resetting (Lenser and Veloso 2000: the share of new samples is one minus the ratio of the
observation's likelihood to what a good fit has) with the label sequence as the observation.

:meth:`ParticleFilter.estimate` gives the pose (weighted mean of the heaviest cluster:
particles within ``cluster_radius`` of the heaviest 0.5 m cell), its covariance and the
cluster's share of the weight. Global localization starts from :meth:`init_uniform`, pose
tracking from :meth:`init_pose`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np
import numpy.typing as npt

from knowledge.localization.likelihood import LikelihoodField
from knowledge.localization.motion import MotionNoise, sample_motion
from knowledge.localization.se2 import between, wrap
from knowledge.localization.semantic import OBSERVATIONS, SemanticMap

__all__ = ["Estimate", "MclParams", "ParticleFilter", "beam_log_likelihood"]

#: metres between two labels of the history proposal (consecutive labels repeat each other)
_HISTORY_STEP = 1.0
#: candidates per particle of the history proposal
_OVERSAMPLE = 20


@dataclass(frozen=True)
class MclParams:
    """The particle filter's parameters (see the module docstring).

    Attributes:
        particles: particles after the first resampling (and for :meth:`ParticleFilter.init_pose`).
        initial_particles: particles of :meth:`ParticleFilter.init_uniform` (0: ``particles``).
        beams: beams used per scan (evenly spread over the scan's valid beams).
        max_range: metres; longer beams and no-returns are not used.
        sigma_hit: metres, the likelihood field's spread.
        z_hit, z_rand: the field model's mixture weights.
        beam_weight: the factor on the beams' summed log-likelihood.
        off_map: the weight factor of a particle on an occupied or unknown cell.
        laser: use the laser term.
        semantic_weight: the factor on the semantic term's log-likelihood (0: off).
        semantic_observation: how the scan's histogram gives ``Pr(z_t | y)``
            (:data:`~knowledge.localization.semantic.OBSERVATIONS`: ``"argmax"``, the book's
            label, or ``"histogram"``, the mixture over the whole histogram).
        semantic_distance: metres driven between two semantic weightings (0: at every
            measurement update); the term is applied earlier when the scan's most probable
            class changes. Consecutive labels of a slowly moving robot are nearly the same
            observation, and counting each as new overcounts it.
        semantic_proposal: draw new particles in proportion to ``Pr(z_t | y)`` over the free
            cells instead of uniformly — the initial draw of :meth:`ParticleFilter.init_uniform`
            (at the first measurement update, whose semantic factor the draw then already
            holds) and the random particles of recovery (a semantic sensor resetting).
        proposal_history: metres of label history that recovery's semantic draw also
            matches (0: the current label only): candidates drawn from the current label are
            kept in proportion to ``Π_j Pr(z_j | y(x ⊕ (o_t ⊖ o_j)))`` over the labels ``z_j``
            of the last ``proposal_history`` metres, one per metre, at the places the
            odometry ``o`` puts them behind each candidate ``x`` — a sequence such as room,
            doorway, corridor fits far fewer places than its last label does.
        history_reset: a semantic sensor resetting from the label history (0: off; needs
            ``proposal_history``): at each resampling, once half of ``proposal_history`` has
            labels, a share ``1 − (L_p / L_q)^history_reset`` of the particles is drawn anew
            from the history proposal, ``L_p`` the per-label likelihood of the history at the
            particles (their weighted geometric mean) and ``L_q`` the same at the places the
            history proposal draws. Particles whose past labels fit as well as the best
            places of the map's stay; particles on a wrong place, which the laser alone
            can fit for tens of metres (recovery's long-term average then still holds the
            uniform start's low fit), are replaced where the labels say.
        update_distance, update_angle: metres, radians of motion between measurement updates.
        resample_threshold: resample when the effective sample size is below this share of N.
        alpha_slow, alpha_fast: the averaging rates of augmented MCL (``alpha_fast`` 0: no
            random particles).
        motion: the motion model's noise.
        cluster_radius: metres, the estimate's cluster around the heaviest cell.
    """

    particles: int = 10_000
    initial_particles: int = 0
    beams: int = 60
    max_range: float = 20.0
    sigma_hit: float = 0.2
    z_hit: float = 0.9
    z_rand: float = 0.1
    beam_weight: float = 0.2
    off_map: float = 1e-3
    laser: bool = True
    semantic_weight: float = 1.0
    semantic_observation: str = "argmax"
    semantic_distance: float = 0.0
    semantic_proposal: bool = False
    proposal_history: float = 0.0
    semantic_recovery: bool = False
    history_reset: float = 0.0
    update_distance: float = 0.2
    update_angle: float = 0.2
    resample_threshold: float = 0.5
    alpha_slow: float = 0.001
    alpha_fast: float = 0.1
    motion: MotionNoise = field(default_factory=MotionNoise)
    cluster_radius: float = 1.0

    def __post_init__(self) -> None:
        if self.particles < 1 or self.initial_particles < 0 or self.beams < 1:
            raise ValueError("particles and beams must be >= 1, initial_particles >= 0")
        for name in ("max_range", "sigma_hit", "cluster_radius"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"MclParams.{name} must be a positive number, got {v!r}")
        if not (0 < self.off_map <= 1) or not (0 <= self.resample_threshold <= 1):
            raise ValueError("off_map must be in (0, 1] and resample_threshold in [0, 1]")
        if (
            min(self.z_hit, self.z_rand, self.beam_weight, self.semantic_weight) < 0
            or self.z_hit + self.z_rand <= 0
        ):
            raise ValueError("z_hit, z_rand, beam_weight and semantic_weight must be >= 0")
        if self.semantic_observation not in OBSERVATIONS:
            raise ValueError(
                f"semantic_observation must be one of {OBSERVATIONS}, got {self.semantic_observation!r}"
            )
        if not (math.isfinite(self.proposal_history) and self.proposal_history >= 0):
            raise ValueError(f"proposal_history must be >= 0 metres, got {self.proposal_history!r}")
        if not (math.isfinite(self.history_reset) and self.history_reset >= 0):
            raise ValueError(f"history_reset must be >= 0, got {self.history_reset!r}")
        if not (math.isfinite(self.semantic_distance) and self.semantic_distance >= 0):
            raise ValueError(f"semantic_distance must be >= 0 metres, got {self.semantic_distance!r}")
        if not (0 <= self.alpha_slow <= 1 and 0 <= self.alpha_fast <= 1):
            raise ValueError("alpha_slow and alpha_fast must be in [0, 1]")


@dataclass(frozen=True)
class Estimate:
    """The filter's answer.

    Attributes:
        pose: ``(3,)`` the laser's pose in the world frame (the map's).
        covariance: ``(3, 3)`` of the cluster's particles (x, y, theta).
        share: the cluster's share of the total weight (1: one hypothesis).
        spread: metres, RMS distance of all particles from ``pose``.
    """

    pose: np.ndarray
    covariance: np.ndarray
    share: float
    spread: float


@numba.njit(cache=True, nogil=True)
def beam_log_likelihood(
    particles: np.ndarray, bx: np.ndarray, by: np.ndarray, logp: np.ndarray, res: float, outside: float
) -> np.ndarray:
    """``(N,)`` the summed ``logp`` of each particle's beam endpoints.

    ``particles``: ``(N, 3)`` map-frame poses; ``bx, by``: ``(M,)`` endpoints in the laser's
    frame; ``logp``: ``(rows, cols)`` per-cell log-likelihood (map orientation); endpoints
    outside the grid count ``outside``."""
    rows, cols = logp.shape
    n = particles.shape[0]
    m = bx.shape[0]
    out = np.empty(n)
    inv = 1.0 / res
    for i in range(n):
        x, y, th = particles[i, 0], particles[i, 1], particles[i, 2]
        c, s = math.cos(th), math.sin(th)
        tot = 0.0
        for k in range(m):
            ex = x + c * bx[k] - s * by[k]
            ey = y + s * bx[k] + c * by[k]
            col = math.floor(ex * inv)
            row = math.floor(ey * inv)
            if 0 <= row < rows and 0 <= col < cols:
                tot += logp[row, col]
            else:
                tot += outside
        out[i] = tot
    return out


@numba.njit(cache=True, nogil=True)
def history_scores(
    cand: np.ndarray, rel: np.ndarray, loglik: np.ndarray, labels: np.ndarray, res: float
) -> np.ndarray:
    """``(M,)`` ``Σ_j loglik[j, y(cand ⊕ rel[j])]`` for ``(M, 3)`` map-frame candidates,
    ``(H, 3)`` relative poses and ``(H, K + 1)`` log-likelihoods per class (the last column:
    cells without class or outside ``labels``, which holds -1 for no class)."""
    rows, cols = labels.shape
    k = loglik.shape[1] - 1
    m = cand.shape[0]
    out = np.zeros(m)
    for i in range(m):
        x, y, th = cand[i, 0], cand[i, 1], cand[i, 2]
        c, s = math.cos(th), math.sin(th)
        tot = 0.0
        for j in range(rel.shape[0]):
            px = x + c * rel[j, 0] - s * rel[j, 1]
            py = y + s * rel[j, 0] + c * rel[j, 1]
            col = math.floor(px / res)
            row = math.floor(py / res)
            cls = k
            if 0 <= row < rows and 0 <= col < cols:
                v = labels[row, col]
                if v >= 0:
                    cls = v
            tot += loglik[j, cls]
        out[i] = tot
    return out


class ParticleFilter:
    """Monte Carlo localization (see the module docstring).

    Args:
        field: the map's likelihood field.
        params: the parameters.
        semantic: the labelled map (same cells as ``field``) for the semantic term.
        rng: the random generator (seeded for reproducible runs).
    """

    def __init__(
        self,
        field: LikelihoodField,
        params: MclParams | None = None,
        *,
        semantic: SemanticMap | None = None,
        rng: np.random.Generator | None = None,
    ) -> None:
        self.field = field
        self.params = prm = params or MclParams()
        if semantic is not None and semantic.labels.shape != field.shape:
            raise ValueError(
                f"the semantic map's cells {semantic.labels.shape} are not the map's {field.shape}"
            )
        self.semantic = semantic
        self.rng = rng or np.random.default_rng()
        d = field.distance.astype(np.float64)
        z_rand = prm.z_rand / prm.max_range
        # float32: half the memory traffic of the lookups, which is what the weighting waits on
        self._logp = np.log(prm.z_hit * np.exp(-0.5 * (d / prm.sigma_hit) ** 2) + z_rand).astype(np.float32)
        self._outside = math.log(
            prm.z_hit * math.exp(-0.5 * (field.max_distance / prm.sigma_hit) ** 2) + z_rand
        )
        self._free_xy = field.free_positions()
        if self._free_xy.shape[0] == 0:
            raise ValueError("the map has no free cells to localize in")
        # the free cells sorted by their class (the last group: no class), for semantic draws
        self._class_xy = np.zeros((0, 2))
        self._class_start = np.zeros(1, dtype=np.int64)
        if semantic is not None:
            iy, ix = np.nonzero(field.free)  # the order of free_positions()
            y = semantic.classes_at(iy, ix)
            order = np.argsort(y, kind="stable")
            self._class_xy = self._free_xy[order]
            counts = np.bincount(y, minlength=len(semantic.classes) + 1)
            self._class_start = np.concatenate([[0], np.cumsum(counts)])
        self._draw_pending = False
        self._likelihood: np.ndarray | None = None  # Pr(z_t | y) of the last weighting
        self._sem_driven = 0.0
        self._sem_class = -1
        self._driven = 0.0
        self._history: list[tuple[float, np.ndarray, np.ndarray]] = []  # (driven, odom, Pr(z | y))
        self.particles = np.zeros((0, 3))
        self.weights = np.zeros(0)
        self._odom: np.ndarray | None = None
        self._last_update: np.ndarray | None = None
        self._w_slow = 0.0
        self._w_fast = 0.0
        self._first_resample = True
        self.updates = 0
        self.resamples = 0
        self.injected = 0

    # ------------------------------------------------------------------ initialisation
    def _uniform(self, n: int) -> np.ndarray:
        res = self.field.resolution
        k = self.rng.integers(0, self._free_xy.shape[0], n)
        xy = self._free_xy[k] + self.rng.uniform(-0.5 * res, 0.5 * res, (n, 2))
        th = self.rng.uniform(-math.pi, math.pi, n)
        return np.column_stack([xy, th])

    def semantic_draw(self, n: int, likelihood: npt.ArrayLike) -> np.ndarray:
        """``(n, 3)`` map-frame poses on the free cells, a cell drawn in proportion to
        ``likelihood[y]`` of its class ``y`` (``(K + 1,)``, the last entry for cells without
        class: :meth:`~knowledge.localization.semantic.SemanticMap.class_likelihood`), any
        heading. With the labels' statistics as ``likelihood`` this is the posterior of a
        uniform prior after the semantic observation alone."""
        if self.semantic is None:
            raise ValueError("a semantic draw needs the semantic map")
        lik = np.asarray(likelihood, dtype=np.float64)
        start = self._class_start
        counts = np.diff(start)
        if lik.shape != counts.shape or lik.min() < 0:
            raise ValueError(f"likelihood must be {counts.shape[0]} non-negative numbers, got {lik.shape}")
        mass = counts * lik
        if mass.sum() <= 0:
            return self._uniform(n)
        per_class = self.rng.multinomial(n, mass / mass.sum())
        idx = np.concatenate(
            [start[c] + self.rng.integers(0, counts[c], m) for c, m in enumerate(per_class) if m]
        )
        res = self.field.resolution
        xy = self._class_xy[idx] + self.rng.uniform(-0.5 * res, 0.5 * res, (n, 2))
        th = self.rng.uniform(-math.pi, math.pi, n)
        return np.column_stack([xy, th])

    def init_uniform(self) -> None:
        """Global localization: particles uniform over the free cells, any heading."""
        prm = self.params
        n = prm.initial_particles or prm.particles
        self.particles = self._uniform(n)
        self.weights = np.full(n, 1.0 / n)
        self._first_resample = n != prm.particles
        self._reset()
        self._draw_pending = prm.semantic_proposal and self.semantic is not None

    def init_pose(self, pose: npt.ArrayLike, std: tuple[float, float, float] = (0.1, 0.1, 0.05)) -> None:
        """Pose tracking: particles Gaussian around the world ``pose`` (stds: m, m, rad)."""
        n = self.params.particles
        p = self.field.to_map(np.asarray(pose, dtype=np.float64))
        self.particles = np.column_stack([self.rng.normal(p[i], std[i], n) for i in range(3)])
        self.particles[:, 2] = wrap(self.particles[:, 2])
        self.weights = np.full(n, 1.0 / n)
        self._first_resample = False
        self._reset()

    def _reset(self) -> None:
        self._odom = None
        self._last_update = None
        self._w_slow = self._w_fast = 0.0
        self._draw_pending = False
        self._likelihood = None
        self._sem_driven = 0.0
        self._sem_class = -1
        self._driven = 0.0
        self._history = []

    # ------------------------------------------------------------------ the filter
    def update(
        self,
        odom: npt.ArrayLike,
        ranges: npt.ArrayLike,
        angles: npt.ArrayLike,
        *,
        range_max: float,
        range_min: float = 0.0,
        proba: npt.ArrayLike | None = None,
    ) -> bool:
        """One step with the laser's odometry pose and its scan (``proba``: the classifier's
        histogram over the semantic map's classes). Returns whether the particles were
        weighted (the robot had moved enough)."""
        if self.particles.shape[0] == 0:
            raise ValueError("initialise the filter first (init_uniform or init_pose)")
        o = np.asarray(odom, dtype=np.float64)
        if self._odom is None:
            self._odom = o
            self._last_update = o
        else:
            self.particles = sample_motion(self.particles, self._odom, o, self.params.motion, self.rng)
            self._odom = o
        assert self._last_update is not None
        moved = between(self._last_update, o)
        prm = self.params
        if (
            self.updates
            and math.hypot(moved[0], moved[1]) < prm.update_distance
            and abs(moved[2]) < prm.update_angle
        ):
            return False
        self._last_update = o
        self._sem_driven += math.hypot(moved[0], moved[1])
        self._driven += math.hypot(moved[0], moved[1])
        self._weigh(ranges, angles, range_max, range_min, proba)
        self.updates += 1
        return True

    def _endpoints(
        self, ranges: npt.ArrayLike, angles: npt.ArrayLike, range_max: float, range_min: float
    ) -> tuple[np.ndarray, np.ndarray]:
        r = np.asarray(ranges, dtype=np.float64)
        a = np.asarray(angles, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            ok = (
                np.isfinite(r)
                & (r > max(range_min, 0.0))
                & (r < range_max * (1 - 1e-6))
                & (r <= self.params.max_range)
            )
        idx = np.nonzero(ok)[0]
        if idx.size > self.params.beams:
            idx = idx[np.linspace(0, idx.size - 1, self.params.beams).round().astype(np.int64)]
        return r[idx] * np.cos(a[idx]), r[idx] * np.sin(a[idx])

    def _weigh(
        self,
        ranges: npt.ArrayLike,
        angles: npt.ArrayLike,
        range_max: float,
        range_min: float,
        proba: npt.ArrayLike | None,
    ) -> None:
        prm = self.params
        semantic_factor = False
        if self.semantic is not None and proba is not None:
            h = np.asarray(proba, dtype=np.float64)
            self._likelihood = self.semantic.class_likelihood(h, prm.semantic_observation)
            if prm.proposal_history > 0:
                self._remember(self._likelihood)
            z = int(np.argmax(h))
            if self._draw_pending:  # the initial draw from the semantic proposal
                n = self.particles.shape[0]
                self.particles = self.semantic_draw(n, self._likelihood)
                self.weights = np.full(n, 1.0 / n)
                self._sem_driven, self._sem_class = 0.0, z  # the draw holds this observation
            elif prm.semantic_weight > 0 and (
                self._sem_driven >= prm.semantic_distance or z != self._sem_class
            ):
                semantic_factor = True
                self._sem_driven, self._sem_class = 0.0, z
        self._draw_pending = False
        P = self.particles
        res = self.field.resolution
        rows_n, cols_n = self.field.shape
        col = np.floor(P[:, 0] / res).astype(np.int64)
        row = np.floor(P[:, 1] / res).astype(np.int64)
        inside = (row >= 0) & (row < rows_n) & (col >= 0) & (col < cols_n)
        logw = np.zeros(P.shape[0])
        free = np.zeros(P.shape[0], dtype=bool)
        free[inside] = self.field.free[row[inside], col[inside]]
        logw[~free] += math.log(prm.off_map)
        logw[~inside] = -np.inf
        fit = None
        if prm.laser:
            bx, by = self._endpoints(ranges, angles, range_max, range_min)
            if bx.size:
                ll = beam_log_likelihood(np.ascontiguousarray(P), bx, by, self._logp, res, self._outside)
                logw += prm.beam_weight * ll
                fit = np.exp(ll / bx.size)  # per-beam likelihood, for recovery
        if semantic_factor and self.semantic is not None and self._likelihood is not None:
            logw += prm.semantic_weight * np.log(self._likelihood)[self.semantic.classes_at(row, col)]
        if (
            prm.semantic_recovery
            and fit is not None
            and self.semantic is not None
            and self._likelihood is not None
        ):
            # recovery watches how well the particles' places explain the label too
            fit = fit * self._likelihood[self.semantic.classes_at(row, col)]
        self._apply(logw, fit)

    def _remember(self, likelihood: np.ndarray) -> None:
        """Keep the label of this update for the history proposal (one per metre driven)."""
        assert self._last_update is not None
        hist = self._history
        if hist and self._driven - hist[-1][0] < _HISTORY_STEP:
            return
        hist.append((self._driven, self._last_update.copy(), likelihood))
        while hist and self._driven - hist[0][0] > self.params.proposal_history:
            hist.pop(0)

    def _past(self) -> tuple[np.ndarray, np.ndarray]:
        """The history's labels before this update: ``(H, 3)`` their odometry poses relative
        to the current one and ``(H, K + 1)`` their log-likelihoods per class."""
        assert self._odom is not None
        past = [(o, lik) for at, o, lik in self._history if self._driven - at > 0.5 * _HISTORY_STEP]
        if not past:
            return np.zeros((0, 3)), np.zeros((0, 0))
        rel = np.array([between(self._odom, o) for o, _ in past])
        return rel, np.log(np.array([lik for _, lik in past]))

    def history_draw(self, n: int) -> np.ndarray:
        """``(n, 3)`` poses drawn in proportion to the current label and the labels of the
        history (``proposal_history``; see :class:`MclParams`): :data:`_OVERSAMPLE` times ``n``
        candidates from :meth:`semantic_draw`, kept in proportion to how well the history's
        labels fit at the places the odometry puts them behind each candidate."""
        assert self.semantic is not None and self._likelihood is not None and self._odom is not None
        cand = self.semantic_draw(_OVERSAMPLE * n, self._likelihood)
        rel, loglik = self._past()
        if not rel.shape[0]:
            return cand[:n]
        score = history_scores(cand, rel, loglik, self.semantic.labels, self.field.resolution)
        p = np.exp(score - score.max())
        distinct = np.count_nonzero(p) >= n  # (scores far below the best underflow to 0)
        return cand[self.rng.choice(cand.shape[0], n, replace=not distinct, p=p / p.sum())]

    def history_fit(self) -> tuple[float, float]:
        """``(L_p, L_q)``: the per-label likelihood of the label history (the geometric mean of
        ``Pr(z_j | y)`` over its labels) at the particles (weighted) and at the places the
        history proposal draws (:data:`_OVERSAMPLE` × 1,000 candidates from the current label,
        averaged in proportion to their history likelihood); ``(1, 1)`` without history."""
        assert self.semantic is not None and self._likelihood is not None and self._odom is not None
        rel, loglik = self._past()
        h = rel.shape[0]
        if not h:
            return 1.0, 1.0
        lab, res = self.semantic.labels, self.field.resolution
        own = history_scores(np.ascontiguousarray(self.particles), rel, loglik, lab, res)
        cand = self.semantic_draw(_OVERSAMPLE * 1000, self._likelihood)
        score = history_scores(cand, rel, loglik, lab, res)
        p = np.exp(score - score.max())
        a_p = float(np.sum(self.weights * own) / np.sum(self.weights))
        a_q = float(np.sum(p * score) / np.sum(p))
        return math.exp(a_p / h), math.exp(a_q / h)

    def _apply(self, logw: np.ndarray, fit: np.ndarray | None) -> None:
        prm = self.params
        lw = np.log(np.maximum(self.weights, 1e-300)) + logw
        top = np.max(lw)
        if not np.isfinite(top):  # every particle left the map: start again
            self.init_uniform()
            return
        w = np.exp(lw - top)
        w /= w.sum()
        self.weights = w
        if fit is not None and prm.alpha_fast > 0:
            alive = np.isfinite(logw)
            w_avg = float(np.mean(fit[alive])) if alive.any() else 0.0
            self._w_slow = (
                w_avg if self._w_slow == 0 else self._w_slow + prm.alpha_slow * (w_avg - self._w_slow)
            )
            self._w_fast = (
                w_avg if self._w_fast == 0 else self._w_fast + prm.alpha_fast * (w_avg - self._w_fast)
            )
        neff = 1.0 / float(np.sum(w * w))
        if neff < prm.resample_threshold * w.size or self._first_resample:
            self._resample()

    def _resample(self) -> None:
        prm = self.params
        n = prm.particles
        w = self.weights
        # low-variance sampling
        positions = (self.rng.uniform() + np.arange(n)) / n
        cum = np.cumsum(w)
        cum[-1] = 1.0
        idx = np.searchsorted(cum, positions)
        P = self.particles[idx]
        inject = 0
        share = 0.0
        if prm.alpha_fast > 0 and self._w_slow > 0:
            share = max(0.0, 1.0 - self._w_fast / self._w_slow)
        if (
            prm.history_reset > 0
            and prm.semantic_proposal
            and prm.proposal_history > 0
            and self.semantic is not None
            and self._likelihood is not None
            and len(self._history) > 0.5 * prm.proposal_history / _HISTORY_STEP
        ):
            l_p, l_q = self.history_fit()
            share = max(share, 1.0 - min(l_p / l_q, 1.0) ** prm.history_reset)
        if share > 0:
            inject = int(self.rng.binomial(n, min(share, 1.0)))
        if inject:
            if prm.semantic_proposal and self.semantic is not None and self._likelihood is not None:
                new = (
                    self.history_draw(inject)
                    if prm.proposal_history > 0
                    else self.semantic_draw(inject, self._likelihood)
                )
            else:
                new = self._uniform(inject)
            P[self.rng.choice(n, inject, replace=False)] = new
            self.injected += inject
        self.particles = P
        self.weights = np.full(n, 1.0 / n)
        self._first_resample = False
        self.resamples += 1

    # ------------------------------------------------------------------ answers
    def estimate(self) -> Estimate:
        """The pose of the heaviest cluster (see the module docstring), in the world frame."""
        P, w = self.particles, self.weights
        cell = 0.5
        key = np.floor(P[:, :2] / cell).astype(np.int64)
        k = key[:, 0] * 1_000_003 + key[:, 1]
        uniq, inv = np.unique(k, return_inverse=True)
        mass = np.bincount(inv, weights=w, minlength=uniq.size)
        best = int(np.argmax(mass))
        sel = inv == best
        centre = np.average(P[sel, :2], axis=0, weights=w[sel] + 1e-300)
        near = np.hypot(P[:, 0] - centre[0], P[:, 1] - centre[1]) <= self.params.cluster_radius
        wn = w[near] + 1e-300
        Pn = P[near]
        mx, my = np.average(Pn[:, 0], weights=wn), np.average(Pn[:, 1], weights=wn)
        th = math.atan2(float(np.sum(wn * np.sin(Pn[:, 2]))), float(np.sum(wn * np.cos(Pn[:, 2]))))
        d = np.column_stack([Pn[:, 0] - mx, Pn[:, 1] - my, wrap(Pn[:, 2] - th)])
        cov = (d * (wn / wn.sum())[:, None]).T @ d
        pose = self.field.to_world(np.array([mx, my, th]))
        spread = float(np.sqrt(np.sum(w * ((P[:, 0] - mx) ** 2 + (P[:, 1] - my) ** 2))))
        return Estimate(pose, cov, float(w[near].sum()), spread)

    def world_particles(self) -> np.ndarray:
        """``(N, 3)`` the particles in the world frame."""
        return self.field.to_world(self.particles)
