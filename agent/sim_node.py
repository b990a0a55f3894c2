"""The simulated robot on the bus: what ``loci sim robot`` runs.

:func:`run_robot` puts a :class:`sim.robot.SimRobot` (base, virtual LMS on a pty or scans on
the bus, camera) on Zenoh as a real robot's drivers would be: odometry on ``odom``, scans on
``scan`` (for a 360° laser), camera frames on ``camera``, the base's status on
``base/status``; it obeys ``base/cmd`` and ``base/goal``. The simulator's ground truth goes on
``sim/truth`` (``loci.truth/1``), and with the guided tour's tutor its state on
``sim/tutor/state``, for evaluation only. The simulation itself (:mod:`sim`) knows no bus.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import signal
import sys
import uuid
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import zenoh

    from agent.bus.bridge import Publisher
    from sim.robot import Goal, RobotSample, SimRobot, StatusReport

log = logging.getLogger(__name__)


async def run_robot(robot: SimRobot, name: str, bus: Any, duration: float | None, tutor: Any = None) -> int:
    from agent.bus.bridge import BusClosed, subscribe_stream
    from agent.bus.ready import declare_ready
    from agent.bus.session import bus_session

    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        with bus_session(bus) as session:
            node = RobotNode(session, name, robot)
            cmds = subscribe_stream(session, name, "base/cmd")
            goals = subscribe_stream(session, name, "base/goal")

            async def obey_commands() -> None:
                with contextlib.suppress(BusClosed):
                    while True:
                        msg = await cmds.recv()
                        robot.command_velocity(float(msg["v"]), float(msg["omega"]))

            async def obey_goals() -> None:
                with contextlib.suppress(BusClosed):
                    while True:
                        msg = await goals.recv()
                        if msg.get("cancel"):
                            robot.cancel()
                        else:
                            robot.send_goal(goal_from_message(msg))

            tasks = [asyncio.create_task(obey_commands()), asyncio.create_task(obey_goals())]
            if tutor is not None:
                tasks.append(asyncio.create_task(_serve_tutor(session, name, tutor)))
            try:
                path = robot.start()
                ready = declare_ready(session, name, "sim")  # the base runs, the laser streams
                print(path if path is not None else "-", flush=True)
                print(name, flush=True)
                c = robot.config
                where = robot.base.true_pose
                print(
                    f"simulated robot {name!r} in {robot.grid.name}: "
                    f"{'LMS on ' + str(path) if path else '360° laser on loci/' + name + '/scan'}, "
                    f"start ({where.x:.2f}, {where.y:.2f}, {math.degrees(where.theta):.0f}°), "
                    f"{'tour of ' + str(len(robot.route.visits)) + ' rooms, ' if c.tour and robot.route else ''}"
                    f"{'route of ' + format(robot.route.length, '.1f') + ' m, ' if robot.route else ''}"
                    f"speed x{c.speed:g}; bus connect {', '.join(bus.connect)}; Ctrl-C to stop",
                    file=sys.stderr,
                    flush=True,
                )
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), duration)
            finally:
                with contextlib.suppress(Exception):
                    ready.undeclare()
                robot.stop()
                cmds.close()
                goals.close()
                for t in tasks:
                    t.cancel()
                await asyncio.gather(*tasks, return_exceptions=True)
                node.close()
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
    st = robot.state()
    print(
        f"simulated robot stopped after {st['time']:.1f} simulated s: {st['distance']:.1f} m driven, "
        f"{st['collisions']} collisions, {st['lms'] or 0} LMS scans sent",
        file=sys.stderr,
    )
    return 0


async def _serve_tutor(session: zenoh.Session, name: str, tutor: Any, period: float = 0.2) -> None:
    """Obey ``loci/<r>/sim/tutor`` commands and publish the tutor's state every ``period`` s."""
    import zenoh

    from agent.demo import messages

    def on_cmd(sample: zenoh.Sample) -> None:
        try:
            tutor.command(messages.decode(sample.payload.to_bytes()))
        except ValueError as exc:
            log.warning("sim/tutor: ignored a command: %s", exc)

    sub = session.declare_subscriber(messages.tutor_cmd_key(name), on_cmd)
    pub = session.declare_publisher(
        messages.tutor_state_key(name), encoding=zenoh.Encoding(messages.ENCODING)
    )
    try:
        while True:
            pub.put(messages.encode(tutor.state()))
            await asyncio.sleep(period)
    finally:
        with contextlib.suppress(zenoh.ZError):
            sub.undeclare()
            pub.undeclare()


def goal_from_message(msg: dict[str, Any]) -> Goal:
    """A ``loci.base_goal/1`` message (validated) as a :class:`~sim.robot.Goal`."""
    from sim.robot import Goal

    points = [msg["goal"]] if msg.get("goal") is not None else list(msg["path"])
    heading = points[-1].get("theta")
    return Goal(
        id=str(msg.get("id") or f"goal-{uuid.uuid4().hex[:12]}"),
        points=tuple((float(p["x"]), float(p["y"])) for p in points),
        heading=None if heading is None else float(heading),
        frame_id=str(msg.get("frame_id", "odom")),
        plan=bool(msg.get("plan", True)),
    )


class RobotNode:
    """Publishes what a :class:`~sim.robot.SimRobot` produces (called on its threads)."""

    def __init__(self, session: zenoh.Session, name: str, robot: SimRobot) -> None:
        from agent.bus.bridge import publish_stream

        self.odom: Publisher[Any] = publish_stream(session, name, "odom")
        self.truth: Publisher[Any] = publish_stream(session, name, "sim/truth")
        self.status: Publisher[Any] = publish_stream(session, name, "base/status")
        self.pubs = [self.odom, self.truth, self.status]
        robot.sample_listeners.append(self.on_sample)
        robot.status_listeners.append(self.on_status)
        if robot.config.laser == "360":
            self.scan = publish_stream(session, name, "scan")
            self.pubs.append(self.scan)
            robot.scan_listeners.append(self.scan.put)
        if robot.camera is not None:
            self.camera = publish_stream(session, name, "camera")
            self.pubs.append(self.camera)
            robot.frame_listeners.append(self.camera.put)

    def on_sample(self, s: RobotSample) -> None:
        self.odom.put(s.odom)
        self.truth.put(truth_message(s))

    def on_status(self, r: StatusReport) -> None:
        self.status.put(status_message(r))

    def close(self) -> None:
        for p in self.pubs:
            p.close()


def truth_message(s: RobotSample) -> dict[str, Any]:
    """A ``loci.truth/1`` message of one simulation step."""
    t, o = s.truth, s.odom
    return {
        "schema": "loci.truth/1",
        "stamp": s.stamp,
        "x": t.x,
        "y": t.y,
        "theta": t.theta,
        "frame_id": t.frame_id,
        "odom": {"x": o.x, "y": o.y, "theta": o.theta},
        "space": s.space,
        "label": s.label,
        "collisions": s.collisions,
    }


def status_message(r: StatusReport) -> dict[str, Any]:
    """A ``loci.base_status/1`` message of a status report."""
    return {
        "schema": "loci.base_status/1",
        "stamp": r.stamp,
        "status": r.status,
        "goal": r.goal,
        "reason": r.reason,
        "pose": {"x": r.odom.x, "y": r.odom.y, "theta": r.odom.theta},
        "distance": r.distance,
    }
