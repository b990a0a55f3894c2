"""Kill the agent at random moments and check that nothing it acknowledged is lost (issue 25).

What an operator did to file the issue, as a probe with a seed: the simulated robot drives a
tour of a generated building again and again (``loci sim robot --tour --loop``, a 360° laser
on the bus); ``loci run`` builds its map with the conceptual map on; a tutor names the place
every ``--period`` seconds (``assert_name`` "crash name N": an ``ok`` reply makes the name
*acknowledged*) and answers every "Was there a door here?" (yes and no in turn: an ``ok``
makes the answer acknowledged); a querier asks ``state/graph`` every 0.1 s. The agent is
killed with SIGKILL by its pid, at random, in one of three moments:

- ``startup``: while it starts (0 s to the time the first start took to answer: during the
  resume of the saved map and the conceptual map);
- ``ack``: 0 to 1.5 s after an acknowledgement;
- ``run``: 1 to 8 s after it answered.

and started again on the same state folder. Checked after every kill and restart:

- **lost**: an acknowledged name not on an area of the restarted agent's conceptual map
  (``state/concepts``), or on an area its map (``state/areas``) does not have; a doorway the
  tutor said was none back in the map; a doorway the tutor confirmed not in the saved file;
- **empty**: a ``state/graph`` answer with fewer nodes than the file had when the agent was
  started (a doorway removed since excepted): an agent answering before it resumed its map;
- **corrupt**: ``navgraph.json`` that does not load, a conceptual map whose SQLite
  ``integrity_check`` is not ``ok``, a temp file of a save left after the restart.

``make fuzz`` runs 50 kills (``python -m tools.crash --kills 50``) and writes the table in
docs/results/reliability.md (``--out``); ``tests/e2e/test_crash.py`` runs a short version.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
ROBOT = "crashbot"
MODES = ("startup", "ack", "run")
#: seconds after an acknowledgement (``ack``) and after the first answer (``run``)
ACK_WINDOW = (0.0, 1.5)
RUN_WINDOW = (1.0, 8.0)


@dataclass
class Kill:
    """One kill: when, what the agent had acknowledged by then, what the restart showed."""

    index: int
    mode: str
    after_s: float  # seconds after the start (startup, run) or after the acknowledgement (ack)
    answering_s: float | None  # the start's first state/graph answer, seconds after the spawn
    acknowledged: int  # facts acknowledged before the kill (all incarnations)
    starting_replies: int  # intents answered "starting" during this incarnation
    disk_nodes: int  # nodes in navgraph.json when this incarnation started
    lost: list[str] = field(default_factory=list)  # acknowledged before, missing at this start
    empty: int = 0
    corrupt: list[str] = field(default_factory=list)


@dataclass
class CrashReport:
    kills: list[Kill]
    seed: int
    acknowledged: int
    names: int
    doors: int
    lost: list[str]
    empty_answers: int
    corrupt: list[str]
    starting_replies: int
    graph_answers: int
    starting_answers: int  # state/graph queries answered "starting" (the map still loading)
    seconds: float
    startup_s: list[float]

    @property
    def ok(self) -> bool:
        return not self.lost and not self.empty_answers and not self.corrupt

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self), "ok": self.ok}


class Tutor:
    """The tutor and the querier on the harness's own Zenoh session (threads)."""

    def __init__(self, session: Any, period: float, rng: random.Random) -> None:
        from agent.bus.bridge import publish_stream

        self.session = session
        self.period = period
        self.rng = rng
        self.lock = threading.Condition()
        self.sent: dict[str, tuple[str, Any]] = {}  # intent id -> (kind, what)
        self.acked: list[tuple[str, Any, float]] = []  # (kind, what, monotonic time)
        self.starting = 0
        self.refused = 0
        self.graph_answers: list[
            tuple[int, float, int | None, str | None]
        ] = []  # (incarnation, t, nodes, err)
        self.incarnation = 0
        self.alive = False
        self._n = 0
        self._answers = 0
        self._stop = threading.Event()
        self._intents = publish_stream(session, ROBOT, "dialogue/intent")
        self._subs = [
            session.declare_subscriber(f"loci/{ROBOT}/dialogue/say", self._on_say),
            session.declare_subscriber(f"loci/{ROBOT}/dialogue/ask", self._on_ask),
        ]
        self._threads = [
            threading.Thread(target=self._talk, daemon=True, name="tutor"),
            threading.Thread(target=self._query, daemon=True, name="querier"),
        ]
        for t in self._threads:
            t.start()

    def _put(self, iid: str, kind: str, args: dict[str, Any], what: Any) -> None:
        with self.lock:
            self.sent[iid] = (kind, what)
        self._intents.put(
            {"schema": "loci.intent/1", "id": iid, "speaker": "tutor", "intent": kind, "args": args}
        )

    def _talk(self) -> None:
        while not self._stop.wait(self.period * self.rng.uniform(0.5, 1.5)):
            self._n += 1
            name = f"crash name {self._n}"
            self._put(f"name-{self._n}", "assert_name", {"name": name}, name)

    def _on_ask(self, sample: Any) -> None:
        msg = json.loads(sample.payload.to_bytes())
        about = msg.get("about") or {}
        node = about.get("door", about.get("node"))
        if not isinstance(node, int) or "yes" not in msg.get("choices", []):
            return
        self._answers += 1
        answer = "yes" if self._answers % 2 else "no"
        self._put(
            f"answer-{self._answers}", "answer", {"answer": answer, "question": msg["id"]}, (answer, node)
        )

    def _on_say(self, sample: Any) -> None:
        msg = json.loads(sample.payload.to_bytes())
        iid = msg.get("in_reply_to")
        with self.lock:
            sent = self.sent.pop(iid, None)
            if sent is None:
                return
            if msg.get("status") == "ok":
                kind, what = sent
                if kind == "assert_name":
                    self.acked.append(("name", what, time.monotonic()))
                elif "removed" in (msg.get("content") or {}) or what[0] == "yes":
                    self.acked.append(("door_" + what[0], what[1], time.monotonic()))
            elif (msg.get("content") or {}).get("starting"):
                self.starting += 1
            else:
                self.refused += 1
            self.lock.notify_all()

    def _query(self) -> None:
        from agent.bus.queryable import query_state

        while not self._stop.wait(0.1):
            if not self.alive:
                continue
            inc = self.incarnation
            for r in query_state(self.session, f"loci/{ROBOT}/state/graph", timeout=1.0):
                nodes = len(r.value.get("nodes", [])) if r.value is not None else None
                with self.lock:
                    self.graph_answers.append((inc, time.monotonic(), nodes, r.error))

    def wait_ack(self, after: float, timeout: float) -> float | None:
        """The time of the first acknowledgement after ``after`` (None: none within ``timeout``)."""
        deadline = time.monotonic() + timeout
        with self.lock:
            while True:
                later = [t for _, _, t in self.acked if t > after]
                if later:
                    return min(later)
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self.lock.wait(left)

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(5)
        for s in self._subs:
            s.undeclare()
        self._intents.close()


