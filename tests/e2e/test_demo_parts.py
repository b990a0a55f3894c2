"""The pieces of `loci demo` that run in one process: the tutor's messages, the tutor driven
through the simulated robot, the agent's configuration, the children's clean stop."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from agent.config import load_config
from agent.demo import messages
from agent.demo.processes import Children, free_port
from agent.demo.tour_run import TAUGHT, teach_objects, write_agent_config
from agent.demo.tutor_control import TutorControl
from sim.robot import SimRobot, SimRobotConfig
from sim.tour import tour_world


def test_tutor_commands_are_validated() -> None:
    assert messages.walk_cmd("into_room") == {"schema": messages.TUTOR_CMD, "walk": "into_room"}
    assert messages.walk_cmd([(1, 2), (3.5, 4)])["walk"] == [[1.0, 2.0], [3.5, 4.0]]
    assert messages.validate_cmd({"stop": True}) == {"schema": messages.TUTOR_CMD, "stop": True}
    bads: list[dict[str, Any]] = [
        {},
        {"walk": []},
        {"walk": [[1, float("nan")]]},
        {"walk": [[1, 2, 3]]},
        {"schema": "x", "stop": True},
    ]
    for bad in bads:
        with pytest.raises(ValueError):
            messages.validate_cmd(bad)
    with pytest.raises(ValueError):
        messages.decode(b"[1, 2]")
    assert messages.decode(messages.encode({"stop": True})) == {"stop": True}


def test_the_demo_world_starts_at_the_station_and_its_camera_sees_the_tours_objects() -> None:
    tour = tour_world(0)
    robot = SimRobot(SimRobotConfig(world="demo:0", laser="360", camera=True))
    assert robot.tour is not None
    truth = robot.base.true_pose
    assert (truth.x, truth.y, truth.theta) == pytest.approx(tour.start)
    assert {o.name for o in robot.world.objects} == {o.name for o in tour.objects}
    assert robot.building is not None and robot.building.grid.name == tour.grid.name


def test_the_tutor_walks_queued_legs_and_the_laser_sees_it() -> None:
    tour = tour_world(0)
    robot = SimRobot(SimRobotConfig(world="demo:0", laser="360", beams=720, noise=0.0))
    control = TutorControl(tour, wait_distance=50.0, resume_distance=40.0)
    control.attach(robot)
    before = robot.scan_360()
    control.command({"walk": "into_room"})
    control.command({"walk": [[11.0, 4.2]]})
    with pytest.raises(ValueError, match="legs are"):
        control.command({"walk": "nowhere"})
    robot.run_for(1.0)
    assert control.state()["walking"]
    leg = tour.leg("into_room")
    robot.run_for(leg.length / 0.6 + 0.5)
    assert control.walks == 1
    assert control.tutor.walking  # now the waypoints
    robot.run_for(6.0)
    state = control.state()
    assert state["walks"] == 2 and not state["walking"]
    assert math.dist((state["x"], state["y"]), (11.0, 4.2)) < 0.05
    # the legs were in the laser's world while the tutor stood near the robot at the start
    pose = robot.sensor_pose
    d0 = math.dist(tour.tutor_start, pose[:2])
    assert float(before.ranges.min()) < d0 + 0.1
    control.command({"stop": True})
    robot.run_for(0.1)
    assert not control.tutor.walking


def test_a_goal_beside_an_obstacle_is_moved_where_the_base_keeps_clear() -> None:
    tour = tour_world(0)
    robot = SimRobot(SimRobotConfig(world="demo:0", laser="360"))
    gap = tour.false_doorway
    # 0.25 m off the gap's centre line, towards the bucket: the robot's 0.2 m footprint would touch it
    goal = (gap.center[0] + 0.25, gap.center[1])
    assert float(robot.planner.clearance(goal)) < robot.planner.params.clearance
    snapped = robot.planner.nearest_clear(goal)
    assert float(robot.planner.clearance(snapped)) >= robot.planner.params.clearance
    assert math.dist(snapped, goal) < 0.3


def test_the_agent_configuration_loads(tmp_path: Path) -> None:
    lms = tmp_path / "lms"
    path = write_agent_config(tmp_path / "agent.toml", robot="tour", port=7999, lms=lms, folder=tmp_path)
    cfg = load_config(path)
    assert cfg.robot.name == "tour"
    assert cfg.laser.source == "lms" and Path(cfg.laser.port or "") == lms
    assert cfg.conceptual.on
    assert Path(cfg.objects.database) == tmp_path / "objects"
    assert Path(cfg.record.path or "") == tmp_path / "tour.mcap"
    assert cfg.bus.listen == ("tcp/127.0.0.1:7999",)


def test_the_taught_objects_are_recognised_in_their_pictures(tmp_path: Path) -> None:
    from knowledge.objects import ObjectDatabase, ObjectRecogniser
    from sim.objects import object_texture

    tour = tour_world(0)
    names = teach_objects(tmp_path / "objects", tour)
    assert sorted(names) == sorted(TAUGHT)
    rec = ObjectRecogniser(ObjectDatabase.open(tmp_path / "objects"))
    found = rec.recognise(object_texture(tour.object("television")))
    assert [d.name for d in found][:1] == ["television"]


def test_children_are_stopped_even_when_they_ignore_sigint(tmp_path: Path) -> None:
    assert 1024 <= free_port() <= 65535
    with Children(tmp_path) as children:
        child = children.start("sleeper", ["--help"])
        # replace the command by one that ignores SIGINT: the stop must fall back to SIGKILL
        child.proc.wait(10)
        import subprocess

        stubborn = subprocess.Popen(
            [
                sys.executable,
                "-c",
                "import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); time.sleep(60)",
            ],
            start_new_session=True,
        )
        child.proc = stubborn
        t0 = time.monotonic()
        assert child.stop(grace=0.5) is not None
        assert time.monotonic() - t0 < 5.0
    assert stubborn.poll() is not None
    assert "usage: loci" in (tmp_path / "sleeper.log").read_text()


def test_interactive_mode_takes_the_tutors_lines_from_the_console(tmp_path: Path) -> None:
    """``loci demo --interactive``: typed lines reach the agent through the dialogue process and
    the robot's answers are printed; end of input ends the demo cleanly (nothing is checked)."""
    import json
    import subprocess

    out = tmp_path / "tour"
    proc = subprocess.run(
        [sys.executable, "-m", "agent.cli", "demo", "--interactive", "--no-replay", "--out", str(out)],
        input="You are at the charging station.\nWhere are you?\n:quit\n",
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    printed = proc.stdout + proc.stderr  # the conversation goes to stderr, the summary to stdout
    assert "robot: Thank you. This is the charging station." in printed, printed
    assert "DONE (interactive" in proc.stdout
    lines = [json.loads(x) for x in (out / "transcript.jsonl").read_text().splitlines()]
    said = [x["text"] for x in lines if x.get("speaker") == "robot"]
    assert any(t.startswith("I am in ") for t in said), said  # "Where are you?" was answered
    assert (out / "map.png").is_file() and (out / "tour.mcap").is_file()


def test_the_noisy_odometry_tour_turns_tracking_on(tmp_path: Path) -> None:
    lms = tmp_path / "lms"
    plain = load_config(
        write_agent_config(tmp_path / "a.toml", robot="tour", port=7999, lms=lms, folder=tmp_path)
    )
    noisy = load_config(
        write_agent_config(
            tmp_path / "b.toml", robot="tour", port=7999, lms=lms, folder=tmp_path, tracking=True
        )
    )
    assert not plain.localization.tracking and noisy.localization.tracking
