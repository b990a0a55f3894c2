"""Follow me (issue 7, after book chapter 8's people detector): which person, and where to drive.

Pure logic: no bus, no asyncio, no clock of its own. The agent feeds :meth:`FollowMe.update`
every scan's confirmed people tracks (a :class:`~knowledge.people.pipeline.PeopleFrame` or its
``tracks``) with the robot's pose in the **same fixed frame** as the tracks (the odometry
frame when the pipeline is given the laser's odometry pose) and the scan's stamp, and
publishes the goal it gets back.

Behaviour:

* :meth:`FollowMe.start` begins **searching**: the target is the confirmed track seen in this
  scan (``misses == 0``) nearest to the robot among those within ``cone`` radians of its
  heading and ``max_range`` metres. Nobody there for ``search_for`` seconds → **lost**.
* **following**: the target is kept by its track id; another person passing by, even
  nearer, does not take over. The goal is the point ``distance`` metres short of the
  person on the line robot → person, heading towards the person (when the robot is
  already nearer than ``distance``: its own position, turning to face the person). A
  goal is only handed out when it differs from the last one (from the robot's pose before
  the first) by more than ``tolerance`` metres or ``heading_tolerance`` radians, so the
  base is not re-planned for every centimetre of tracker noise.
* When the target's track disappears (the tracker deleted it, e.g. after an occlusion:
  the person turned round a door jamb), the robot drives to where it last saw them, up to
  ``chase_short`` metres short of that point (once per disappearance), so that it looks
  round the corner; a new confirmed track seen within ``reacquire_radius`` metres of the
  target's constant-velocity prediction (extrapolated at most ``max_prediction`` seconds),
  plus ``search_speed`` metres per second since the target was last seen, takes over as the
  target — the same person under a new id. So may an older track that, the last time the
  target was seen, was within ``sibling_radius`` metres of it (seen or coasting): the same
  person tracked twice (the legs of a tutor
  standing with feet apart tracked apart, the target's track dying while the other lives
  on; in the noisy-odometry tour this made the robot stand 1 m from its tutor and say "I
  lost you"). A track seen at the same time further from the target — another person —
  still cannot take over. While the target's own track coasts (not seen, the tracker
  still predicting it) for more than ``coast_takeover`` seconds, a track that may take over
  does so: the robot follows the person it sees, not a prediction drifting through the
  walls.
* When the target has not been seen for ``lost_after`` seconds → **lost**: no goal,
  ``cancel`` once (the base should stop) and the message ``"I lost you."`` once. Lost is
  final until :meth:`FollowMe.start` is called again. A target whose track vanished and
  that the robot is driving after (the chase above) gets ``chase_for`` seconds more: the
  robot needs them to reach the corner the person turned round and look.
* :meth:`FollowMe.stop` → **idle** (nothing to do; stopping the base is the caller's job).

Units: metres, radians, seconds (``stamp`` on the tracks' clock).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from knowledge.people.pipeline import PeopleFrame
from knowledge.people.tracking import TrackState

Pose = tuple[float, float, float]

#: States of :class:`FollowStep`.
STATES = ("idle", "searching", "following", "lost")
LOST_MESSAGE = "I lost you."
NOBODY_MESSAGE = "I cannot see anyone in front of me."


@dataclass(frozen=True)
class FollowParams:
    """Parameters of :class:`FollowMe` (see the module doc).

    Attributes:
        distance: metres to keep between the goal and the person (> 0).
        lost_after: seconds without seeing the target before giving up (> 0).
        cone: half-angle in radians around the robot's heading where a target is picked (0, π].
        max_range: metres: farthest person picked at the start (> 0).
        tolerance: metres a new goal must differ from the last one by (>= 0).
        heading_tolerance: radians a new goal's heading must differ by (>= 0).
        reacquire_radius: metres around the target's predicted position where a new track
            is taken for the same person (> 0).
        max_prediction: seconds: the prediction of a vanished target stops moving after this (>= 0).
        search_for: seconds of searching without a target before giving up (> 0).
        chase_short: metres short of the vanished target's last position to drive to (>= 0).
        search_speed: m/s: how fast the reacquisition radius grows while the target is
            unseen (>= 0; a walking person who turned a corner is that far by now).
        chase_for: seconds added to ``lost_after`` while the robot drives after a vanished
            target (>= 0).
        max_search_radius: metres; the reacquisition radius grows no further (> 0).
        sibling_radius: metres; a track this near the target when it was last seen may take
            over although it is older (>= 0; 0: only tracks born since).
        coast_takeover: seconds the target's track may coast (not seen) before a track that
            may be the same person takes over (>= 0).
    """

    distance: float = 1.0
    lost_after: float = 2.0
    cone: float = math.radians(60.0)
    max_range: float = 3.0
    tolerance: float = 0.15
    heading_tolerance: float = math.radians(25.0)
    reacquire_radius: float = 0.8
    max_prediction: float = 1.0
    search_for: float = 5.0
    chase_short: float = 0.5
    search_speed: float = 0.6
    chase_for: float = 4.0
    max_search_radius: float = 2.5
    sibling_radius: float = 1.5
    coast_takeover: float = 0.5

    def __post_init__(self) -> None:
        for name in (
            "distance",
            "lost_after",
            "max_range",
            "reacquire_radius",
            "search_for",
            "max_search_radius",
        ):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"FollowParams.{name} must be a positive number, got {v!r}")
        for name in (
            "tolerance",
            "heading_tolerance",
            "max_prediction",
            "chase_short",
            "search_speed",
            "chase_for",
            "sibling_radius",
            "coast_takeover",
        ):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"FollowParams.{name} must be a number >= 0, got {v!r}")
        if not (isinstance(self.cone, int | float) and 0 < self.cone <= math.pi):
            raise ValueError(
                f"FollowParams.cone is a half-angle in radians in (0, π], got {self.cone!r} "
                "(e.g. math.radians(60))"
            )


@dataclass(frozen=True)
class FollowStep:
    """What :meth:`FollowMe.update` decided for one scan.

    Attributes:
        goal: ``(x, y, θ)`` to send to the base now (the tracks' frame), or None: keep the
            current goal (or, when lost or idle, there is none).
        state: one of :data:`STATES`.
        target_track: the followed track's id, or None.
        message: a sentence to say now (once per event), or None.
        cancel: True once, when the target is lost: stop the base.
    """

    goal: Pose | None
    state: str
    target_track: int | None
    message: str | None = None
    cancel: bool = False


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def goal_behind(person: tuple[float, float], robot: Pose, distance: float) -> Pose:
    """The pose ``distance`` metres short of ``person`` on the line from ``robot``, facing the person.

    When the robot is already nearer than ``distance`` it is the robot's own position
    (turning to face the person; on top of the person: its own heading).
    """
    dx, dy = person[0] - robot[0], person[1] - robot[1]
    n = math.hypot(dx, dy)
    if n < 1e-9:
        return (robot[0], robot[1], robot[2])
    heading = math.atan2(dy, dx)
    if n <= distance:
        return (robot[0], robot[1], heading)
    k = (n - distance) / n
    return (robot[0] + k * dx, robot[1] + k * dy, heading)


class FollowMe:
    """The follow-me decision logic (see the module doc); one instance per robot."""

    def __init__(self, params: FollowParams | None = None) -> None:
        self.params = params or FollowParams()
        self._state = "idle"
        self._target: int | None = None
        self._started = 0.0
        self._last_seen = 0.0
        self._last_pos = np.zeros(2)
        self._last_vel = np.zeros(2)
        self._goal: Pose | None = None
        self._stamp: float | None = None
        self._chased = False  # drove to the vanished target's last position already
        self._siblings: frozenset[int] = frozenset()  # tracks near the target when last seen

    @property
    def active(self) -> bool:
        """True while searching for or following someone."""
        return self._state in ("searching", "following")

    @property
    def state(self) -> str:
        return self._state

    @property
    def target(self) -> int | None:
        """The followed track's id (None while searching, idle or lost)."""
        return self._target

    @property
    def goal(self) -> Pose | None:
        """The last goal handed out (None before the first, and after lost or stop)."""
        return self._goal

    def start(self, stamp: float) -> None:
        """Begin following: search for the nearest person in front from ``stamp`` seconds on."""
        if not math.isfinite(stamp):
            raise ValueError(f"stamp must be a finite time in seconds, got {stamp!r}")
        self._state = "searching"
        self._target = None
        self._goal = None
        self._siblings = frozenset()
        self._started = float(stamp)
        self._stamp = None

    def stop(self) -> None:
        """Stop following (state idle)."""
        self._state = "idle"
        self._target = None
        self._goal = None

    def update(
        self,
        people: PeopleFrame | Sequence[TrackState],
        robot_pose: tuple[float, float, float],
        stamp: float,
    ) -> FollowStep:
        """One scan: the confirmed ``people`` tracks, the robot's pose ``(x, y, θ)`` in their frame, the time."""
        tracks = list(people.tracks if isinstance(people, PeopleFrame) else people)
        pose = (float(robot_pose[0]), float(robot_pose[1]), float(robot_pose[2]))
        if not all(math.isfinite(v) for v in (*pose, stamp)):
            raise ValueError(f"robot_pose and stamp must be finite, got {robot_pose!r} at {stamp!r}")
        if self._stamp is not None and stamp < self._stamp:
            raise ValueError(f"time went backwards: update at {stamp} after {self._stamp}")
        if not self.active:
            return FollowStep(None, self._state, None)
        self._stamp = float(stamp)
        if self._state == "searching":
            track = self._pick(tracks, pose)
            if track is None:
                if stamp - self._started >= self.params.search_for:
                    return self._lose(NOBODY_MESSAGE)
                return FollowStep(None, "searching", None)
            self._state = "following"
            self._target = track.id
        else:
            track = self._find_target(tracks, stamp)
        if track is not None and track.misses == 0:
            self._last_seen = float(stamp)
            # tracks that may become the target although older: those beside it now
            r = self.params.sibling_radius
            here = np.asarray(track.position, dtype=np.float64)
            self._siblings = frozenset(
                t.id
                for t in tracks
                if t.id != track.id
                and float(np.hypot(*(np.asarray(t.position, dtype=np.float64) - here))) <= r
            )
        chase: Pose | None = None
        if track is None and not self._chased:  # vanished, maybe round a corner: go and look
            self._chased = True
            last = (float(self._last_pos[0]), float(self._last_pos[1]))
            chase = goal_behind(last, pose, self.params.chase_short)
        patience = self.params.lost_after + (self.params.chase_for if track is None else 0.0)
        if stamp - self._last_seen >= patience:
            return self._lose(LOST_MESSAGE)
        if track is None:
            if chase is not None:
                self._goal = chase
            return FollowStep(chase, "following", self._target)
        self._chased = False
        if track.misses == 0:  # where the person was seen, not where a coasting track drifts
            self._last_pos = np.asarray(track.position, dtype=np.float64).copy()
            self._last_vel = np.asarray(track.velocity, dtype=np.float64).copy()
        goal = goal_behind((float(track.position[0]), float(track.position[1])), pose, self.params.distance)
        ref = self._goal if self._goal is not None else pose
        if (
            math.hypot(goal[0] - ref[0], goal[1] - ref[1]) <= self.params.tolerance
            and abs(_wrap(goal[2] - ref[2])) <= self.params.heading_tolerance
        ):
            return FollowStep(None, "following", self._target)
        self._goal = goal
        return FollowStep(goal, "following", self._target)

    # ------------------------------------------------------------------ internals
    def _pick(self, tracks: list[TrackState], pose: Pose) -> TrackState | None:
        """The track seen now nearest to the robot within the cone and the range."""
        best: TrackState | None = None
        best_d = math.inf
        for t in tracks:
            if t.misses > 0:
                continue
            dx, dy = float(t.position[0]) - pose[0], float(t.position[1]) - pose[1]
            d = math.hypot(dx, dy)
            if d > self.params.max_range or d >= best_d:
                continue
            if d > 1e-9 and abs(_wrap(math.atan2(dy, dx) - pose[2])) > self.params.cone:
                continue
            best, best_d = t, d
        return best

    def _find_target(self, tracks: list[TrackState], stamp: float) -> TrackState | None:
        """The target's track, or a new track near where the vanished target should be."""
        coasting: TrackState | None = None
        for t in tracks:
            if t.id == self._target:
                if t.misses == 0:
                    return t
                coasting = t  # the tracker still predicts it: someone seen near there may win
        if coasting is not None and stamp - self._last_seen < self.params.coast_takeover:
            return coasting  # a short occlusion: keep the target
        dt = min(max(0.0, stamp - self._last_seen), self.params.max_prediction)
        predicted = self._last_pos + dt * self._last_vel
        best: TrackState | None = None
        unseen = max(0.0, stamp - self._last_seen)
        best_d = min(
            self.params.reacquire_radius + self.params.search_speed * unseen, self.params.max_search_radius
        )
        for t in tracks:
            if t.id == self._target or t.misses > 0:
                continue
            if t.first_seen < self._last_seen and t.id not in self._siblings:
                continue  # only tracks born after the target was last seen, or beside it then, can be it
            d = float(np.hypot(*(np.asarray(t.position, dtype=np.float64) - predicted)))
            if d <= best_d:
                best, best_d = t, d
        if best is not None:
            self._target = best.id
            return best
        return coasting

    def _lose(self, message: str) -> FollowStep:
        self._state = "lost"
        target = self._target
        self._target = None
        self._goal = None
        return FollowStep(None, "lost", target, message, cancel=True)