def agent_config(work: Path, endpoint: str, robot: str = ROBOT, *, save_interval: float = 30.0) -> Path:
    """``work/robot.toml``: ``loci run`` on the bus (scans and odometry from ``loci/<robot>/``),
    its state in ``work/state``, the conceptual map on, connected to ``endpoint``."""
    path = work / "robot.toml"
    path.write_text(
        f"""
[robot]
name = "{robot}"

[bus]
listen = ["tcp/127.0.0.1:0"]
connect = ["{endpoint}"]

[laser]
source = "bus"

[state]
dir = "{work / "state"}"
save_interval = {save_interval}

[conceptual]
enabled = true
debounce = 0.5
"""
    )
    return path


def _disk(state: Path) -> dict[str, Any]:
    """What the state folder holds, and what is wrong with it."""
    from knowledge.topology import persistence

    out: dict[str, Any] = {"nodes": 0, "areas": 0, "confirmed": set(), "corrupt": []}
    nav = state / "navgraph.json"
    if nav.exists():
        try:
            doc = json.loads(nav.read_text(encoding="utf-8"))
            graph, areas = persistence.from_document(doc)
            out["nodes"], out["areas"] = len(graph), len(areas.areas) if areas is not None else 0
            out["confirmed"] = set((doc.get("meta") or {}).get("confirmed_doorways") or [])
        except Exception as exc:
            out["corrupt"].append(f"navgraph.json: {exc}")
    db = state / "concepts.sqlite3"
    if db.exists():
        try:
            con = sqlite3.connect(str(db))
            try:
                (result,) = con.execute("PRAGMA integrity_check").fetchone()
            finally:
                con.close()
            if result != "ok":
                out["corrupt"].append(f"concepts.sqlite3: integrity_check {result}")
        except sqlite3.Error as exc:
            out["corrupt"].append(f"concepts.sqlite3: {exc}")
    return out


