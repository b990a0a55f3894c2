"""``loci demo``: the guided tour of the book's Sect. 7.4, end to end (see :mod:`agent.demo.tour_run`).

The simulated robot, the agent and the dialogue process run as separate processes on a
loopback Zenoh bus; the tutor's lines are scripted (or typed with ``--interactive``). The
whole-map labeling demo that used to be here is ``loci places demo``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _speed(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = -1.0
    if not (0 < v <= 4):
        raise argparse.ArgumentTypeError(f"--speed is a number in (0, 4], got {text!r}")
    return v


def _address(text: str) -> str:
    from agent.live.config import parse_address

    try:
        parse_address(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "demo",
        help="the guided tour: follow me, a false doorway, look around, go to (no hardware needed)",
        description=(
            "Play the guided tour of the book's Sect. 7.4 on a simulated office: a tutor wakes the robot "
            "at the charging station, the robot follows it through a door into a room, asks about a "
            "false doorway, learns that the room is a living room from what it sees, then goes to the "
            "television and back to the station. The simulator, the agent and the dialogue process run "
            "as separate processes on a loopback Zenoh bus. Writes the transcript, the MCAP recording "
            "(loci replay, Foxglove), the layered map (map.png) and summary.json to the output folder."
        ),
        epilog="Example: loci demo --out-dir out/tour;  loci demo --interactive  (docs/demo.md)",
    )
    p.add_argument(
        "--out-dir",
        "--out",
        dest="out",
        type=Path,
        default=None,
        metavar="DIR",
        help="the folder to write into (default: out/tour-YYYYmmdd-HHMMSS; --out is the old name)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the tour's office (default 0)")
    p.add_argument(
        "--speed",
        type=_speed,
        default=1.5,
        help="simulated seconds per wall-clock second (default 1.5)",
    )
    p.add_argument(
        "--interactive",
        action="store_true",
        help="type the tutor's lines yourself; 'Follow me.' also makes the tutor walk the next leg",
    )
    p.add_argument("--no-replay", action="store_true", help="skip replaying the recording at the end")
    p.add_argument(
        "--foxglove",
        type=_address,
        metavar="[HOST:]PORT",
        help="watch the tour live in the Foxglove app: the agent serves its layers on this WebSocket "
        "port (docs/foxglove.md)",
    )
    p.add_argument(
        "--odometry",
        choices=("exact", "noisy"),
        default="noisy",
        help="noisy (default): the base's odometry drifts (drivers.sim.base.OdometryNoise) and the agent "
        "tracks its pose by scan matching on its own thread; exact: the simulated odometry is the true pose",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print the summary as one JSON object at the end (the conversation goes to stderr)",
    )
    p.set_defaults(handler=cmd_demo)


def cmd_demo(args: argparse.Namespace) -> int:
    from agent.demo.tour_run import DemoOptions, Screen, run_demo

    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    opts = DemoOptions(
        out=args.out,
        seed=args.seed,
        speed=args.speed,
        interactive=args.interactive,
        replay=not args.no_replay,
        foxglove=args.foxglove,
        odometry=args.odometry,
    )
    import signal

    def on_term(signum: int, frame: object) -> None:
        raise KeyboardInterrupt  # the children are stopped on the way out

    previous = signal.signal(signal.SIGTERM, on_term)
    try:
        # with --json the conversation goes to stderr: stdout holds the one JSON object
        summary = run_demo(opts, Screen(out=sys.stderr) if args.json else None)
    finally:
        signal.signal(signal.SIGTERM, previous)
    if args.json:
        json.dump(summary, sys.stdout, indent=2, default=str)
        sys.stdout.write("\n")
    else:
        print()
        for s in summary["steps"]:
            mark = "ok  " if s["passed"] else "FAIL"
            why = f"  ({s['failure']})" if s["failure"] else ""
            print(f"  {mark} {s['book_step']}. {s['step']:<12} {s['text']}{why}")
        rep = summary.get("replay")
        if rep:
            print(
                f"  {'ok  ' if rep['passed'] else 'FAIL'} replay: the recording gives the same areas"
                + (f" ({rep.get('failure')})" if not rep["passed"] else "")
            )
        t = summary["timings_s"]
        verdict = (
            "DONE (interactive: nothing is checked)"
            if args.interactive
            else ("PASSED" if summary["passed"] else "NOT PASSED")
        )
        print(
            f"\n{verdict} in {t.get('total', 0):.0f} s "
            f"(start {t.get('startup', 0):.0f} s, tour {t.get('tour', 0):.0f} s); outputs in {summary['folder']}/: "
            "transcript.jsonl, tour.mcap, map.png, summary.json, *.log"
        )
    return 0 if summary["passed"] or args.interactive else 1
