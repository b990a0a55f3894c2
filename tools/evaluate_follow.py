"""Follow-me on the guided tour in the simulator: how often the robot loses its tutor.

For each seed of the tour's office (:func:`sim.tour.tour_world`), in process and in
simulated time: a :class:`~sim.robot.SimRobot` with a 360° laser at 0.5° cut to its
front 180° (the SICK LMS 2xx at 0.5°: 361 beams, 25 scans/s), noisy odometry; the tutor
(:class:`~sim.tutor.Tutor`, as the demo plays it: 0.6 m/s, waits for the robot
beyond 2 m) stands in front of the robot for 3 s, then — "Follow me." — walks the tour's
legs ``into_room``, ``false_doorway`` and ``to_view`` one after the other; every scan goes
through :class:`~knowledge.people.pipeline.PeoplePipeline` (the bundled detector; the
tracker as configured) and :class:`~agent.core.follow.FollowMe`, whose goals drive the robot.
When follow-me gives up it is counted — "I lost you." (the target was being followed) apart
from "I cannot see anyone in front of me." (searching gave up) — and started again, as a
tutor would say "Follow me." again (a restart searches only in front of the robot, so one
loss can be followed by many give-ups while the tutor stands beside it).

Counted per seed: the times the tutor was lost, the seconds spent searching, the
tutor's legs finished, the largest robot–tutor distance, and the scans in which the target
was not the tutor. Rows (:data:`CONFIGS`): before issue 15 (the plain tracker, follow-me
giving up ``lost_after`` seconds after the target was last seen even while it drives to
where the person vanished); the plain tracker with today's follow-me (``chase_for``: the
chase to the corner gets 4 s more, the search radius stops at 2.5 m); and today's default
(the tracker that confirms on evidence and coasts hidden tracks for 2 s).

Run: ``python -m tools.evaluate_follow [--seeds 0-7] [--out docs/results]``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from agent.core.follow import LOST_MESSAGE, FollowMe, FollowParams
from knowledge.fileio import atomic_write_text
from knowledge.people.detector import LegDetector
from knowledge.people.pipeline import PeoplePipeline
from knowledge.people.tracking import TrackerConfig
from sim.robot import Goal, SimRobot, SimRobotConfig
from sim.tour import tour_world
from sim.tutor import Tutor

LEGS = ("into_room", "false_doorway", "to_view")
STAND = 3.0  # seconds the tutor stands in front of the robot before "Follow me."
TIMEOUT = 150.0  # simulated seconds per run


def front_half(ranges: np.ndarray) -> np.ndarray:
    """Beams −90° … +90° of a 360° scan whose beam ``i`` is at ``i·2π/n``."""
    q = ranges.size // 4
    return np.concatenate([ranges[-q:], ranges[: q + 1]])


#: name -> (tracker, follow-me parameters). FollowParams(chase_for=0, max_search_radius=2) is
#: exactly the follow-me before issue 15 (its search radius grew for at most lost_after = 2 s).
CONFIGS = {
    "before (plain tracker, no chase patience)": (
        "plain",
        FollowParams(chase_for=0.0, max_search_radius=2.0),
    ),
    "plain tracker, follow-me today": ("plain", FollowParams()),
    "default (today)": ("default", FollowParams()),
}


def run_seed(seed: int, tracker: str, det: LegDetector, params: FollowParams | None = None) -> dict[str, Any]:
    tour = tour_world(seed)
    cfg = SimRobotConfig(
        world=f"demo:{seed}",
        start=tour.start,
        laser="360",
        beams=720,
        scan_rate=25.0,
        scan_range=10.0,
        seed=seed,
    )
    robot = SimRobot(cfg)
    first = tour.leg(LEGS[0]).waypoints
    heading = math.atan2(first[1][1] - first[0][1], first[1][0] - first[0][0])
    tutor = Tutor(tour.tutor_start, heading, speed=0.6, wait_distance=2.0, resume_distance=1.4)
    tutor.attach(robot)
    scans: list[Any] = []
    robot.scan_listeners.append(scans.append)
    pipe = (
        PeoplePipeline(det, tracker=TrackerConfig(), static=None, min_seen_through=0, min_score=None)
        if tracker == "plain"
        else PeoplePipeline(det)
    )
    follow = FollowMe(params or FollowParams())
    legs = list(LEGS)
    started = False
    lost: list[tuple[float, str]] = []
    searching = 0.0
    max_gap = 0.0
    wrong = 0
    last_t = 0.0
    steps = round(TIMEOUT * cfg.odom_rate)
    finished_at: float | None = None
    for _ in range(steps):
        sample = robot.step()
        t = robot.base.time
        truth = sample.truth
        if not started and t >= STAND:
            follow.start(sample.stamp)
            tutor.walk(tour.leg(legs.pop(0)).waypoints)
            started = True
            last_t = t
        elif started and legs and not tutor.walking:
            tutor.walk(tour.leg(legs.pop(0)).waypoints)
        if started and not legs and not tutor.walking and finished_at is None:
            finished_at = t
        if finished_at is not None and t > finished_at + 3.0:
            break
        if started:
            max_gap = max(max_gap, math.dist(tutor.position, (truth.x, truth.y)))
        while scans:
            scan = scans.pop(0)
            odom = (sample.odom.x, sample.odom.y, sample.odom.theta)
            frame = pipe.process(
                front_half(scan.ranges),
                scan.stamp,
                angle_min=-math.pi / 2,
                angle_increment=scan.angle_increment,
                range_max=scan.range_max,
                sensor_pose=cfg.mount.apply(odom),
            )
            if not started:
                continue
            step = follow.update(frame, odom, scan.stamp)
            if step.state == "searching":
                searching += t - last_t
            if step.state == "following" and step.target_track is not None:
                tr = {s.id: s for s in frame.tracks}.get(step.target_track)
                if tr is not None and tr.misses == 0:
                    # the tutor's true position seen through the odometry's drift
                    dx, dy = tutor.position[0] - truth.x, tutor.position[1] - truth.y
                    c, s_ = math.cos(odom[2] - truth.theta), math.sin(odom[2] - truth.theta)
                    seen = (odom[0] + c * dx - s_ * dy, odom[1] + s_ * dx + c * dy)
                    wrong += math.dist(seen, tr.position) > 0.6
            if step.cancel:
                robot.cancel()
                lost.append((round(t, 1), step.message or ""))
                follow.start(scan.stamp)  # the tutor says "Follow me." again
            if step.goal is not None:
                robot.send_goal(Goal(f"follow-{t:.2f}", (step.goal[:2],), heading=step.goal[2]))
            last_t = t
    return {
        "seed": seed,
        "tracker": tracker,
        "lost": len(lost),
        "lost_at": lost,
        "legs_finished": len(LEGS) - len(legs) - (1 if tutor.walking else 0),
        "searching_s": round(searching, 1),
        "max_distance_m": round(max_gap, 2),
        "wrong_target_scans": wrong,
        "seconds": round(robot.base.time, 1),
        "collisions": robot.base.collisions,
    }


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.evaluate_follow", description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-7", help="seeds of the tour's office, e.g. 0-7 or 0,2,5")
    ap.add_argument("--out", type=Path, help="write follow_tour.md and follow_tour.json here")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if "-" in args.seeds:
        a, b = args.seeds.split("-")
        seeds = list(range(int(a), int(b) + 1))
    else:
        seeds = [int(s) for s in args.seeds.split(",")]
    det = LegDetector.load()
    rows = []
    t0 = time.perf_counter()
    for name, (tracker, params) in CONFIGS.items():
        for seed in seeds:
            r = {"config": name, **run_seed(seed, tracker, det, params)}
            rows.append(r)
            print(json.dumps(r), file=sys.stderr)
    lines = [
        '| configuration | seed | lost ("I lost you.") | first lost at (s) | gave up searching | legs walked '
        "| searching (s) | max distance (m) | wrong-target scans |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        lost = [t for t, m in r["lost_at"] if m == LOST_MESSAGE]
        gave_up = len(r["lost_at"]) - len(lost)
        at = f"{lost[0]:g}" if lost else "—"
        lines.append(
            f"| {r['config']} | {r['seed']} | {len(lost)} | {at} | {gave_up} | {r['legs_finished']}/{len(LEGS)} | "
            f"{r['searching_s']} | {r['max_distance_m']} | {r['wrong_target_scans']} |"
        )
    for name in CONFIGS:
        sel = [r for r in rows if r["config"] == name]
        n_lost = [sum(m == LOST_MESSAGE for _, m in r["lost_at"]) for r in sel]
        lines.append(
            f"\n{name}: the tutor lost {sum(n_lost)} times in {len(sel)} tours ({sum(n > 0 for n in n_lost)} "
            f"tours with a loss); all legs walked in {sum(r['legs_finished'] == len(LEGS) for r in sel)}"
        )
    text = "\n".join(lines)
    print(text)
    print(f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        head = (
            "# Follow-me on the guided tour (simulator)\n\n"
            f"Made by `python -m tools.evaluate_follow --seeds {args.seeds} --out docs/results`; "
            "the set-up is in the tool's docstring.\n\n"
        )
        atomic_write_text(args.out / "follow_tour.md", head + text + "\n")
        atomic_write_text(args.out / "follow_tour.json", json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
