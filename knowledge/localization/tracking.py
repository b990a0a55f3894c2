"""Pose tracking: odometry corrected by matching each scan against a map.

:class:`PoseTracker` keeps the ``map → odom`` correction ``C``: the laser's pose in the map
is ``C ⊕ odom`` (``odom``: the laser's odometry pose). For each scan it predicts the pose
from the odometry increment, matches the scan there
(:class:`~knowledge.localization.scan_matching.ScanMatcher`) and, when the match is good,
takes the matched pose and updates ``C``. Two kinds of map:

* **built as it goes** (no map given, the agent's default): the scans are integrated at
  their corrected poses into an occupancy grid of counts
  (:class:`~knowledge.metric.mapping.ScanMapper`), one scan each time the robot has moved
  ``integrate_distance`` or turned ``integrate_angle``; each scan is matched against the
  likelihood field of that grid as it was when the field was last brought up to date, which
  it is when the robot has moved ``refresh_distance`` from where it was then or
  ``refresh_scans`` scans were integrated since. The field covers the whole map and is kept
  up to date tile by tile where the scans changed the map
  (:class:`~knowledge.localization.tracking_field.TrackingField`: about 4 ms of CPU per
  update on the CSAIL log, instead of 26–29 ms to remake the field of a 44 m window around
  the robot, ``field = "window"``, which older recordings replay with). Errors still
  accumulate (there is no loop closure), but only where a scan sees nothing it saw before:
  back in known places the scans match the map made there, which bounds the drift
  (docs/localization.md has how far on real logs).
* **known** (``prior``): one likelihood field of the whole map; nothing is integrated.

**Odometry that stalls, odometry that jumps.** Raw odometry sometimes stands still while the
robot moves (the raw CSAIL log has runs of 4–46 scans without an increment) and then
reports the whole motion at once. The tracker tells the cases apart by what the odometry
says, never by how well a scan happens to fit somewhere else:

* the odometry **stood still** since the last scan (less than :data:`STILL` metres and
  radians) while the tracker was moving: the prediction repeats the last pose, and when the
  scan fits poorly there, the tracker's own last motion is tried as well (the scan matched
  with the search, without the prior, from the last pose moved on by the last step); the
  better fit wins (``fallback = "still"``; ``"poor_fit"``, the rule before, tried it for any
  poor fit, also when the odometry had moved: a stale scan paired with odometry 0.74 m on
  then matched where it was taken, and the error stayed);
* the odometry **moves again** after such a stall: what it reports spans the stall, so the
  correction from before the stall is tried as well (its prediction is the odometry's own
  motion since then), not an extrapolation across the jump.

**Corrections the odometry cannot explain.** The odometry's error grows with its increment:
``σ = floor + noise · increment`` (:class:`TrackingParams`' ``noise_floor``,
``noise_translation``, ``noise_rotation``). A match that moves the pose further from the
prediction than ``gate`` such σ (and is not a stall's: the odometry said nothing then) is
taken, as a ``correction`` event, but the correction it replaced is kept for ``undo_scans``
scans: the next scans may contradict it. The scans after a correction read late out of a
buffer are such a case — they agree with the wrong correction among themselves, and only the
fresh scans after them fit poorly with it. So whenever a scan fits poorly (below the match's
``min_fit``), it is also matched from each kept correction, and one that fits it better on
``confirm_scans`` such scans in a row is taken back (``reverted``; the correction it
replaces is kept in turn). :attr:`TrackStep.uncertain` is set for ``confirm_scans`` scans
after a correction and while scans fit poorly with an alternative at hand, or do not match.

**The odometry as a prior.** Each match also pays for moving away from the prediction
(:class:`~knowledge.localization.scan_matching.MatchParams`' translation and rotation
weights), with weights that shrink as the odometry's increment since the last scan grows —
``prior_translation / (d + 0.01 m)`` and ``prior_rotation / (|Δθ| + 0.01 rad)`` — because
odometry's error grows with the motion it integrates: a robot that moved a centimetre since
the last scan knows where it is to well under a centimetre, one that moved 20 cm and turned
0.3 rad (the CSAIL log between scans) does not. Along a corridor, where the scan barely fixes
the position along it, the prior keeps the odometry's motion instead of letting stray
endpoints (a tutor's legs walking ahead, a door jamb) slide the pose back by a metre; across
walls the scan outweighs it by far. The fallback from the last motion (below) has no prior:
there the odometry is what went wrong.

A scan whose fit stays below ``accept_fit`` (too few endpoints near mapped walls: an open
hall, a scan full of people, the first seconds) keeps the odometry's prediction. All poses
are the laser's ``(x, y, theta)``, metres and radians.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from knowledge.localization.likelihood import LikelihoodField, distance_field
from knowledge.localization.scan_matching import (
    MatchField,
    MatchParams,
    MatchResult,
    ScanMatcher,
    scan_points,
)
from knowledge.localization.se2 import between, compose, inverse
from knowledge.localization.tracking_field import TrackingField
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.mapping import MappingParams, ScanMapper

__all__ = ["PoseTracker", "TrackStep", "TrackingParams"]

FIELD_KINDS = ("incremental", "window")
FALLBACKS = ("still", "poor_fit")
#: Metres and radians: an odometry increment below both is the odometry standing still.
STILL = (1e-3, 1e-3)
#: What a :class:`TrackStep` may report happened (None: a plain step).
EVENTS = ("stall", "resumed", "correction", "reverted")


@dataclass(frozen=True)
class TrackingParams:
    """How :class:`PoseTracker` tracks.

    Attributes:
        match: the scan matcher's parameters.
        max_range: metres; longer beams are not matched (nor mapped).
        beam_step: match every ``beam_step``-th beam.
        accept_fit: the least mean score of a match that is taken (else the prediction is kept).
        resolution: metres per cell of the map built as it goes.
        integrate_distance, integrate_angle: metres, radians of motion between integrated scans.
        field: how the map built as it goes is matched: ``"incremental"`` (one likelihood
            field of the whole map, kept up to date tile by tile where scans changed it:
            :class:`~knowledge.localization.tracking_field.TrackingField`) or ``"window"``
            (the field of a window of the map around the robot, remade at each refresh: the
            tracker before the incremental field, which recordings made then replay with).
        window: metres, half the side of the matching window (``field = "window"`` only).
        refresh_distance: metres from where the field was last brought up to date at which
            it is again.
        refresh_scans: integrated scans after which the field is brought up to date.
        max_distance: metres, where the likelihood field's distances are clipped.
        prior_translation: the prior's translation weight times metres (0: no prior).
        prior_rotation: the prior's rotation weight times radians (0: no prior).
        fallback: when the tracker's own last motion is tried besides the odometry's
            prediction: ``"still"`` (only when the odometry stood still since the last scan)
            or ``"poor_fit"`` (whenever the prediction's fit is poor: recordings made before
            replay with it).
        noise_floor: ``(metres, radians)``, the odometry noise model's σ for no motion.
        noise_translation: metres of σ per metre driven.
        noise_rotation: radians of σ per radian turned (and half that per metre driven).
        gate: a correction beyond this many σ of the odometry's increment goes on probation.
        confirm_scans: poorly fitting scans in a row that must fit better with a replaced
            correction to take it back; also the scans after a large correction during which
            the pose counts as uncertain (0: corrections are never questioned, as before).
        undo_scans: scans for which a replaced correction can be taken back.
    """

    match: MatchParams = field(default_factory=lambda: MatchParams(angular_window=0.4, min_fit=0.8))
    max_range: float = 20.0
    beam_step: int = 2
    accept_fit: float = 0.3
    resolution: float = 0.05
    integrate_distance: float = 0.2
    integrate_angle: float = 0.1
    field: str = "incremental"
    window: float = 22.0
    refresh_distance: float = 2.0
    refresh_scans: int = 5
    max_distance: float = 1.0
    prior_translation: float = 0.15
    prior_rotation: float = 0.02
    fallback: str = "still"
    noise_floor: tuple[float, float] = (0.03, 0.03)
    noise_translation: float = 0.1
    noise_rotation: float = 0.1
    gate: float = 3.0
    confirm_scans: int = 5
    undo_scans: int = 400

    def __post_init__(self) -> None:
        if self.fallback not in FALLBACKS:
            raise ValueError(f"TrackingParams.fallback must be one of {FALLBACKS}, got {self.fallback!r}")
        floor = tuple(float(v) for v in self.noise_floor)
        if len(floor) != 2 or not all(math.isfinite(v) and v > 0 for v in floor):
            raise ValueError(
                f"TrackingParams.noise_floor must be (metres, radians) > 0, got {self.noise_floor!r}"
            )
        object.__setattr__(self, "noise_floor", floor)
        for name in ("noise_translation", "noise_rotation", "gate"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"TrackingParams.{name} must be a finite number >= 0, got {v!r}")
        if (
            isinstance(self.confirm_scans, bool)
            or not isinstance(self.confirm_scans, int)
            or self.confirm_scans < 0
        ):
            raise ValueError(
                f"TrackingParams.confirm_scans must be a whole number >= 0, got {self.confirm_scans!r}"
            )
        for name in ("prior_translation", "prior_rotation"):
            w = getattr(self, name)
            if not (math.isfinite(w) and w >= 0):
                raise ValueError(f"TrackingParams.{name} must be a finite number >= 0, got {w!r}")
        for name in ("max_range", "resolution", "window", "refresh_distance", "max_distance"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"TrackingParams.{name} must be a positive number, got {v!r}")
        if self.beam_step < 1 or self.refresh_scans < 1:
            raise ValueError("beam_step and refresh_scans must be >= 1")
        if not 0.0 <= self.accept_fit <= 1.0:
            raise ValueError(f"accept_fit must be in [0, 1], got {self.accept_fit}")
        if self.field not in FIELD_KINDS:
            raise ValueError(f"TrackingParams.field must be one of {FIELD_KINDS}, got {self.field!r}")


@dataclass(frozen=True)
class TrackStep:
    """One :meth:`PoseTracker.update`.

    Attributes:
        pose: ``(3,)`` the laser's pose in the map frame.
        correction: ``(3,)`` the ``map → odom`` transform after this scan.
        fit: the match's mean score (0 when nothing was matched).
        matched: the match was taken.
        searched: the correlative search ran.
        integrated: the scan went into the map.
        deviation: ``(metres, radians)`` the pose taken from the odometry's prediction.
        sigma: ``(metres, radians)`` the odometry noise model's σ for this scan's increment.
        uncertain: a correction is on probation, or the scan did not fit well enough to be matched.
        event: one of :data:`EVENTS` (the module docstring says when), or None.
    """

    pose: np.ndarray
    correction: np.ndarray
    fit: float
    matched: bool
    searched: bool
    integrated: bool
    deviation: tuple[float, float] = (0.0, 0.0)
    sigma: tuple[float, float] = (0.0, 0.0)
    uncertain: bool = False
    event: str | None = None


#: Mean score by which a scan must fit better with a replaced correction to vote for it.
PROBATION_MARGIN = 0.02
#: Replaced corrections kept at once.
MAX_ALTERNATIVES = 3


@dataclass
class _Alternative:
    """A correction a larger one replaced: since which scan, and the poorly fitting scans in
    a row that fit better with it."""

    correction: np.ndarray
    since: int
    votes: int = 0


class PoseTracker:
    """Scan-to-map pose tracking (see the module docstring).

    Args:
        params: the parameters.
        prior: a known map to track in (None: build the map as it goes).
        initial: the laser's pose in the map at the first scan (default: where the odometry
            says, i.e. the map frame starts as the odometry frame).
    """

    def __init__(
        self,
        params: TrackingParams | None = None,
        *,
        prior: OccupancyGrid | None = None,
        initial: npt.ArrayLike | None = None,
    ) -> None:
        self.params = params or TrackingParams()
        self.matcher = ScanMatcher(self.params.match)
        self.correction: np.ndarray | None = None
        self._initial = None if initial is None else np.asarray(initial, dtype=np.float64)
        self._mf: MatchField | None = None
        self._prior = prior is not None
        if prior is not None:
            self._mf = self.matcher.field(LikelihoodField.from_grid(prior, self.params.max_distance))
        incremental = prior is None and self.params.field == "incremental"
        self.mapper = ScanMapper(
            MappingParams(resolution=self.params.resolution, max_range=self.params.max_range),
            changes=incremental,
        )
        #: the field of the map built as it goes (``field = "incremental"``, after the first scan)
        self.tracking_field: TrackingField | None = None
        self._last_integrated: np.ndarray | None = None
        self._last_pose: np.ndarray | None = None
        self._last_step: np.ndarray | None = None
        self._last_odom: np.ndarray | None = None
        self._window_centre: np.ndarray | None = None
        self._since_refresh = 0
        self._stall: np.ndarray | None = None  # the correction before the odometry stood still
        self._was_still = False  # the odometry stood still at the last scan
        # corrections that larger ones replaced, for undoing them (oldest first)
        self._alternatives: deque[_Alternative] = deque()
        self._unsure = 0  # scans after a large correction that still count as uncertain
        self.scans = 0

    @property
    def known_map(self) -> bool:
        return self._prior

    def update(
        self,
        ranges: npt.ArrayLike,
        angles: npt.ArrayLike,
        odom: npt.ArrayLike,
        *,
        range_max: float,
        range_min: float = 0.0,
    ) -> TrackStep:
        """Track one scan: ``(n,)`` ranges at ``(n,)`` angles, the laser's odometry pose ``odom``."""
        prm = self.params
        o = np.asarray(odom, dtype=np.float64)
        if self.correction is None:
            start = self._initial if self._initial is not None else o
            self.correction = compose(start, inverse(o))
        before = self.correction.copy()
        predicted = compose(before, o)
        pts = scan_points(
            ranges,
            angles,
            range_max=range_max,
            range_min=range_min,
            max_range=prm.max_range,
            step=prm.beam_step,
        )
        inc = np.zeros(3) if self._last_odom is None else between(self._last_odom, o)
        moved = (math.hypot(inc[0], inc[1]), abs(float(inc[2])))
        still = self._last_odom is not None and moved[0] < STILL[0] and moved[1] < STILL[1]
        self._was_still, was_still = still, self._was_still
        sigma = self._sigma(moved)
        pose, fit, matched, searched = predicted, 0.0, False, False
        event: str | None = None
        # a stall's correction is exempt from the gate (the odometry said nothing); a correction at
        # the odometry's catch-up is not: the catch-up may be right and the scan's fit misleading
        exempt = False
        mf = self._field_for(predicted)
        weights = self._prior_weights(o)
        self._last_odom = o.copy()
        if mf is not None and pts.shape[0] >= 10:
            res = self.matcher.match(mf, pts, mf.field.to_map(predicted), weights=weights)
            stalled = still and self._moving() and self._last_pose is not None and self._last_step is not None
            if prm.fallback == "poor_fit":
                res, _ = self._try_steady(mf, pts, predicted, res)
            elif stalled and res.fit < prm.match.min_fit:
                # the odometry stood still while the robot moved: the tracker's own last motion
                res, took = self._try_steady(mf, pts, predicted, res)
                if took:
                    if self._stall is None:
                        self._stall = before
                    event, exempt = "stall", True
            elif not still and was_still and res.fit < prm.match.min_fit:
                # the odometry moves again after standing still, and its increment spans the
                # stall: the correction from before the stall predicts it (when the tracker
                # moved on meanwhile); or the odometry's catch-up is wrong and the tracker's
                # own motion is right. Never an extrapolation across the jump itself.
                if self._stall is not None:
                    resumed = compose(self._stall, o)
                    alt = self.matcher.match(mf, pts, mf.field.to_map(resumed), search=True, weights=weights)
                    if alt.fit > res.fit:
                        res, event = alt, "resumed"
                res, took = self._try_steady(mf, pts, predicted, res)
                if took:
                    event = "resumed"
            if not still:
                self._stall = None
            fit, searched = res.fit, res.searched
            if fit >= prm.accept_fit:
                pose = mf.field.to_world(res.pose)
                matched = True
        d = between(predicted, pose)
        deviation = (math.hypot(d[0], d[1]), abs(float(d[2])))
        pose, event, uncertain = self._judge(
            pose, o, before, deviation, sigma, exempt, event, mf, pts, weights, matched, fit
        )
        if self._last_pose is not None:
            step = between(self._last_pose, pose)
            # no extrapolation across a jump: a step the odometry cannot explain is not "the motion"
            self._last_step = step if event not in ("correction", "reverted") else inc
        self._last_pose = pose
        self.correction = compose(pose, inverse(o))
        integrated = False
        if not self._prior and self._should_integrate(pose):
            self._integrate((np.asarray(ranges), np.asarray(angles), pose, range_max, range_min))
            integrated = True
        self.scans += 1
        return TrackStep(
            pose,
            self.correction.copy(),
            fit,
            matched,
            searched,
            integrated,
            deviation=(round(deviation[0], 6), round(deviation[1], 6)),
            sigma=(round(sigma[0], 6), round(sigma[1], 6)),
            uncertain=uncertain or (not matched and mf is not None),
            event=event,
        )

    def _integrate(self, scan: tuple[np.ndarray, np.ndarray, np.ndarray, float, float]) -> None:
        ranges, angles, pose, range_max, range_min = scan
        self.mapper.add(ranges, angles, pose, range_max=range_max, range_min=range_min)
        self._last_integrated = pose
        self._since_refresh += 1

    @property
    def undoable(self) -> int:
        """How many replaced corrections could still be taken back."""
        return len(self._alternatives)

    def _moving(self) -> bool:
        """Whether the tracker's last step moved (it had motion to extrapolate)."""
        s = self._last_step
        return s is not None and (math.hypot(s[0], s[1]) >= STILL[0] or abs(float(s[2])) >= STILL[1])

    def _try_steady(
        self, mf: MatchField, pts: np.ndarray, predicted: np.ndarray, res: MatchResult
    ) -> tuple[MatchResult, bool]:
        """The scan matched from the tracker's last motion (search, no prior), if that is far
        from the prediction and fits better; ``(result, whether it was taken)``."""
        prm = self.params
        if res.fit >= prm.match.min_fit or self._last_pose is None or self._last_step is None:
            return res, False
        steady = compose(self._last_pose, self._last_step)
        d = between(steady, predicted)
        if math.hypot(d[0], d[1]) <= prm.match.linear_window and abs(d[2]) <= prm.match.angular_window:
            return res, False
        alt = self.matcher.match(mf, pts, mf.field.to_map(steady), search=True, weights=(0.0, 0.0))
        return (alt, True) if alt.fit > res.fit else (res, False)

    def _sigma(self, moved: tuple[float, float]) -> tuple[float, float]:
        """The odometry noise model's σ ``(metres, radians)`` for an increment ``moved``."""
        prm = self.params
        d, a = moved
        return (
            prm.noise_floor[0] + prm.noise_translation * d,
            prm.noise_floor[1] + prm.noise_rotation * (a + 0.5 * d),
        )

    def _judge(
        self,
        pose: np.ndarray,
        odom: np.ndarray,
        before: np.ndarray,
        deviation: tuple[float, float],
        sigma: tuple[float, float],
        exempt: bool,
        event: str | None,
        mf: MatchField | None,
        pts: np.ndarray,
        weights: tuple[float, float],
        matched: bool,
        fit: float,
    ) -> tuple[np.ndarray, str | None, bool]:
        """Corrections the odometry cannot explain, and undoing them (see the module
        docstring): the pose to take, the event, and whether the pose is uncertain."""
        prm = self.params
        if prm.confirm_scans == 0:
            return pose, event, False
        alts = self._alternatives
        while alts and self.scans - alts[0].since > prm.undo_scans:
            alts.popleft()
        beyond = (
            matched
            and not exempt
            and (deviation[0] > prm.gate * sigma[0] or deviation[1] > prm.gate * sigma[1])
        )
        if beyond:
            # taken, but the correction it replaces is kept: the next scans may contradict it
            alts.append(_Alternative(before.copy(), self.scans))
            while len(alts) > MAX_ALTERNATIVES:
                alts.popleft()
            self._unsure = prm.confirm_scans
            return pose, "correction", True
        uncertain = self._unsure > 0
        self._unsure = max(0, self._unsure - 1)
        if fit >= prm.match.min_fit or mf is None or pts.shape[0] < 10 or not alts:
            for alt in alts:
                alt.votes = 0
            return pose, event, uncertain
        # a poor fit: does a correction this one replaced fit the scan better?
        best: tuple[float, _Alternative, np.ndarray] | None = None
        for alt in alts:
            res = self.matcher.match(mf, pts, mf.field.to_map(compose(alt.correction, odom)), weights=weights)
            if res.fit > fit + PROBATION_MARGIN:
                alt.votes += 1
                if best is None or res.fit > best[0]:
                    best = (res.fit, alt, mf.field.to_world(res.pose))
            else:
                alt.votes = 0
        if best is not None and best[1].votes >= prm.confirm_scans:
            alts.remove(best[1])
            alts.append(_Alternative(compose(pose, inverse(odom)), self.scans))  # undoable in turn
            self._unsure = 0
            return best[2], "reverted", False
        return pose, event, True

    def _prior_weights(self, odom: np.ndarray) -> tuple[float, float]:
        """The prior's (translation, rotation) weights for this scan (see the module docstring)."""
        prm = self.params
        if self._last_odom is None:
            d, a = 0.0, 0.0
        else:
            inc = between(self._last_odom, odom)
            d, a = math.hypot(inc[0], inc[1]), abs(float(inc[2]))
        return prm.prior_translation / (d + 0.01), prm.prior_rotation / (a + 0.01)

    def _should_integrate(self, pose: np.ndarray) -> bool:
        if self._last_integrated is None:
            return True
        d = between(self._last_integrated, pose)
        return bool(
            math.hypot(d[0], d[1]) >= self.params.integrate_distance
            or abs(d[2]) >= self.params.integrate_angle
        )

    def _field_for(self, pose: np.ndarray) -> MatchField | None:
        """The matching field around ``pose`` (None while the map is empty)."""
        if self._prior:
            return self._mf
        if self.mapper.scans == 0:
            return None
        prm = self.params
        stale = (
            self._mf is None
            or self._window_centre is None
            or math.hypot(*(pose[:2] - self._window_centre)) >= prm.refresh_distance
            or self._since_refresh >= prm.refresh_scans
        )
        if stale and prm.field == "incremental":
            if self.tracking_field is None:
                origin = self.mapper.lattice_origin
                if origin is None:  # no beam was integrated yet
                    return None
                self.tracking_field = TrackingField(
                    origin, prm.resolution, prm.max_distance, self.matcher.params.sigmas
                )
            self.tracking_field.update(self.mapper.take_changes())
            self._mf = self.tracking_field.match_field()
            self._window_centre = pose[:2].copy()
            self._since_refresh = 0
        elif stale:
            occ, free, origin = self.mapper.window(
                pose[0] - prm.window, pose[1] - prm.window, pose[0] + prm.window, pose[1] + prm.window
            )
            lf = LikelihoodField(
                distance_field(occ, prm.resolution, prm.max_distance),
                free,
                occ,
                prm.resolution,
                (origin[0], origin[1], 0.0),
                prm.max_distance,
            )
            self._mf = self.matcher.field(lf)
            self._window_centre = pose[:2].copy()
            self._since_refresh = 0
        return self._mf
