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

Odometry that stalls and then jumps (the raw CSAIL log has such jumps, up to 1.5 rad between
two scans) would throw the prediction beyond any search window: when the fit from the
odometry's prediction is poor and the motion the tracker saw last points elsewhere, the
scan is also matched (with the search) from there, and the better fit wins.

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
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from knowledge.localization.likelihood import LikelihoodField, distance_field
from knowledge.localization.scan_matching import MatchField, MatchParams, ScanMatcher, scan_points
from knowledge.localization.se2 import between, compose, inverse
from knowledge.localization.tracking_field import TrackingField
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.mapping import MappingParams, ScanMapper

__all__ = ["PoseTracker", "TrackStep", "TrackingParams"]

FIELD_KINDS = ("incremental", "window")


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

    def __post_init__(self) -> None:
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
    """

    pose: np.ndarray
    correction: np.ndarray
    fit: float
    matched: bool
    searched: bool
    integrated: bool


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
        predicted = compose(self.correction, o)
        pts = scan_points(
            ranges,
            angles,
            range_max=range_max,
            range_min=range_min,
            max_range=prm.max_range,
            step=prm.beam_step,
        )
        pose, fit, matched, searched = predicted, 0.0, False, False
        mf = self._field_for(predicted)
        weights = self._prior_weights(o)
        self._last_odom = o.copy()
        if mf is not None and pts.shape[0] >= 10:
            res = self.matcher.match(mf, pts, mf.field.to_map(predicted), weights=weights)
            # odometry that stalled and then jumped (a turn of 1.5 rad between two scans on
            # the CSAIL log) gives a prediction no search window reaches: when the fit is
            # poor, the motion the tracker saw last is tried as well
            if res.fit < prm.match.min_fit and self._last_pose is not None and self._last_step is not None:
                steady = compose(self._last_pose, self._last_step)
                d = between(steady, predicted)
                if math.hypot(d[0], d[1]) > prm.match.linear_window or abs(d[2]) > prm.match.angular_window:
                    alt = self.matcher.match(
                        mf, pts, mf.field.to_map(steady), search=True, weights=(0.0, 0.0)
                    )
                    if alt.fit > res.fit:
                        res = alt
            fit, searched = res.fit, res.searched
            if fit >= prm.accept_fit:
                pose = mf.field.to_world(res.pose)
                matched = True
        if self._last_pose is not None:
            self._last_step = between(self._last_pose, pose)
        self._last_pose = pose
        self.correction = compose(pose, inverse(o))
        integrated = False
        if not self._prior and self._should_integrate(pose):
            self.mapper.add(
                np.asarray(ranges), np.asarray(angles), pose, range_max=range_max, range_min=range_min
            )
            self._last_integrated = pose
            self._since_refresh += 1
            integrated = True
        self.scans += 1
        return TrackStep(pose, self.correction.copy(), fit, matched, searched, integrated)

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
