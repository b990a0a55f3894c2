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
   after ``confirm_hits`` associated scans, of which at least ``confirm_evidence`` had
   *evidence* (the caller says which detections have it: e.g. the laser saw through that
   place a moment before, :mod:`knowledge.people.freespace`, so someone walked in), or once
   it has moved ``confirm_travel`` metres from where it was born (someone walking away from
   the laser hides their own next position, so the laser never sees through it); a
   tentative track that misses ``tentative_misses`` scans in a row is dropped. With
   ``min_travel`` > 0 a new track must also have moved that far from where it was born before it
   is confirmed, whatever its evidence (a table leg stays put; so, measured on the benchmark
   bag, does a person standing in a group: docs/people.md). Detections
   the caller marks as no *birth* (e.g. on cells the laser has hit for seconds: furniture,
   :mod:`knowledge.people.static`) may feed confirmed tracks — a person who walked up and
   stands still stays tracked — but neither start nor feed tentative ones;
5. deaths: a confirmed track that misses more than ``max_misses`` scans in a row is deleted.
   While it misses it coasts on its prediction (``misses > 0`` in its state). Misses while
   the caller says the predicted position is *occluded* (something nearer on the laser's
   beam towards it: a passer-by, a door jamb the person turned round) do not count, for at
   most ``max_occluded`` seconds since it was last seen: a person hidden for a moment keeps
   their track (and follow-me its target).

