"""People tracked over scans: constant-velocity Kalman filters, nearest-neighbour association.

Each track's state is ``x = (x, y, vx, vy)`` (metres, metres per second) in one fixed frame
(the sensor's if it does not move, else the odometry or map frame: transform the detections
first). Between scans the state follows a constant-velocity model driven by white-noise
acceleration of standard deviation ``accel_std`` (m/s²):

    F = [[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1]],
    Q = accel_std² · [[dt⁴/4, dt³/2], [dt³/2, dt²]] per axis;

detections are positions with noise ``meas_std`` (m): ``H = [I 0]``, ``R = meas_std² I``.

Each scan (:meth:`PeopleTracker.update`):

1. every track is predicted to the scan's time;
2. detections are associated with tracks by global nearest neighbour: the assignment that
   minimises the summed Euclidean distances between predicted positions and detections
   (Hungarian method), pairs further apart than ``gate`` metres are not associated.
   Confirmed tracks are served first, tentative ones get the detections left over;
3. associated tracks are corrected with their detection (Kalman update);
4. births: every detection left over starts a *tentative* track (velocity 0, uncertain by
   ``init_speed_std``). It becomes *confirmed* — and only then gets its id and is reported —
   after ``confirm_hits`` associated scans; a tentative track that misses ``tentative_misses``
   scans in a row is dropped;
5. deaths: a confirmed track that misses more than ``max_misses`` scans in a row is deleted.
   While it misses it coasts on its prediction (``misses > 0`` in its state).

Ids are integers from 1, given in order of confirmation, never reused by one tracker.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from knowledge.people.segmentation import FloatArray


@dataclass(frozen=True)
class TrackerConfig:
    """Parameters of :class:`PeopleTracker` (units in the module doc)."""

    gate: float = 0.6
    confirm_hits: int = 3
    tentative_misses: int = 1
    max_misses: int = 10
    accel_std: float = 2.0
    meas_std: float = 0.08
    init_speed_std: float = 1.0

    def __post_init__(self) -> None:
        for name in ("gate", "accel_std", "meas_std", "init_speed_std"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"TrackerConfig.{name} must be a positive number, got {v!r}")
        for name in ("confirm_hits", "tentative_misses", "max_misses"):
            v = getattr(self, name)
            if int(v) != v or v < 1:
                raise ValueError(f"TrackerConfig.{name} must be an integer >= 1, got {v!r}")


def cv_transition(dt: float) -> FloatArray:
    """``(4, 4)`` constant-velocity state transition over ``dt`` seconds."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    return F


def cv_process_noise(dt: float, accel_std: float) -> FloatArray:
    """``(4, 4)`` process noise of white acceleration ``accel_std`` m/s² over ``dt`` seconds."""
    q = accel_std**2
    Q = np.zeros((4, 4))
    for p, v in ((0, 2), (1, 3)):
        Q[p, p] = q * dt**4 / 4
        Q[p, v] = Q[v, p] = q * dt**3 / 2
        Q[v, v] = q * dt**2
    return Q


def kalman_predict(
    x: FloatArray, P: FloatArray, dt: float, accel_std: float
) -> tuple[FloatArray, FloatArray]:
    """Predict state ``(4,)`` and covariance ``(4, 4)`` ``dt`` seconds ahead."""
    F = cv_transition(dt)
    return F @ x, F @ P @ F.T + cv_process_noise(dt, accel_std)


def kalman_update(
    x: FloatArray, P: FloatArray, z: FloatArray, meas_std: float
) -> tuple[FloatArray, FloatArray]:
    """Correct state ``(4,)`` / covariance ``(4, 4)`` with a position ``z`` ``(2,)`` (Joseph form)."""
    H = np.zeros((2, 4))
    H[0, 0] = H[1, 1] = 1.0
    R = np.eye(2) * meas_std**2
    S = H @ P @ H.T + R
    K = np.linalg.solve(S, H @ P).T
    x = x + K @ (z - H @ x)
    IKH = np.eye(4) - K @ H
    return x, IKH @ P @ IKH.T + K @ R @ K.T


@dataclass(frozen=True)
class TrackState:
    """A confirmed track as reported after a scan.

    Attributes:
        id: stable integer id (from 1).
        position: ``(2,)`` metres; velocity: ``(2,)`` m/s; covariance: ``(4, 4)`` of (x, y, vx, vy).
        hits: scans with an associated detection; misses: scans missed in a row (0 = seen now).
        age: scans since birth; first_seen, last_seen: times in seconds.
    """

    id: int
    position: FloatArray
    velocity: FloatArray
    covariance: FloatArray
    hits: int
    misses: int
    age: int
    first_seen: float
    last_seen: float

    @property
    def speed(self) -> float:
        return float(np.hypot(*self.velocity))


