"""The tutor of the guided tour: a simulated person who walks on command, and the lines it says.

:class:`Tutor` is a person with two legs and the gait of :class:`~sim.people.SimPerson`
(what a laser at knee height sees: two circles of about 6 cm radius). It stands until told
to :meth:`Tutor.walk` a list of waypoints, walks them at ``speed`` (0.6 m/s by default, a
slow guiding pace), then stops and stands, facing the way it walked. A tutor who looks back
waits for the robot: while the robot is farther than ``wait_distance`` metres it stands
(legs together) and walks on once the robot is within ``resume_distance``.

The tutor moves when :meth:`Tutor.advance` is called with the simulation time (seconds) and
the robot's position; :meth:`Tutor.attach` does that on every step of a
:class:`~sim.robot.SimRobot` and puts the tutor's legs into the robot's lasers (the
360° scans and the LMS on the pseudo-terminal). The legs are where the tutor is after the
last :meth:`advance`; the time the laser asks for is not used.

:data:`SCRIPT` is the story of the book's Sect. 7.4 as data: per step what the tutor says,
the intent the dialogue should understand, words the robot's reply must contain, the robot's
question the tutor answers, and the legs of :class:`~sim.tour.TourWorld` the tutor
walks afterwards. The demo plays it; tests check the replies against ``expect``.

Units: metres, radians, seconds; positions in the map frame of the world the tutor is in.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from sim.lms_world import Leg
from sim.people import Gait, SimPerson

if TYPE_CHECKING:
    from sim.robot import RobotSample, SimRobot

__all__ = ["SCRIPT", "ScriptLine", "Tutor", "script_step"]

Point = tuple[float, float]


# ------------------------------------------------------------------------------ the script
@dataclass(frozen=True)
class ScriptLine:
    """One thing the tutor says in the tour.

    Attributes:
        step: the story step's name (unique in :data:`SCRIPT`).
        book_step: the step's number in the book's story (BOOK.md, Sect. 7.4: 1–7).
        text: what the tutor says.
        intent: the ``loci.intent/1`` kind the dialogue should understand from it.
        expect: words (lower case) the robot's reply must contain; empty: any reply.
        answers: words of the robot's question (``loci.ask/1`` text, lower case) the tutor
            waits for before saying this line; empty: the tutor does not wait for a question.
        walk: names of the tour legs the tutor walks after saying this line, in order.
        reached: the robot's task should end with ``reached`` (a go-to).
    """

    step: str
    book_step: int
    text: str
    intent: str
    expect: tuple[str, ...] = ()
    answers: tuple[str, ...] = ()
    walk: tuple[str, ...] = ()
    reached: bool = False

    def reply_ok(self, reply: str) -> bool:
        """Whether a reply's text contains every expected word (case-insensitive)."""
        low = reply.lower()
        return all(w in low for w in self.expect)


#: The guided tour (the book's Sect. 7.4), in order.
SCRIPT: tuple[ScriptLine, ...] = (
    ScriptLine("station", 1, "You are at the charging station.", "assert_object"),
    ScriptLine("follow", 2, "Follow me.", "follow_me", walk=("into_room", "false_doorway")),
    ScriptLine("no_door", 3, "No.", "answer", answers=("door",), walk=("to_view",)),
    ScriptLine("stop", 3, "Stop.", "stop"),
    ScriptLine("where", 4, "Where are you?", "ask_place", expect=("room",)),
    ScriptLine("look", 5, "Look around.", "look_around", expect=("couch", "television")),
    ScriptLine("where_again", 5, "Where are you?", "ask_place", expect=("living room",)),
    ScriptLine("go_tv", 6, "Go to the television.", "go_to", expect=("television",), reached=True),
    ScriptLine(
        "go_station", 7, "Go to the charging station.", "go_to", expect=("charging station",), reached=True
    ),
)


