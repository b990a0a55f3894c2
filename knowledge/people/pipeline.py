"""One scan in, people out: segmentation → features → classification → pairing → tracking.

:class:`PeoplePipeline` holds the state that spans scans (the previous scan for C.14, the
tracker) so a caller — the agent's follow-me task, a replay, a benchmark — only hands it each
scan with its time and, on a moving robot, the sensor's pose in a fixed frame (odometry), so
people are tracked in that frame rather than in the moving sensor's.

With the sensor's pose it also uses time to tell people from furniture that looks like legs
(docs/people.md, "Tracks on a real benchmark"): a person detected where the laser has hit an
obstacle for ``static.settle`` seconds (:class:`~knowledge.people.static.StaticCells`) may
not start a track, and a new track is only confirmed once ``tracker.confirm_evidence`` of its
detections stood where the laser saw through a moment before
(:class:`~knowledge.people.freespace.SeenThrough`, ``min_seen_through`` scans): someone
walked in. Without a pose (a sensor that does not move) neither rule applies.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
import numpy.typing as npt

from knowledge.people.detector import LegDetector, SegmentDetection
from knowledge.people.freespace import SeenThrough, SeenThroughParams
from knowledge.people.pairing import DEFAULT_MAX_DISTANCE, People, pair_legs
from knowledge.people.segmentation import FloatArray
from knowledge.people.static import StaticCells, StaticParams
from knowledge.people.tracking import PeopleTracker, TrackerConfig, TrackState

SCHEMA = "loci.people/1"
#: Scans further apart than this (seconds) do not feed C.14 (a gap in the data).
MAX_MOTION_GAP = 1.0
#: The tracker of the pipeline: tentative tracks survive two missed scans, and are confirmed
#: after three detections that stood where the laser saw through a moment before, or once they
#: walked 0.2 m; a confirmed track hidden behind something nearer coasts for up to 2 s, and a
#: track confirmed within 1 m of where one vanished less than 5 s before continues it (its id)
#: (docs/results/people_tracks.md has the measurements behind these values; its protocol
#: chooses ``min_travel`` 0.1 m and ``min_score`` 0.4 on the bag, see DEFAULT_MIN_SCORE).
DEFAULT_TRACKER = TrackerConfig(
    tentative_misses=3,
    confirm_evidence=3,
    confirm_travel=0.2,
    max_occluded=2.0,
    revive_radius=1.0,
    revive_for=5.0,
)
#: A person candidate on cells the laser has hit for this long starts no track.
DEFAULT_STATIC = StaticParams(settle=2.0)
#: Scans of the last two seconds that must have seen through a detection for it to be evidence.
DEFAULT_MIN_SEEN_THROUGH = 3
#: The smallest detector output ``F`` of a leg of the people step (None: the detector's threshold).
#: 0.4 is what the benchmark bag's protocol chooses, but not the default: it loses the walker of
#: the follow-me test a second before they leave the laser's sight, and it confirms a stool's
#: legs in the furniture test (docs/people.md, "Tracks on a real benchmark").
DEFAULT_MIN_SCORE: float | None = None


def to_frame(points: FloatArray, pose: tuple[float, float, float] | None) -> FloatArray:
    """``(K, 2)`` sensor-frame points in the frame where the sensor has ``pose`` (x, y, θ)."""
    if pose is None or points.shape[0] == 0:
        return points
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    return np.column_stack([x + c * points[:, 0] - s * points[:, 1], y + s * points[:, 0] + c * points[:, 1]])


@dataclass(frozen=True, eq=False)
class PeopleFrame:
    """What one scan produced.

    Attributes:
        stamp: the scan's time, seconds.
        detection: segments, features, scores and per-beam labels (sensor frame).
        legs: ``(K, 2)`` leg centroids in the tracking frame, metres.
        people: the persons of this scan (positions in the tracking frame).
        tracks: the confirmed tracks after this scan.
    """

    stamp: float
    detection: SegmentDetection
    legs: FloatArray
    people: People
    tracks: list[TrackState]

    def to_json(self, frame_id: str = "laser") -> dict[str, Any]:
        """A JSON-able summary (schema ``loci.people/1``) for publishing."""
        return {
            "schema": SCHEMA,
            "stamp": self.stamp,
            "frame_id": frame_id,
            "legs": [[float(x), float(y)] for x, y in self.legs],
            "people": [
                {"x": float(p[0]), "y": float(p[1]), "legs": int(n)}
                for p, n in zip(self.people.positions, self.people.n_legs, strict=True)
            ],
            "tracks": [
                {
                    "id": t.id,
                    "x": float(t.position[0]),
                    "y": float(t.position[1]),
                    "vx": float(t.velocity[0]),
                    "vy": float(t.velocity[1]),
                    "misses": t.misses,
                    "age": t.age,
                }
                for t in self.tracks
            ],
        }


#: Metres something must stand in front of a tracked person for the person to count as hidden.
OCCLUSION_MARGIN = 0.3
#: Metres to either side of the person whose beams are looked at.
OCCLUSION_HALF_WIDTH = 0.15


def hidden_behind(
    points: FloatArray,
    ranges: FloatArray,
    pose: tuple[float, float, float],
    angle_min: float,
    angle_increment: float,
    range_max: float,
    range_min: float = 0.0,
) -> npt.NDArray[np.bool_]:
    """``(K,)`` bool: a beam of the scan ``ranges`` (taken from ``pose``, tracking frame)
    within :data:`OCCLUSION_HALF_WIDTH` of each point ``(K, 2)`` ended at least
    :data:`OCCLUSION_MARGIN` in front of it: something nearer hides it. Points outside the
    field of view are not hidden (they are out of sight)."""
    q = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
    out = np.zeros(q.shape[0], dtype=np.bool_)
    _hidden(
        q,
        np.ascontiguousarray(ranges, dtype=np.float64),
        float(pose[0]),
        float(pose[1]),
        float(pose[2]),
        float(angle_min),
        float(angle_increment),
        float(range_max),
        float(range_min),
        out,
    )
    return out


@numba.njit(cache=True, nogil=True)
def _hidden(
    q: np.ndarray,
    ranges: np.ndarray,
    x: float,
    y: float,
    th: float,
    angle_min: float,
    inc: float,
    range_max: float,
    range_min: float,
    out: np.ndarray,
) -> None:
    """:func:`hidden_behind` into ``out`` (K,) bool."""
    n = ranges.shape[0]
    for k in range(q.shape[0]):
        dx, dy = q[k, 0] - x, q[k, 1] - y
        d = math.hypot(dx, dy)
        b = math.atan2(dy, dx) - th
        b = math.atan2(math.sin(b), math.cos(b))
        centre = int(np.rint((b - angle_min) / inc))
        if centre < 0 or centre >= n:
            continue
        w = math.ceil(OCCLUSION_HALF_WIDTH / (max(d, 0.05) * inc))
        for i in range(max(0, centre - w), min(n, centre + w + 1)):
            r = ranges[i]
            if math.isfinite(r) and r > 0 and r >= range_min and r < range_max and r < d - OCCLUSION_MARGIN:
                out[k] = True
                break


class PeoplePipeline:
    """Per-scan people detection and tracking (see the module doc).

    Args:
        detector: a fitted :class:`LegDetector` (default: the bundled model).
        pair_distance: largest distance between two legs of one person, metres.
        lone_legs: ``"person"`` or ``"drop"`` (see :mod:`knowledge.people.pairing`).
        tracker: tracker parameters (default :data:`DEFAULT_TRACKER`).
        static: how long an obstacle must have been hit to count as furniture (None: off).
        seen_through: how free-space evidence is taken (see :mod:`knowledge.people.freespace`).
        min_seen_through: a detection is evidence when at least this many recent scans saw
            through it (0: every detection is).
        min_score: a segment is a leg of the people step only when the detector's output
            ``F`` is at least this (and the detector's threshold; None: the threshold alone):
            the frame's ``detection.is_person``, ``legs`` and ``people`` are those.
    """

    def __init__(
        self,
        detector: LegDetector | None = None,
        *,
        pair_distance: float = DEFAULT_MAX_DISTANCE,
        lone_legs: str = "person",
        tracker: TrackerConfig | None = None,
        static: StaticParams | None = DEFAULT_STATIC,
        seen_through: SeenThroughParams | None = None,
        min_seen_through: int = DEFAULT_MIN_SEEN_THROUGH,
        min_score: float | None = DEFAULT_MIN_SCORE,
    ) -> None:
        if min_score is not None and not math.isfinite(min_score):
            raise ValueError(f"min_score must be None or a finite number, got {min_score!r}")
        if int(min_seen_through) != min_seen_through or min_seen_through < 0:
            raise ValueError(f"min_seen_through must be an integer >= 0, got {min_seen_through!r}")
        self.detector = detector if detector is not None else LegDetector.load()
        self.pair_distance = pair_distance
        self.lone_legs = lone_legs
        self.tracker = PeopleTracker(tracker if tracker is not None else DEFAULT_TRACKER)
        self.static = StaticCells(static) if static is not None else None
        self.seen_through = SeenThrough(seen_through)
        self.min_seen_through = int(min_seen_through)
        self.min_score = min_score
        self._previous: tuple[float, npt.NDArray[np.float64]] | None = None
        self._angles: tuple[tuple[int, float, float], FloatArray, FloatArray] | None = None

    def process(
        self,
        ranges: npt.ArrayLike,
        stamp: float,
        *,
        angle_min: float,
        angle_increment: float,
        range_max: float,
        range_min: float = 0.0,
        sensor_pose: tuple[float, float, float] | None = None,
    ) -> PeopleFrame:
        """Detect and track people in one scan ``(B,)`` (metres) taken at ``stamp`` seconds.

        ``range_min``/``range_max``: the sensor's limits in metres; readings outside them are
        no returns (e.g. a Hokuyo's error codes of a few millimetres, below its ``range_min``).

        ``sensor_pose`` ``(x, y, θ)`` is the sensor's pose in the fixed tracking frame at
        ``stamp`` (None: track in the sensor frame, for a sensor that does not move).
        """
        r = np.asarray(ranges, dtype=np.float64)
        prev, dt = None, None
        if self._previous is not None and self.detector.uses_motion:
            t0, r0 = self._previous
            if r0.shape == r.shape and 0 < stamp - t0 <= MAX_MOTION_GAP:
                prev, dt = r0, stamp - t0
        det = self.detector.detect(
            r, angle_min, angle_increment, range_max=range_max, range_min=range_min, previous=prev, dt=dt
        )
        self._previous = (float(stamp), r)
        if self.min_score is not None and self.min_score > self.detector.threshold:
            det = dataclasses.replace(det, is_person=det.is_person & (det.score >= self.min_score))
        legs = to_frame(det.legs, sensor_pose)
        people = pair_legs(legs, max_distance=self.pair_distance, lone_legs=self.lone_legs)
        pos = people.positions
        evidence = births = None
        if sensor_pose is not None:
            if self.static is not None:
                self.static.update(
                    self._endpoints(r, sensor_pose, angle_min, angle_increment, range_max, range_min), stamp
                )
                births = ~self.static.static(pos) if pos.shape[0] else None
            if self.min_seen_through > 0:
                self.seen_through.add(
                    r,
                    float(stamp),
                    sensor_pose,
                    angle_min=angle_min,
                    angle_increment=angle_increment,
                    range_max=range_max,
                    range_min=range_min,
                )
                evidence = self.seen_through.evidence(pos, float(stamp)) >= self.min_seen_through
        occluded = None
        if sensor_pose is not None:
            pose = sensor_pose

            def occluded(points: FloatArray) -> npt.NDArray[np.bool_]:
                return hidden_behind(points, r, pose, angle_min, angle_increment, range_max, range_min)

        tracks = self.tracker.update(pos, float(stamp), evidence=evidence, births=births, occluded=occluded)
        return PeopleFrame(float(stamp), det, legs, people, tracks)

    def _endpoints(
        self,
        r: FloatArray,
        pose: tuple[float, float, float],
        angle_min: float,
        angle_increment: float,
        range_max: float,
        range_min: float,
    ) -> FloatArray:
        """``(k, 2)`` the scan's hits in the tracking frame."""
        key = (r.size, float(angle_min), float(angle_increment))
        if self._angles is None or self._angles[0] != key:
            a = angle_min + np.arange(r.size) * angle_increment
            self._angles = (key, np.cos(a), np.sin(a))
        _, c, s = self._angles
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(r) & (r > 0) & (r >= range_min) & (r < range_max)
        x, y, th = pose
        ct, st = math.cos(th), math.sin(th)
        lx, ly = r[ok] * c[ok], r[ok] * s[ok]
        return np.column_stack([x + ct * lx - st * ly, y + st * lx + ct * ly])

    def process_scan(self, scan: Any, sensor_pose: tuple[float, float, float] | None = None) -> PeopleFrame:
        """:meth:`process` for a :class:`drivers.messages.LaserScan` (duck-typed: ``ranges``,
        ``stamp``, ``angle_min``, ``angle_increment``, ``range_max``; ``range_min`` if it has one)."""
        return self.process(
            scan.ranges,
            float(scan.stamp),
            angle_min=float(scan.angle_min),
            angle_increment=float(scan.angle_increment),
            range_max=float(scan.range_max),
            range_min=float(getattr(scan, "range_min", 0.0)),
            sensor_pose=sensor_pose,
        )
