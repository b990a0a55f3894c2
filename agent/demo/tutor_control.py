"""The simulated tutor inside the simulator process, obeying ``loci.tutor_cmd/1`` commands.

:class:`TutorControl` owns a :class:`~sim.tutor.Tutor` in a
:class:`~sim.robot.SimRobot` whose world is the guided tour (``demo:SEED``). Walk
commands queue up: the tutor walks them one after another (a leg by name, or waypoints);
``stop`` drops the queue and the walk under way. Everything runs on the robot's thread
(:meth:`TutorControl.command` only queues), so the tutor and the robot never race.
"""

from __future__ import annotations

import collections
import math
import threading
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from agent.demo.messages import state_message, validate_cmd
from sim.tutor import Tutor

if TYPE_CHECKING:
    from sim.robot import RobotSample, SimRobot
    from sim.tour import TourWorld

__all__ = ["TutorControl"]


class TutorControl:
    """A tutor in the tour's world that walks legs on command.

    Args:
        tour: the world (its legs name the walks).
        speed: the tutor's walking speed, m/s.
        wait_distance, resume_distance: metres; the tutor stops while the robot is farther
            than ``wait_distance`` and walks on once it is within ``resume_distance`` (a guide
            who keeps the robot close, so that it does not lose them at a door).
    """

    def __init__(
        self,
        tour: TourWorld,
        *,
        speed: float = 0.6,
        wait_distance: float = 2.0,
        resume_distance: float = 1.4,
    ) -> None:
        self.tour = tour
        first = tour.legs[0].waypoints
        heading = math.atan2(first[1][1] - first[0][1], first[1][0] - first[0][0]) if len(first) > 1 else 0.0
        self.tutor = Tutor(
            tour.tutor_start,
            heading,
            speed=speed,
            wait_distance=wait_distance,
            resume_distance=resume_distance,
        )
        self._lock = threading.Lock()
        self._queue: collections.deque[list[tuple[float, float]]] = collections.deque()
        self._stop = False
        self.walks = 0  # walks finished
        self._busy = False

    def attach(self, robot: SimRobot) -> None:
        """Put the tutor into the robot's world; it moves with every step of the robot."""
        robot.add_person(self.tutor.legs(), self._on_step)

    def command(self, msg: Mapping[str, Any]) -> None:
        """Obey a ``loci.tutor_cmd/1`` (queued; applied at the robot's next step).

        Raises:
            ValueError: not a valid command, or an unknown leg name (the message names the legs).
        """
        cmd = validate_cmd(msg)
        with self._lock:
            if cmd.get("stop"):
                self._queue.clear()
                self._stop = True
                return
            walk = cmd["walk"]
            if isinstance(walk, str):
                try:
                    points = [tuple(p) for p in self.tour.leg(walk).waypoints]
                except KeyError as exc:
                    raise ValueError(str(exc).strip("'\"")) from None
            else:
                points = [(p[0], p[1]) for p in walk]
            self._queue.append([(float(x), float(y)) for x, y in points])

    def _on_step(self, sample: RobotSample) -> None:
        t = self.tutor
        with self._lock:
            if self._stop:
                self._stop = False
                if self._busy:
                    self.walks += 1
                self._busy = False
                t.stop()
            t.advance(sample.time, (sample.truth.x, sample.truth.y))
            if self._busy and not t.walking:
                self._busy = False
                self.walks += 1
            if not self._busy and self._queue:
                t.walk(self._queue.popleft())
                self._busy = t.walking
                if not self._busy:  # already there
                    self.walks += 1

    def state(self) -> dict[str, Any]:
        """A ``loci.tutor_state/1`` message of the tutor now."""
        t = self.tutor
        with self._lock:
            pending = len(self._queue)
            walks = self.walks
            busy = self._busy
        return state_message(
            t.position,
            t.heading,
            walking=busy or pending > 0,
            waiting=t.waiting,
            remaining=t.remaining,
            walks=walks,
        )