def script_step(step: str) -> ScriptLine:
    """The line of :data:`SCRIPT` called ``step`` (KeyError naming the steps)."""
    for line in SCRIPT:
        if line.step == step:
            return line
    raise KeyError(f"no script step {step!r}; the steps are {[s.step for s in SCRIPT]}")


# ------------------------------------------------------------------------------- the person
class Tutor:
    """A person who walks waypoints on command (see the module docstring).

    Args:
        position: where the tutor stands, ``(x, y)`` metres.
        heading: the way it faces, radians.
        speed: walking speed, m/s.
        gait: the legs' gait (default :class:`~sim.people.Gait`).
        wait_distance: metres; the tutor stops while the robot is farther away than this
            (None: it never waits).
        resume_distance: metres; a waiting tutor walks on once the robot is this near.
        come_back_after: seconds; a tutor who has waited this long for a robot that does not
            come (it lost sight of the tutor round a corner) walks back along its way until
            the robot is within ``resume_distance``, then on again (None: it only waits).
    """

    def __init__(
        self,
        position: Point,
        heading: float = 0.0,
        *,
        speed: float = 0.6,
        gait: Gait | None = None,
        wait_distance: float | None = 2.5,
        resume_distance: float = 1.6,
        come_back_after: float | None = 2.5,
    ) -> None:
        x, y = float(position[0]), float(position[1])
        if not all(math.isfinite(v) for v in (x, y, heading)):
            raise ValueError(f"the tutor needs a finite position and heading, got {position!r}, {heading!r}")
        if not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"speed must be a positive number of m/s, got {speed!r}")
        if wait_distance is not None and not (
            math.isfinite(wait_distance) and 0 < resume_distance <= wait_distance
        ):
            raise ValueError(
                "need 0 < resume_distance <= wait_distance (metres), "
                f"got resume_distance={resume_distance!r}, wait_distance={wait_distance!r}"
            )
        self.speed = float(speed)
        self.gait = gait or Gait()
        self.wait_distance = wait_distance
        self.resume_distance = float(resume_distance)
        if come_back_after is not None and not (math.isfinite(come_back_after) and come_back_after >= 0):
            raise ValueError(f"come_back_after must be None or seconds >= 0, got {come_back_after!r}")
        self.come_back_after = come_back_after
        self._waited = 0.0  # seconds waited for the robot so far
        self._returning = False  # walking back to the robot
        self._lock = threading.Lock()
        self._xy = (x, y)
        self._heading = float(heading)
        self._person: SimPerson | None = None
        self._arc = 0.0  # metres walked along the current walk
        self._walked = 0.0  # metres walked in all (the gait's phase)
        self._time: float | None = None
        self._waiting = False

    # ------------------------------------------------------------------ state
    @property
    def position(self) -> Point:
        """Where the tutor's body is, ``(x, y)`` metres."""
        with self._lock:
            return self._xy

    @property
    def heading(self) -> float:
        """The way the tutor faces, radians."""
        with self._lock:
            return self._heading

    @property
    def walking(self) -> bool:
        """Whether the tutor has a walk to finish (also while it waits for the robot)."""
        with self._lock:
            return self._person is not None

    @property
    def waiting(self) -> bool:
        """Whether the tutor stands mid-walk, waiting for the robot to come nearer."""
        with self._lock:
            return self._waiting

    @property
    def remaining(self) -> float:
        """Metres left of the current walk (0 when standing)."""
        with self._lock:
            return 0.0 if self._person is None else self._person.length - self._arc

    # ------------------------------------------------------------------ commands
    def walk(self, waypoints: Sequence[Point] | np.ndarray) -> None:
        """Walk from where the tutor is through ``waypoints`` ``(k, 2)``, then stop.

        A first waypoint within 5 cm of the tutor's position is its start. Replaces a walk
        not finished yet.

        Raises:
            ValueError: no waypoint, or not finite.
        """
        W = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
        if W.shape[0] == 0 or not np.isfinite(W).all():
            raise ValueError("the tutor needs at least one finite (x, y) waypoint in metres")
        with self._lock:
            here = np.asarray(self._xy)
            if float(np.hypot(*(W[0] - here))) <= 0.05:
                W = W[1:]
            path = np.vstack([here[None, :], W])
            seg = np.hypot(*np.diff(path, axis=0).T)
            path = path[np.concatenate([[True], seg > 1e-9])]
            if path.shape[0] < 2:
                self._person = None
                return
            phase = (self._walked / self.gait.stride + 0.5) % 1.0
            self._person = SimPerson(path, self.speed, mode="stop", gait=self.gait, phase=phase)
            self._arc = 0.0
            self._waiting = self._returning = False
            self._waited = 0.0

    def stop(self) -> None:
        """Stand where the tutor is now (the walk is dropped)."""
        with self._lock:
            self._person = None
            self._waiting = self._returning = False
            self._waited = 0.0

    def advance(self, t: float, robot_xy: Point | None = None) -> None:
        """Move on to simulation time ``t`` seconds (the first call only sets the clock).

        ``robot_xy``: where the robot is; the tutor waits for it (see the class docstring).
        """
        with self._lock:
            dt = 0.0 if self._time is None else max(0.0, float(t) - self._time)
            self._time = float(t)
            person = self._person
            if person is None:
                return
            if robot_xy is not None and self.wait_distance is not None:
                gap = math.hypot(robot_xy[0] - self._xy[0], robot_xy[1] - self._xy[1])
                if gap > self.wait_distance and not self._returning:
                    self._waiting = True
                elif gap <= self.resume_distance:
                    self._waiting = self._returning = False
                    self._waited = 0.0
            if self._waiting:
                self._waited += dt
                if self.come_back_after is None or self._waited < self.come_back_after or self._arc <= 0.0:
                    return
                self._waiting, self._returning = False, True
            if self._returning:  # back along the way walked, towards the robot left behind
                self._arc = max(0.0, self._arc - self.speed * dt)
                x, y, _h = person.body(self._arc / self.speed)
                self._xy = (x, y)
                if robot_xy is not None:
                    self._heading = math.atan2(robot_xy[1] - y, robot_xy[0] - x)
                if self._arc <= 0.0:  # back at the walk's start: wait there
                    self._returning, self._waiting = False, True
                return
            step = min(self.speed * dt, person.length - self._arc)
            self._arc += step
            self._walked += step
            x, y, h = person.body(self._arc / self.speed)
            self._xy, self._heading = (x, y), h
            if self._arc >= person.length - 1e-9:
                self._person = None

    # ------------------------------------------------------------------ legs
    def leg_positions(self) -> np.ndarray:
        """``(2, 2)`` world centres of the two leg circles in the scan plane, metres."""
        with self._lock:
            person = self._person
            if person is not None and not self._waiting:
                return person.leg_positions(self._arc / self.speed)
            x, y = self._xy
            h = self._heading
            half = self.gait.stance_width / 2
            nx, ny = -math.sin(h), math.cos(h)
            return np.array([[x + half * nx, y + half * ny], [x - half * nx, y - half * ny]])

    def legs(self) -> tuple[Leg, Leg]:
        """The two legs as :class:`~sim.lms_world.Leg` circles (positions: now)."""

        def leg(k: int) -> Leg:
            def pos(_t: float) -> Point:
                p = self.leg_positions()[k]
                return (float(p[0]), float(p[1]))

            return Leg(pos, self.gait.leg_radius)

        return leg(0), leg(1)

    def attach(self, robot: SimRobot) -> None:
        """Put the tutor into a simulated robot's world: its lasers see the legs, and every
        step of the robot advances the tutor (with the robot's true position)."""

        def on_step(sample: RobotSample) -> None:
            self.advance(sample.time, (sample.truth.x, sample.truth.y))

        robot.add_person(self.legs(), on_step)