Ids are integers from 1, given in order of confirmation, never given to another person's
track by one tracker; but a track confirmed within ``revive_radius`` metres of where a confirmed
track was last seen, less than ``revive_for`` seconds after it vanished, *continues* that track
with its id (the person stepped out of view, round a corner, behind someone, and back). It needs
no evidence then: a person the laser saw walking a moment ago may stand still now.
"""

from __future__ import annotations

import math
from collections.abc import Callable
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
    confirm_evidence: int = 0
    confirm_travel: float | None = None
    max_occluded: float = 0.0
    revive_radius: float = 0.0
    revive_for: float = 0.0
    min_travel: float = 0.0

    def __post_init__(self) -> None:
        for name in ("gate", "accel_std", "meas_std", "init_speed_std"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"TrackerConfig.{name} must be a positive number, got {v!r}")
        for name in ("confirm_hits", "tentative_misses", "max_misses"):
            v = getattr(self, name)
            if int(v) != v or v < 1:
                raise ValueError(f"TrackerConfig.{name} must be an integer >= 1, got {v!r}")
        if self.confirm_travel is not None and not (
            math.isfinite(self.confirm_travel) and self.confirm_travel > 0
        ):
            raise ValueError(
                f"TrackerConfig.confirm_travel must be None or a positive number, got {self.confirm_travel!r}"
            )
        for name in ("revive_radius", "revive_for", "min_travel"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"TrackerConfig.{name} must be a number >= 0, got {v!r}")
        if not (math.isfinite(self.max_occluded) and self.max_occluded >= 0):
            raise ValueError(
                f"TrackerConfig.max_occluded must be a number of seconds >= 0, got {self.max_occluded!r}"
            )
        v = self.confirm_evidence
        if int(v) != v or not 0 <= v <= self.confirm_hits:
            raise ValueError(
                f"TrackerConfig.confirm_evidence must be an integer in 0..confirm_hits, got {v!r}"
            )


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
        travelled: metres, the farthest the track's estimated position has been from where it
            was born (a person walks; a table leg taken for a leg stays put).
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
    travelled: float = 0.0

    @property
    def speed(self) -> float:
        return float(np.hypot(*self.velocity))


@dataclass(slots=True)
class _Track:
    """A track's state in closed form. The tracker's covariance never couples the axes (``F``,
    ``Q``, ``H``, ``R`` and the birth covariance are all block-diagonal in (x, vx) and (y, vy)),
    so each axis keeps its 2×2 block ``[[a, b], [b, c]]`` (position variance, position–velocity
    covariance, velocity variance); the 4×4 covariance has zeros elsewhere."""

    px: float
    py: float
    vx: float
    vy: float
    ax: float
    bx: float
    cx: float
    ay: float
    by: float
    cy: float
    born: float
    last_seen: float
    hits: int = 1
    misses: int = 0
    age: int = 1
    id: int = 0  # 0 while tentative
    x0: float = 0.0  # where it was born
    y0: float = 0.0
    travelled: float = 0.0  # the farthest the corrected position has been from (x0, y0)
    evidence: int = 0  # associated detections that had evidence (while tentative)
    hidden: int = 0  # of the misses in a row, those while the predicted position was occluded

    def predict(self, dt: float, q00: float, q01: float, q11: float) -> None:
        """:func:`kalman_predict` over ``dt`` seconds with process noise ``[[q00, q01], [q01, q11]]`` per axis."""
        self.px, self.vx, self.ax, self.bx, self.cx = _predict_axis(
            self.px, self.vx, self.ax, self.bx, self.cx, dt, q00, q01, q11
        )
        self.py, self.vy, self.ay, self.by, self.cy = _predict_axis(
            self.py, self.vy, self.ay, self.by, self.cy, dt, q00, q01, q11
        )

    def correct(self, zx: float, zy: float, r: float) -> None:
        """:func:`kalman_update` with the position ``(zx, zy)`` of variance ``r`` per axis (Joseph form)."""
        self.px, self.vx, self.ax, self.bx, self.cx = _correct_axis(
            self.px, self.vx, self.ax, self.bx, self.cx, zx, r
        )
        self.py, self.vy, self.ay, self.by, self.cy = _correct_axis(
            self.py, self.vy, self.ay, self.by, self.cy, zy, r
        )


Axis = tuple[float, float, float, float, float]


def _predict_axis(
    p: float, v: float, a: float, b: float, c: float, dt: float, q00: float, q01: float, q11: float
) -> Axis:
    """One axis of :func:`kalman_predict`: position ``p``, velocity ``v`` and their covariance
    ``[[a, b], [b, c]]`` ``dt`` seconds ahead, with process noise ``[[q00, q01], [q01, q11]]``."""
    return p + dt * v, v, (a + dt * b) + dt * (b + dt * c) + q00, (b + dt * c) + q01, c + q11


def _correct_axis(p: float, v: float, a: float, b: float, c: float, z: float, r: float) -> Axis:
    """One axis of :func:`kalman_update` (Joseph form): the state corrected with position ``z`` of variance ``r``."""
    s = a + r
    kp, kv = a / s, b / s
    e = z - p
    g = 1.0 - kp
    return (
        p + kp * e,
        v + kv * e,
        g * a * g + r * kp * kp,
        g * (b - kv * a) + r * kp * kv,
        (c - kv * b) - kv * (b - kv * a) + r * kv * kv,
    )


def _assign(dist: list[list[float]], gate: float) -> list[tuple[int, int]]:
    """The (row, column) pairs, by row, of the minimal-sum assignment of ``dist`` (rows ×
    columns, at least 1 × 1) that are within ``gate``.

    Pairs further than ``gate`` cost a large constant instead of their distance (Hungarian
    method). Two cases need no Hungarian method. If no row and no column has two pairs within
    the gate, every minimal assignment holds all of them (leaving one out costs the constant
    minus its distance): they are the answer. A single row or column with a unique nearest
    entry within the gate: the nearest is the optimum.
    """
    near = [(i, j) for i, row in enumerate(dist) for j, d in enumerate(row) if d <= gate]
    if len({i for i, _ in near}) == len(near) == len({j for _, j in near}):
        return near
    if len(dist) == 1 or len(dist[0]) == 1:
        flat = dist[0] if len(dist) == 1 else [row[0] for row in dist]
        d = min(flat)
        if flat.count(d) == 1:
            k = flat.index(d)
            return [(0, k)] if len(dist) == 1 else [(k, 0)]
    cost = np.array(dist)
    rows, cols = linear_sum_assignment(np.where(cost > gate, gate * 1e3 + 1.0, cost))
    return [(r, c) for r, c in zip(rows.tolist(), cols.tolist(), strict=True) if cost[r, c] <= gate]


class PeopleTracker:
    """Multi-person tracker (see the module doc); call :meth:`update` once per scan."""

    def __init__(self, config: TrackerConfig | None = None) -> None:
        self.config = config or TrackerConfig()
        self._tracks: list[_Track] = []
        self._vanished: list[tuple[int, float, float, float]] = []  # id, x, y, last seen
        self._next_id = 1
        self._time: float | None = None
        self._noise: tuple[tuple[float, float], float, float, float] = ((math.nan, math.nan), 0.0, 0.0, 0.0)

    @property
    def time(self) -> float | None:
        """Time of the last update, seconds (None before the first)."""
        return self._time

    def reset(self) -> None:
        """Forget every track (ids keep counting up)."""
        self._tracks = []
        self._vanished = []
        self._time = None

    def tracks(self, *, include_tentative: bool = False) -> list[TrackState]:
        """Current confirmed tracks (and tentative ones, id 0, if asked), by id."""
        sel = [t for t in self._tracks if t.id > 0 or include_tentative]
        if not sel:
            return []
        sel.sort(key=lambda t: (t.id == 0, t.id))
        # one array for all states, one for all covariances: each state gets its own rows
        X = np.array([(t.px, t.py, t.vx, t.vy) for t in sel])
        C = np.array(
            [
                (t.ax, 0.0, t.bx, 0.0, 0.0, t.ay, 0.0, t.by, t.bx, 0.0, t.cx, 0.0, 0.0, t.by, 0.0, t.cy)
                for t in sel
            ]
        ).reshape(-1, 4, 4)
        return [
            TrackState(
                id=t.id,
                position=X[k, :2],
                velocity=X[k, 2:],
                covariance=C[k],
                hits=t.hits,
                misses=t.misses,
                age=t.age,
                first_seen=t.born,
                last_seen=t.last_seen,
                travelled=t.travelled,
            )
            for k, t in enumerate(sel)
        ]

    def _revive(self, tr: _Track, t: float) -> int:
        """The id of the vanished confirmed track that ``tr`` continues (0: none): the nearest
        within ``revive_radius`` of ``tr``'s birth place that vanished less than ``revive_for``
        seconds ago and was last seen before ``tr`` was born."""
        cfg = self.config
        self._vanished = [v for v in self._vanished if t - v[3] <= cfg.revive_for]
        best, best_d = -1, cfg.revive_radius
        for k, (_, x, y, seen) in enumerate(self._vanished):
            d = math.hypot(tr.x0 - x, tr.y0 - y)
            if seen < tr.born and d <= best_d:
                best, best_d = k, d
        if best < 0:
            return 0
        return self._vanished.pop(best)[0]

    def _process_noise(self, dt: float) -> tuple[float, float, float]:
        """The per-axis block ``(q00, q01, q11)`` of :func:`cv_process_noise` over ``dt``
        (cached: scans mostly come at a fixed rate)."""
        key = (dt, self.config.accel_std)
        if self._noise[0] != key:
            Q = cv_process_noise(dt, self.config.accel_std)
            self._noise = (key, float(Q[0, 0]), float(Q[0, 2]), float(Q[2, 2]))
        return self._noise[1:]

    def update(
        self,
        detections: npt.ArrayLike,
        t: float,
        *,
        evidence: npt.ArrayLike | None = None,
        births: npt.ArrayLike | None = None,
        occluded: Callable[[FloatArray], npt.ArrayLike] | None = None,
    ) -> list[TrackState]:
        """Advance to time ``t`` (seconds) with person positions ``(K, 2)``; returns the confirmed tracks.

        ``evidence`` ``(K,)`` bool: the detections that count towards ``confirm_evidence``
        (None: all). ``births`` ``(K,)`` bool: the detections that may start or feed a
        tentative track (None: all); the others can only feed confirmed tracks. ``occluded``:
        given the predicted positions ``(M, 2)`` of the confirmed tracks that missed this scan,
        says ``(M,)`` bool which of them something nearer hides from the sensor (see
        ``max_occluded``).
        """
        Z = (
            np.asarray(detections, dtype=np.float64).reshape(-1, 2)
            if np.size(detections)
            else np.zeros((0, 2))
        )
        if not np.isfinite(Z).all():
            raise ValueError("detections must be finite (K, 2) positions in metres")
        K0 = Z.shape[0]
        ev = np.ones(K0, dtype=bool) if evidence is None else np.asarray(evidence, dtype=bool).reshape(-1)
        may = np.ones(K0, dtype=bool) if births is None else np.asarray(births, dtype=bool).reshape(-1)
        if ev.shape != (K0,) or may.shape != (K0,):
            raise ValueError(f"evidence and births must be ({K0},) bool, one per detection")
        if not math.isfinite(t):
            raise ValueError(f"t must be a finite time in seconds, got {t!r}")
        cfg = self.config
        dt = 0.0 if self._time is None else t - self._time
        if dt < 0:
            raise ValueError(f"time went backwards: update at t={t} after t={self._time}; call reset() first")
        self._time = t
        if dt > 0 and self._tracks:
            q00, q01, q11 = self._process_noise(dt)
            for tr in self._tracks:
                tr.predict(dt, q00, q01, q11)
        zs: list[list[float]] = Z.tolist()
        K = len(zs)
        free = [True] * K
        n_free = K
        seen: set[int] = set()
        r = cfg.meas_std**2
        for confirmed in (True, False):
            if n_free == 0:
                break
            group = [tr for tr in self._tracks if (tr.id > 0) == confirmed]
            if not group:
                continue
            cand = [k for k in range(K) if free[k] and (confirmed or may[k])]
            if not cand:
                continue
            dist = [[math.hypot(tr.px - zs[k][0], tr.py - zs[k][1]) for k in cand] for tr in group]
            for row, col in _assign(dist, cfg.gate):
                tr = group[row]
                k = cand[col]
                tr.correct(zs[k][0], zs[k][1], r)
                tr.travelled = max(tr.travelled, math.hypot(tr.px - tr.x0, tr.py - tr.y0))
                tr.hits += 1
                tr.evidence += int(ev[k])
                tr.misses = 0
                tr.last_seen = t
                free[k] = False
                n_free -= 1
                seen.add(id(tr))
        hidden: set[int] = set()
        if occluded is not None and cfg.max_occluded > 0:
            missing = [tr for tr in self._tracks if tr.id > 0 and id(tr) not in seen]
            if missing:
                flags = np.asarray(occluded(np.array([(tr.px, tr.py) for tr in missing])), dtype=bool)
                hidden = {id(tr) for tr, f in zip(missing, flags.reshape(-1).tolist(), strict=True) if f}
        survivors: list[_Track] = []
        for tr in self._tracks:
            if id(tr) not in seen:
                tr.misses += 1
                tr.hidden += id(tr) in hidden
            else:
                tr.hidden = 0
            tr.age += 1
            if tr.id > 0:
                if tr.misses - tr.hidden <= cfg.max_misses and (
                    tr.hidden == 0 or t - tr.last_seen <= cfg.max_occluded
                ):
                    survivors.append(tr)
                elif cfg.revive_radius > 0:
                    self._vanished.append((tr.id, tr.px, tr.py, tr.last_seen))
            elif tr.misses < cfg.tentative_misses:
                if tr.hits >= cfg.confirm_hits:
                    revived = self._revive(tr, t)
                    if revived:
                        tr.id = revived
                    elif tr.travelled >= cfg.min_travel and (
                        tr.evidence >= cfg.confirm_evidence
                        or (cfg.confirm_travel is not None and tr.travelled >= cfg.confirm_travel)
                    ):
                        tr.id = self._next_id
                        self._next_id += 1
                survivors.append(tr)
        if n_free:
            p0 = cfg.meas_std**2
            v0 = cfg.init_speed_std**2
            for k in range(K):
                if not (free[k] and may[k]):
                    continue
                x, y = zs[k]
                tr = _Track(x, y, 0.0, 0.0, p0, 0.0, v0, p0, 0.0, v0, born=t, last_seen=t, x0=x, y0=y)
                tr.evidence = int(ev[k])
                if cfg.confirm_hits <= 1 and tr.evidence >= cfg.confirm_evidence and cfg.min_travel == 0:
                    tr.id = self._next_id
                    self._next_id += 1
                survivors.append(tr)
        self._tracks = survivors
        return self.tracks()