class AgentRun:
    """One incarnation of ``loci run`` (stderr to a log file)."""

    def __init__(self, config: Path, log: Path) -> None:
        self.log = log
        self.spawned = time.monotonic()
        self._err = log.open("w")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "agent.cli", "run", "--config", str(config)],
            cwd=REPO,
            stdout=subprocess.DEVNULL,
            stderr=self._err,
        )

    def kill(self) -> None:
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.wait(30)
        self._err.close()

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(60)
        finally:
            self._err.close()


def _first_answer(tutor: Tutor, inc: int, timeout: float, agent: AgentRun) -> float | None:
    """Monotonic time of this incarnation's first state/graph answer with a map."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and agent.proc.poll() is None:
        with tutor.lock:
            got = [t for i, t, n, _ in tutor.graph_answers if i == inc and n is not None]
        if got:
            return got[0]
        time.sleep(0.05)
    return None


def _check_restart(
    tutor: Tutor, session: Any, acked: list[tuple[str, Any, float]], state: Path, settle: float = 30.0
) -> list[str]:
    """Acknowledged facts the restarted agent does not have.

    ``state/concepts`` and ``state/areas`` are two answers: right after a restart the first
    scan may merge two areas while the concepts move their names a moment later, so a name
    on an area the map does not have counts as lost only if it stays so for ``settle`` s.
    """
    from agent.bus.queryable import query_state

    def get(name: str) -> dict[str, Any] | None:
        for _ in range(50):
            for r in query_state(session, f"loci/{ROBOT}/state/{name}", timeout=2.0):
                if r.value is not None:
                    return r.value
            time.sleep(0.1)
        return None

    deadline = time.monotonic() + settle
    while True:
        concepts, areas, graph = get("concepts"), get("areas"), get("graph")
        if concepts is None or areas is None or graph is None:
            return ["the restarted agent did not answer state/concepts, state/areas and state/graph"]
        area_ids = {str(a["id"]) for a in areas.get("areas", [])}
        named: dict[str, str] = {}
        for aid, a in (concepts.get("areas") or {}).items():
            for n in a.get("names", []):
                named[n] = str(aid)
        doors = {int(n["id"]) for n in graph.get("nodes", []) if n.get("kind") not in (None, "place")}
        confirmed = _disk(state)["confirmed"]
        lost, moving = [], False
        for kind, what, _ in acked:
            if kind == "name":
                if what not in named:
                    lost.append(f"{what!r}: not in the conceptual map")
                elif named[what] not in area_ids:
                    lost.append(f"{what!r}: on area {named[what]}, which the map does not have")
                    moving = True
            elif kind == "door_no" and what in doors:
                lost.append(f"doorway {what}: the tutor said there was none; it is back")
            elif kind == "door_yes" and what in doors and what not in confirmed:
                lost.append(f"doorway {what}: confirmed by the tutor, not in the saved file")
        if not moving or time.monotonic() > deadline:
            return lost
        time.sleep(0.2)


def run_crashes(
    kills: int,
    *,
    seed: int = 0,
    work: Path,
    world: str = "gen:3",
    period: float = 2.0,
    modes: Sequence[str] | None = None,
    progress: Callable[[Kill], None] | None = None,
) -> CrashReport:
    """Kill the agent ``kills`` times (see the module docstring); returns what was found.

    ``modes``: the moment of each kill in turn (default: drawn at random from :data:`MODES`).
    A ``startup`` kill before any start was measured waits for the first answer instead.
    """
    from agent.bus.session import BusConfig, bus_session, listening_endpoints
    from agent.demo.processes import stop_process

    rng = random.Random(seed)
    work.mkdir(parents=True, exist_ok=True)
    (work / "state").mkdir(exist_ok=True)
    t0 = time.monotonic()
    results: list[Kill] = []
    startup: list[float] = []
    corrupt: list[str] = []
    with bus_session(BusConfig()) as session:
        (endpoint,) = listening_endpoints(session)
        config = agent_config(work, endpoint)
        sim_log = (work / "sim.log").open("w")
        sim = subprocess.Popen(
            [sys.executable, "-m", "agent.cli", "sim", "robot", "--world", world, "--tour", "--loop",
             "--laser", "360", "--robot", ROBOT, "--connect", endpoint, "--seed", str(seed)],
            cwd=REPO, stdout=subprocess.DEVNULL, stderr=sim_log,
        )  # fmt: skip
        tutor = Tutor(session, period, rng)
        try:
            for k in range(kills + 1):  # the last incarnation is stopped, not killed
                disk = _disk(work / "state")
                corrupt += [f"before start {k}: {c}" for c in disk["corrupt"]]
                with tutor.lock:
                    tutor.incarnation = k
                    starting_before = tutor.starting
                    acked_before = list(tutor.acked)
                agent = AgentRun(config, work / f"agent-{k}.log")
                tutor.alive = True
                if k == kills:
                    mode = "stop"
                else:
                    mode = modes[k % len(modes)] if modes else rng.choice(MODES)
                lost: list[str] = []
                if mode == "startup" and startup:
                    after = rng.uniform(0.0, max(startup))
                    time.sleep(after)
                    answered = None
                else:
                    answered = _first_answer(tutor, k, 120.0, agent)
                    if answered is None:
                        raise RuntimeError(f"the agent did not answer state/graph (see {agent.log})")
                    startup.append(answered - agent.spawned)
                    lost = _check_restart(tutor, session, acked_before, work / "state") if k else []
                    strays = list((work / "state").glob(".navgraph.json.*.tmp"))
                    corrupt += [f"after restart {k}: stray {p.name}" for p in strays]
                    if mode == "ack":
                        t = tutor.wait_ack(time.monotonic(), 60.0)
                        if t is None:
                            raise RuntimeError(f"no acknowledgement within 60 s (see {agent.log})")
                        after = rng.uniform(*ACK_WINDOW)
                        time.sleep(max(0.0, t + after - time.monotonic()))
                    elif mode == "run":
                        after = rng.uniform(*RUN_WINDOW)
                        time.sleep(after)
                    else:
                        after = 0.0
                if mode == "stop":
                    rc = agent.stop()
                    if rc != 0:
                        corrupt.append(f"the last agent exited with {rc} (see {agent.log})")
                else:
                    agent.kill()
                tutor.alive = False
                time.sleep(0.2)  # replies in flight arrive
                with tutor.lock:
                    answers = [(n, e) for i, _, n, e in tutor.graph_answers if i == k]
                    starting = tutor.starting - starting_before
                    acknowledged = len(tutor.acked)
                removed = sum(1 for kind, _, t in tutor.acked if kind == "door_no" and t > agent.spawned)
                empty = sum(1 for n, _ in answers if n is not None and n < disk["nodes"] - removed)
                kill = Kill(k, mode, round(after, 3), round(answered - agent.spawned, 2) if answered else None,
                            acknowledged, starting, disk["nodes"], lost, empty)  # fmt: skip
                results.append(kill)
                if progress is not None:
                    progress(kill)
            # what is on disk at the end holds every acknowledged name
            final = _disk(work / "state")
            corrupt += [f"at the end: {c}" for c in final["corrupt"]]
            final_lost = _check_final(work / "state", tutor.acked)
        finally:
            tutor.close()
            stop_process(sim, signal.SIGTERM, 30.0)
            sim_log.close()
    lost_all = sorted({x for kill in results for x in kill.lost} | set(final_lost))
    kinds = [kind for kind, _, _ in tutor.acked]
    return CrashReport(
        kills=results[:-1] if results and results[-1].mode == "stop" else results,
        seed=seed,
        acknowledged=len(kinds),
        names=kinds.count("name"),
        doors=len(kinds) - kinds.count("name"),
        lost=lost_all,
        empty_answers=sum(k.empty for k in results),
        corrupt=corrupt,
        starting_replies=tutor.starting,
        graph_answers=len(tutor.graph_answers),
        starting_answers=sum(
            1 for *_, e in tutor.graph_answers if e is not None and e.startswith("starting")
        ),
        seconds=round(time.monotonic() - t0, 1),
        startup_s=[round(s, 2) for s in startup],
    )


def _check_final(state: Path, acked: list[tuple[str, Any, float]]) -> list[str]:
    """Acknowledged names not in the conceptual map file after the last agent stopped."""
    from knowledge.conceptual import ConceptualMap

    m = ConceptualMap(state / "concepts.sqlite3")
    try:
        snap = m.snapshot()
    finally:
        m.close()
    names = {n for a in snap["areas"].values() for n in a.get("names", [])}
    return [
        f"{what!r}: not in concepts.sqlite3 at the end"
        for kind, what, _ in acked
        if kind == "name" and what not in names
    ]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m tools.crash",
        description="Kill loci run with SIGKILL at random moments (start-up, right after an "
        "acknowledgement, mid-run) while a tutor names places; check that no acknowledged fact "
        "is lost, no restart answers from an empty map and no file is corrupt.",
    )
    p.add_argument("--kills", type=int, default=50, help="SIGKILLs (default 50)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--world", default="gen:3", help="the simulated building (default gen:3)")
    p.add_argument("--period", type=float, default=2.0, help="seconds between the tutor's names (default 2)")
    p.add_argument("--work", type=Path, help="state folder and logs (default: a temporary folder)")
    p.add_argument("--out", type=Path, help="write crash.json there")
    return p


def main(argv: list[str] | None = None) -> int:
    import tempfile

    args = build_parser().parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="loci-crash-"))

    def show(k: Kill) -> None:
        flags = []
        if k.lost:
            flags.append(f"LOST {k.lost}")
        if k.empty:
            flags.append(f"EMPTY {k.empty}")
        print(
            f"kill {k.index + 1:3d} {k.mode:8s} +{k.after_s:5.2f} s  answered {k.answering_s} s  "
            f"acknowledged {k.acknowledged:4d}  starting replies {k.starting_replies}  "
            f"disk nodes {k.disk_nodes}  {' '.join(flags) or 'ok'}",
            flush=True,
        )

    report = run_crashes(
        args.kills, seed=args.seed, work=work, world=args.world, period=args.period, progress=show
    )
    doc = report.to_json()
    print(json.dumps({k: v for k, v in doc.items() if k != "kills"}, indent=1))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "crash.json").write_text(json.dumps(doc, indent=1) + "\n")
    print(f"work folder: {work}")
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