@dataclass
class _Track:
    x: FloatArray
    P: FloatArray
    born: float
    last_seen: float
    hits: int = 1
    misses: int = 0
    age: int = 1
    id: int = 0  # 0 while tentative

    @property
    def confirmed(self) -> bool:
        return self.id > 0

    def state(self) -> TrackState:
        return TrackState(
            id=self.id,
            position=self.x[:2].copy(),
            velocity=self.x[2:].copy(),
            covariance=self.P.copy(),
            hits=self.hits,
            misses=self.misses,
            age=self.age,
            first_seen=self.born,
            last_seen=self.last_seen,
        )


class PeopleTracker:
    """Multi-person tracker (see the module doc); call :meth:`update` once per scan."""

    def __init__(self, config: TrackerConfig | None = None) -> None:
        self.config = config or TrackerConfig()
        self._tracks: list[_Track] = []
        self._next_id = 1
        self._time: float | None = None

    @property
    def time(self) -> float | None:
        """Time of the last update, seconds (None before the first)."""
        return self._time

    def reset(self) -> None:
        """Forget every track (ids keep counting up)."""
        self._tracks = []
        self._time = None

    def tracks(self, *, include_tentative: bool = False) -> list[TrackState]:
        """Current confirmed tracks (and tentative ones, id 0, if asked), by id."""
        out = [t.state() for t in self._tracks if t.confirmed or include_tentative]
        return sorted(out, key=lambda s: (s.id == 0, s.id))

    def update(self, detections: npt.ArrayLike, t: float) -> list[TrackState]:
        """Advance to time ``t`` (seconds) with person positions ``(K, 2)``; returns the confirmed tracks."""
        Z = (
            np.asarray(detections, dtype=np.float64).reshape(-1, 2)
            if np.size(detections)
            else np.zeros((0, 2))
        )
        if not np.isfinite(Z).all():
            raise ValueError("detections must be finite (K, 2) positions in metres")
        if not math.isfinite(t):
            raise ValueError(f"t must be a finite time in seconds, got {t!r}")
        cfg = self.config
        dt = 0.0 if self._time is None else t - self._time
        if dt < 0:
            raise ValueError(f"time went backwards: update at t={t} after t={self._time}; call reset() first")
        self._time = t
        if dt > 0:
            for tr in self._tracks:
                tr.x, tr.P = kalman_predict(tr.x, tr.P, dt, cfg.accel_std)
        free = np.ones(Z.shape[0], dtype=bool)
        seen: set[int] = set()
        for group in (
            [tr for tr in self._tracks if tr.confirmed],
            [tr for tr in self._tracks if not tr.confirmed],
        ):
            cand = np.flatnonzero(free)
            if not group or cand.size == 0:
                continue
            pred = np.array([tr.x[:2] for tr in group])
            dist = np.hypot(pred[:, None, 0] - Z[None, cand, 0], pred[:, None, 1] - Z[None, cand, 1])
            big = cfg.gate * 1e3 + 1.0
            rows, cols = linear_sum_assignment(np.where(dist > cfg.gate, big, dist))
            for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
                if dist[r, c] > cfg.gate:
                    continue
                tr = group[r]
                z = Z[cand[c]]
                tr.x, tr.P = kalman_update(tr.x, tr.P, z, cfg.meas_std)
                tr.hits += 1
                tr.misses = 0
                tr.last_seen = t
                free[cand[c]] = False
                seen.add(id(tr))
        survivors: list[_Track] = []
        for tr in self._tracks:
            if id(tr) not in seen:
                tr.misses += 1
            tr.age += 1
            if tr.confirmed:
                if tr.misses <= cfg.max_misses:
                    survivors.append(tr)
            elif tr.misses < cfg.tentative_misses:
                if tr.hits >= cfg.confirm_hits:
                    tr.id = self._next_id
                    self._next_id += 1
                survivors.append(tr)
        for z in Z[free]:
            P0 = np.diag([cfg.meas_std**2, cfg.meas_std**2, cfg.init_speed_std**2, cfg.init_speed_std**2])
            tr = _Track(x=np.array([z[0], z[1], 0.0, 0.0]), P=P0, born=t, last_seen=t)
            if cfg.confirm_hits <= 1:
                tr.id = self._next_id
                self._next_id += 1
            survivors.append(tr)
        self._tracks = survivors
        return self.tracks()
