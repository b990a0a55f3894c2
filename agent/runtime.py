"""The running agent: the laser, odometry, the per-scan pipeline and the bus, in one event loop.

``await Agent(config).run(stop)`` (``loci run``) does, in order:

1. open the Zenoh session (closed in ``finally``, whatever happens) and declare the queryables
   ``state/graph``, ``state/areas``, ``state/place`` (``state/concepts``), ``map/save`` and
   the intent subscription: until step 3 is done every query is answered with the error
   ``starting`` (``map/save``: "no map yet") and every intent with a "starting" reply
   (nothing is taken; an agent that restarts never answers from an empty map);
2. load the place model and, unless ``state.resume`` is off, the persisted graph
   (``<state.dir>/navgraph.json``, with the doorways the tutor confirmed); compile the
   pipeline's kernels (a throwaway run);
3. open the conceptual map; from now on the queryables answer from the state and the
   dialogue serves the intents (the same subscription: none falls between);
4. start the recording, if configured: a :class:`~agent.recording.recorder.Recorder` on the
   same session subscribing ``loci/<robot>/**`` (a session hears its own publications), with
   the initial state, the pipeline parameters and the model's hash in the file's metadata;
5. declare the publishers and the odometry subscription;
6. open the laser: an LMS 2xx on ``laser.port`` (read and stamped on a thread of its own,
   :mod:`drivers.threaded`; each scan it gives is published on ``loci/<robot>/scan`` and then
   processed, so the recording holds exactly the scans the agent saw), a subscription to
   ``loci/<robot>/scan``, or a recording (``[laser] source = "recording"``: its scans and
   odometry, paced, published as the robot's own and processed with their recorded arrival
   times; the agent stops at its end);
7. run until ``stop`` is set (SIGINT/SIGTERM in ``loci run``).

Every task runs under :func:`~agent.supervisor.supervise`: a task that raises is logged (its
first failure of a kind with the traceback, then counts), counted (``restarts`` in the report
and the diagnostics) and started again after a back-off (0.1 s doubling to 5 s); no task's
failure stops the agent. The recorder is not restarted (its file is closed when it fails);
the agent runs on without recording.

Tasks (one event loop, one thread for the core): the **laser** task (driver, bus or
recording), the **odometry** task (bus), the **housekeeping** task (every 50 ms: expire
scans that waited too long for odometry, save the state when it changed and
``state.save_interval`` passed), the **diagnostics** task (every ``diagnostics.period``) and
the **recorder** task. Both sensor tasks feed the one sensor loop
(:class:`~agent.core.sensor_loop.SensorLoop`, the same that ``loci replay`` runs): each scan
the odometry association releases goes at once, synchronously (a few ms), through the
:class:`~agent.core.pipeline.Pipeline` and out on the bus, in stamp order. Before a scan
enters the loop, the odometry already queued is taken first, so arrival order is kept across
the two streams. A sensor task yields to the loop after each scan, so with a backlog (a
slow or busy computer) the recorder, the dialogue's answers and the base's status still get
their turn between two scans instead of waiting until the backlog is worked off. With
``[laser] max_rate`` the loop runs the whole chain on at most that many scans a second, by
their stamps, and the others through ``Pipeline.observe`` only (people, local map, doorways).
The warm-up compiles every kernel before the laser opens (:mod:`agent.core.warmup`); the
agent declares itself ready (``loci/<robot>/ready/agent``) once its first scan is processed.

Queues: the driver thread keeps ``laser.queue_size`` scans read and not yet processed
(about 7 s; drop-oldest beyond, counted ``driver``); the bus subscriptions keep 256 samples
each (drop-oldest, counted); the recorder waits (bounded). An agent that falls behind (a
busy machine) processes every scan later rather than fewer of them, so its result does not
depend on its speed; only one more than these queues behind loses scans, and the diagnostics
and the final report say so.

Each processed scan is also integrated into the occupancy map of the run (at the pose the
pipeline gave it, :mod:`agent.core.map_files`), which a ``map/save`` request
(``loci.map_save/1``, ``loci map save``) writes as map_server YAML + PGM with its label image
into the folder it names; the files are written off the loop.

Published per processed scan: ``place`` (``loci.place/1``), ``tf`` (odom → laser; map →
laser with ``[localization]`` tracking, which also publishes ``tf/map``, map → odom),
``scan/full`` (the 360° scan); with ``[people]`` on, for each scan with legs or tracks in
it (and one empty message after the last such scan, which clears the picture) ``people``
(``loci.people/1``, tracks in the odometry frame) and ``people/scene``
(``foxglove.SceneUpdate``); when they change: ``graph``, ``graph/scene``, ``areas``,
``areas/scene``; every period: ``diagnostics``. A malformed message on a subscribed stream
is logged, counted (``invalid``) and ignored.

Shutdown (``stop`` set): the laser stops (the LMS is put back to 9600 baud and its port
closed); scans still waiting get up to ``odometry.max_wait`` for their odometry; the state
is saved; a last diagnostics message marks the end (``extra.final``: the scans fed and the
last scan's stamp, which a replay uses to stop at the same scan); the recording is flushed
and closed; every subscription, queryable and the session are closed.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import zenoh

from agent.bus.bridge import (
    BusClosed,
    BusStats,
    Publisher,
    RawSample,
    Subscription,
    publish_stream,
    subscribe_stream,
)
from agent.bus.codecs import (
    LASER_SCAN_CODEC,
    POSE_CODEC,
    Codec,
    checked_decode,
    decode_laser_scan,
    frame_transform,
)
from agent.bus.diagnostics import diagnostics_message, publish_diagnostics
from agent.bus.keys import REQUEST_KEYS, Policy, RobotKeys, robot_wildcard
from agent.bus.queryable import NO_STATE, RequestQueryable, StateCell, StateQueryable
from agent.bus.ready import declare_ready
from agent.bus.scene import areas_scene, graph_scene, people_scene
from agent.bus.session import close_session, listening_endpoints, open_session
from agent.config import AgentConfig
from agent.conversation.agent import STARTING, DialogueAgent, Outgoing, starting_reply
from agent.conversation.memory import MemoryConcepts
from agent.conversation.task import run_dialogue
from agent.core.map_files import add_step, save_map
from agent.core.odom_sync import Matched, OdomSync
from agent.core.pipeline import Pipeline, PipelineParams, StepResult, place_message
from agent.core.sensor_loop import SensorLoop
from agent.core.warmup import CompileWatch, warm_up
from agent.ratelog import RateLimitedLog
from agent.recording.recorder import McapSink, Recorder, recording_metadata
from agent.supervisor import Restarts, supervise
from drivers.camera.jpeg import decode_image
from drivers.messages import LaserScan, Pose2D
from knowledge.errors import ConfigError, DataError, MapError, ProtocolError
from knowledge.fileio import atomic_write_text, file_sha256, remove_stale_temps
from knowledge.metric.mapping import ScanMapper
from knowledge.people.detector import LegDetector
from knowledge.places.model import PlaceModel
from knowledge.topology import persistence
from knowledge.topology.areas import AreaCreated

log = logging.getLogger(__name__)
T = TypeVar("T")

#: Samples a sensor subscription keeps for a busy loop (drop-oldest beyond, counted).
SENSOR_QUEUE = 256
#: Seconds between housekeeping rounds (expiry of waiting scans, debounced saving).
TICK = 0.05
#: Seconds the recorder gets to receive the agent's last publications before it stops.
RECORD_GRACE = 0.3


async def _take_turns() -> None:
    """Let the loop's other tasks run once: a sensor task with a backlog (a driver queue or a
    subscription that always has the next item ready) would otherwise never yield, and the
    recorder, the dialogue's answers and the base's status would wait until it caught up."""
    await asyncio.sleep(0)


def _timed(codec: Codec[T]) -> Callable[[RawSample], tuple[float, T]]:
    """A subscription decoder keeping the arrival time (seconds since the epoch)."""

    def decode(raw: RawSample) -> tuple[float, T]:
        return raw.recv_ns * 1e-9, checked_decode(codec, raw.encoding, raw.payload, raw.key)

    return decode


def full_scan_message(result: StepResult, max_range: float) -> LaserScan:
    """The 360° scan of a step as a :class:`LaserScan` in the laser's frame (``max_range``:
    the model's, which beams that hit nothing carry)."""
    n = int(result.ranges.shape[0])
    scan = result.scan
    return LaserScan(
        stamp=scan.stamp,
        seq=scan.seq,
        frame_id=scan.frame_id,
        angle_min=0.0,
        angle_increment=2.0 * math.pi / n,
        range_max=float(max_range),
        ranges=result.ranges,
    )


def _percentiles(values: deque[float]) -> dict[str, float]:
    if not values:
        return {}
    s = sorted(values)
    return {"p50": round(s[len(s) // 2], 3), "p99": round(s[min(len(s) - 1, int(0.99 * len(s)))], 3)}


@dataclass
class AgentReport:
    """What a run did (returned by :meth:`Agent.run`, printed by ``loci run`` at exit).

    ``drops`` holds the scans (or samples) not processed, by named reason: ``driver`` (the
    LMS driver's queue), ``scan_queue``, ``odom_queue`` (bus subscriptions), and every reason
    of :data:`~agent.core.odom_sync.DROP_REASONS` (``no_odometry``, ``odom_gap``, ``late``,
    ``future_stamp``, ...); ``sync`` has all of :class:`~agent.core.odom_sync.OdomSync`'s counters.
    """

    robot: str
    scans_fed: int = 0
    scans_processed: int = 0
    scans_over_rate: int = 0  # left out by ``[laser] max_rate`` (a rule on stamps, not a loss)
    errors: int = 0
    restarts: dict[str, int] = field(default_factory=dict)  # failures by task (each logged, restarted)
    drops: dict[str, int] = field(default_factory=dict)
    sync: dict[str, int] = field(default_factory=dict)
    invalid: dict[str, int] = field(default_factory=dict)
    nodes: int = 0
    areas: int = 0
    saves: int = 0
    starting_replies: int = 0  # intents that came while the saved map loaded (answered "starting")
    state_file: str | None = None
    recording: str | None = None
    recorded: int = 0

    @property
    def dropped(self) -> int:
        return sum(self.drops.values())

    def as_dict(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items()} | {"dropped": self.dropped}


class Agent:
    """The asyncio agent (see the module docstring).

    Args:
        config: the configuration.
        model: a loaded place model (default: load ``config.places.model``).
        on_ready: called once everything runs (the laser delivers or is subscribed).
    """

    def __init__(
        self,
        config: AgentConfig,
        *,
        model: PlaceModel | None = None,
        on_ready: Callable[[Agent], None] | None = None,
    ) -> None:
        self.config = config
        self.robot = config.robot_name
        self.keys = RobotKeys(self.robot)
        self.stats = BusStats()
        self.params = PipelineParams.from_config(config)
        #: the one sensor loop (agent/core/sensor_loop.py): scans with their odometry, in stamp
        #: order, through :meth:`_step`
        self.loop = SensorLoop(
            OdomSync(config.odometry.sync),
            self._step,
            on_error=self._step_failed,
            max_rate=config.laser.max_rate,
            observe=self._observe,
        )
        self.sync = self.loop.sync
        self.report = AgentReport(self.robot)
        self.restarts = Restarts()
        self._ratelog = RateLimitedLog(log)
        self.endpoints: list[str] = []
        self.session: zenoh.Session | None = None
        self._model = model
        self._on_ready = on_ready
        self.pipeline: Pipeline | None = None
        self._initial_state: dict[str, Any] | None = None
        self._pubs: dict[str, Publisher[Any]] = {}
        self._cells = {
            "graph": StateCell("loci.graph/1"),
            "areas": StateCell("loci.areas/1"),
            "place": StateCell("loci.place/1"),
        }
        self._last_graph: dict[str, Any] | None = None
        self._last_areas: dict[str, Any] | None = None
        #: the occupancy map of this run: every processed scan at its pose (``map/save`` writes it)
        self.map = ScanMapper()
        #: changes of the persisted state (graph, areas, confirmed doorways) made / on disk:
        #: the state is dirty while ``_saved_gen < _gen``; saves run one at a time (a late
        #: write of an older state never replaces a newer one)
        self._gen = 0
        self._saved_gen = 0
        self._save_lock = asyncio.Lock()
        self._save_task: asyncio.Task[None] | None = None  # the periodic save under way
        self._saved_confirmed: frozenset[int] = frozenset()  # the doorways confirmed in the file
        self._last_save = -math.inf
        #: while the map loads, every intent gets a "starting" reply (the task doing so)
        self._starting: asyncio.Task[None] | None = None
        self._started = time.monotonic()
        self._last_scan_stamp: float | None = None
        self._last_processed_stamp: float | None = None
        self._process_ms: deque[float] = deque(maxlen=1000)
        self._tracking_errors = 0  # the pipeline's tracking_errors already logged
        self._age_ms: deque[float] = deque(maxlen=1000)
        self._ready: Any = None  # the liveliness token loci/<robot>/ready/agent, once ready
        #: the sensor loop's clock for timeouts: the host's, or a recording's (its last message)
        self._clock: Callable[[], float] = time.time
        self._feed_time = 0.0
        self._last_confidence: str | None = None  # the localization state last published
        #: scans per localization state and tracker events ([localization])
        self._localization_counts: dict[str, int] = {}
        #: kernels compiled after the warm-up (a path it missed): counted and logged
        self._compiles = CompileWatch()
        self.compiled: list[str] = []
        self._lms: Any = None
        self._odom_sub: Subscription[tuple[float, Pose2D]] | None = None
        self._scan_sub: Subscription[tuple[float, LaserScan]] | None = None
        self._warned_no_odom = -math.inf
        self.concepts: Any = None
        self.dialogue: DialogueAgent | None = None
        self._recogniser: Any = None
        self._intent_sub: Subscription[bytes] | None = None
        self._status_sub: Subscription[Any] | None = None
        self._camera_sub: Subscription[Any] | None = None
        self._concepts_version: Any = None
        self._people_shown = False
        #: the Foxglove live view (``[foxglove]``), None when off
        self.live: Any = None
        self._ros2: Any = None

    @property
    def _dirty(self) -> bool:
        """The persisted state changed since the last save that reached the disk."""
        return self._saved_gen < self._gen

    def _mark_dirty(self) -> None:
        self._gen += 1

    # ------------------------------------------------------------------ setup
    def _load(self) -> tuple[PlaceModel, Pipeline]:
        cfg = self.config
        if self._model is None and not cfg.places.model_path.is_file():
            raise ConfigError(
                f"places.model: {cfg.places.model_path} is not a file; give a place model (.npz) or 'default'"
            )
        model = self._model or PlaceModel.load(cfg.places.model_path)
        detector = self._people_detector()
        state = cfg.state.path
        for tmp in remove_stale_temps(state):
            log.warning("removed %s: a save cut short (the agent was killed while writing)", tmp)
        if cfg.state.resume and state.exists():
            try:
                doc = json.loads(state.read_text(encoding="utf-8"))
                pipeline = Pipeline.from_state(doc, model, self.params, people_detector=detector)
            except (ValueError, ProtocolError) as exc:
                raise DataError(
                    f"{state}: {exc}. Move the file aside to start a new map, or set state.resume = false"
                ) from exc
            self._initial_state = persistence.to_document(pipeline.graph, pipeline.areas)
            meta = doc.get("meta") if isinstance(doc.get("meta"), dict) else {}
            confirmed = meta.get("confirmed_doorways", [])
            if isinstance(confirmed, list):
                self._saved_confirmed = frozenset(
                    int(n) for n in confirmed if isinstance(n, int) and n in pipeline.graph
                )
            log.info(
                "resumed the map of %s: %d nodes, %d areas",
                state,
                len(pipeline.graph),
                len(pipeline.areas.areas),
            )
        else:
            pipeline = Pipeline(model, self.params, people_detector=detector)
        seconds = warm_up(model, self.params, people_detector=detector)
        self._compiles.arm()
        log.info("the per-scan kernels are ready (%.1f s)", seconds)
        return model, pipeline

    def _people_detector(self) -> LegDetector | None:
        """The leg detector of ``[people]`` (None when people detection is off).

        Raises:
            ConfigError: the model file is missing.
        """
        pc = self.config.people
        if not pc.enabled:
            return None
        if not pc.model_path.is_file():
            raise ConfigError(
                f"people.model: {pc.model_path} is not a file; give a leg detector (.npz), "
                "'default', or set people.enabled = false"
            )
        return LegDetector.load(pc.model_path)

    def _recording_path(self) -> Path | None:
        path = self.config.record.path
        return Path(time.strftime(path)) if path else None

    def _metadata(self, model: PlaceModel) -> dict[str, str]:
        cfg = self.config
        model_path = cfg.places.model_path
        return recording_metadata(
            self.robot,
            key=robot_wildcard(self.robot),
            writer="loci run",
            pipeline=json.dumps(self.params.to_table(), sort_keys=True),
            model=str(model_path),
            model_sha256=file_sha256(model_path) if model_path.is_file() else "",
            initial_state=persistence.dumps(self._initial_state) if self._initial_state else "",
            sync=json.dumps(cfg.odometry.sync.to_table(), sort_keys=True),
            laser_source=cfg.laser.source,
        )

    def _declare_starting(self, session: zenoh.Session) -> list[StateQueryable | RequestQueryable]:
        """What answers while the saved map loads: the state queryables (their cells say
        ``starting``), ``map/save`` (no map yet), ``dialogue/say``, and the intent
        subscription, served by a task that replies "starting" to each intent until
        :meth:`_end_starting` (the dialogue then serves the same subscription: no intent falls
        between the two)."""
        if self.config.conceptual.on:
            self._cells["concepts"] = StateCell("loci.concepts/1")
        for cell in self._cells.values():
            cell.pending = STARTING
        queryables: list[StateQueryable | RequestQueryable] = [
            StateQueryable(session, self.keys.state(name), cell) for name, cell in self._cells.items()
        ]
        request, reply = REQUEST_KEYS["map/save"]
        queryables.append(
            RequestQueryable(
                session,
                self.keys.stream("map/save"),
                self._save_map,
                request,
                reply,
                asyncio.get_running_loop(),
            )
        )
        self._pubs["dialogue/say"] = publish_stream(session, self.robot, "dialogue/say", stats=self.stats)
        self._intent_sub = Subscription(
            session,
            self.keys.stream("dialogue/intent"),
            lambda raw: raw.payload,
            policy=Policy.WAIT,
            capacity=64,
            stats=self.stats,
            name="dialogue/intent",
        )
        self._starting = asyncio.create_task(self._answer_starting(self._intent_sub), name="starting")
        return queryables

    async def _answer_starting(self, intents: Subscription[bytes]) -> None:
        with contextlib.suppress(BusClosed):
            while True:
                for payload in await intents.recv_batch(16):
                    self.report.starting_replies += 1
                    reply = starting_reply(payload)
                    if reply is None:
                        continue
                    try:
                        self._send(reply)
                    except Exception as exc:  # the intent stays unanswered; the start goes on
                        self._ratelog("starting", "could not reply 'starting': %s", exc, exc=exc)

    async def _end_starting(self) -> None:
        """Stop the "starting" replies (cancelling at the queue's await leaves the next intent
        queued for the dialogue)."""
        if self._starting is None:
            return
        await _cancel(self._starting)
        self._starting = None
        if self.report.starting_replies:
            log.info(
                "%d intents came while the map loaded; each got a 'starting' reply",
                self.report.starting_replies,
            )

    def _declare(self, session: zenoh.Session) -> None:
        for stream in (
            "place",
            "tf",
            "scan/full",
            "graph",
            "graph/scene",
            "areas",
            "areas/scene",
            "diagnostics",
        ):
            self._pubs[stream] = publish_stream(session, self.robot, stream, stats=self.stats)
        for stream in (
            "dialogue/ask",
            "base/goal",
            "base/cmd",
            "people",
            "people/scene",
            "objects",
            "map/edit",
            "tf/map",
            "localization/pose",
            "localization/status",
        ):
            self._pubs[stream] = publish_stream(session, self.robot, stream, stats=self.stats)
        if self.config.laser.source in ("lms", "recording"):
            self._pubs["scan"] = publish_stream(session, self.robot, "scan", stats=self.stats)
        if self.config.laser.source == "recording":
            self._pubs["odom"] = publish_stream(session, self.robot, "odom", stats=self.stats)

    def _subscribe(
        self, session: zenoh.Session, stream: str, codec: Codec[T]
    ) -> Subscription[tuple[float, T]]:
        return Subscription(
            session,
            self.keys.stream(stream),
            _timed(codec),
            policy=Policy.DROP_OLDEST,
            capacity=SENSOR_QUEUE,
            stats=self.stats,
            name=stream,
        )

    # ------------------------------------------------------------------ run
    async def run(self, stop: asyncio.Event | None = None) -> AgentReport:
        """Run until ``stop`` is set; returns the report. Raises what made a task fail
        (after the same orderly shutdown)."""
        stop = stop or asyncio.Event()
        cfg = self.config
        self._started = time.monotonic()
        tasks: dict[str, asyncio.Task[Any]] = {}
        queryables: list[StateQueryable | RequestQueryable] = []
        failure: BaseException | None = None
        sink: McapSink | None = None
        recorder: Recorder | None = None
        session = self.session = open_session(cfg.bus)
        try:
            self.endpoints = listening_endpoints(session) if cfg.bus.picks_free_port else list(cfg.bus.listen)
            # until the saved map is loaded, queries and intents get "starting" (never an empty map)
            queryables = self._declare_starting(session)
            model, pipeline = await asyncio.to_thread(self._load)
            self.pipeline = pipeline
            self.concepts = await self._start_concepts()
            self._recogniser = await asyncio.to_thread(self._load_recogniser)
            self.dialogue = DialogueAgent(
                pipeline,
                self.concepts,
                can_recognise=self._recogniser is not None,
                follow_factory=self._follow_factory(),
                people=cfg.people.enabled,
                on_map_changed=self._map_changed,
                commit=self._commit_map,
            )
            self.dialogue.confirmed = set(self._saved_confirmed)
            # what the map already holds (a resumed map) goes to the concepts first
            self.dialogue.on_area_events(
                [AreaCreated(a.id, a.label, a.nodes) for a in pipeline.areas.areas.values()]
            )
            record_path = self._recording_path()
            if record_path is not None:
                sink = McapSink(record_path, overwrite=cfg.record.overwrite, metadata=self._metadata(model))
                recorder = Recorder(
                    session,
                    sink,
                    robot_wildcard(self.robot),
                    flush_interval=cfg.record.flush_interval,
                    stats=self.stats,
                )
                self._spawn(tasks, "recorder", recorder.run, restart=False)
                self.report.recording = str(record_path)
            if cfg.foxglove.on:
                from agent.live.server import start_live_view

                self.live = start_live_view(
                    cfg.foxglove, mount=self.params.mount, name=f"genius-loci {self.robot}"
                )
            self._declare(session)
            self._publish_state(pipeline.last_stamp or time.time(), force=True)
            self._update_concepts_cell()
            for cell in self._cells.values():
                cell.pending = NO_STATE
            await self._end_starting()
            self._start_dialogue(session, tasks)
            log.info(
                "answering: the map (%d nodes, %d areas) and the concepts are loaded, %.1f s after the start",
                len(pipeline.graph),
                len(pipeline.areas.areas),
                time.monotonic() - self._started,
            )
            if cfg.laser.source != "recording":  # a recording brings its own odometry
                self._odom_sub = self._subscribe(session, "odom", POSE_CODEC)
                self._spawn(tasks, "odometry", self._odometry_task)
            if cfg.laser.source == "lms":
                if not await self._start_lms(stop):
                    return self.report
                self._spawn(tasks, "laser", self._lms_task)
            elif cfg.laser.source == "recording":
                self._spawn(tasks, "laser", self._recording_task, restart=False)
            else:
                self._scan_sub = self._subscribe(session, "scan", LASER_SCAN_CODEC)
                self._spawn(tasks, "laser", self._scan_bus_task)
            if cfg.ros2.on:
                from agent.ros2.interface import Ros2Interface

                self._ros2 = Ros2Interface(cfg.ros2, session, self.robot, mount=self.params.mount)
                self._spawn(tasks, "ros2", self._ros2.run)
            self._spawn(tasks, "housekeeping", self._housekeeping_task)
            self._spawn(
                tasks,
                "diagnostics",
                lambda: publish_diagnostics(
                    self._pubs["diagnostics"],
                    self.stats,
                    self.robot,
                    period=cfg.diagnostics.period,
                    extra=self._extra,
                ),
            )
            if self._on_ready is not None:
                self._on_ready(self)
            stopper = asyncio.create_task(stop.wait(), name="stop")
            # a task that ends (its input closed) stops the agent; the recorder's end does not
            # (it ends when its file failed: the agent runs on without recording)
            watched = {t for name, t in tasks.items() if name != "recorder"}
            done, _ = await asyncio.wait({stopper, *watched}, return_when=asyncio.FIRST_COMPLETED)
            stopper.cancel()
            for t in done:
                if t is not stopper and not t.cancelled() and t.exception() is not None:
                    failure = t.exception()
                    log.error("the %s task failed: %s", t.get_name(), failure)
        finally:
            await self._shutdown(tasks, recorder, sink, queryables, session)
        if failure is not None:
            raise failure
        return self.report

    def _spawn(
        self,
        tasks: dict[str, asyncio.Task[Any]],
        name: str,
        start: Callable[[], Any],
        *,
        restart: bool = True,
    ) -> None:
        """Start a supervised task (see the module docstring)."""
        tasks[name] = asyncio.create_task(
            supervise(name, start, restarts=self.restarts, restart=restart, ratelog=self._ratelog),
            name=name,
        )

    async def _start_lms(self, stop: asyncio.Event) -> bool:
        from drivers.sick.driver import LMS2xx
        from drivers.threaded import ThreadedSource

        lc = self.config.laser
        angle, resolution = lc.angle_resolution
        assert lc.port is not None
        # the serial line is read and each scan stamped on a thread of its own: a scan that
        # takes long to process never delays reading the next ones (drivers/threaded.py)
        self._lms = ThreadedSource(
            LMS2xx(
                lc.port,
                baud=lc.baud,
                angle=angle,
                resolution=resolution,
                frame_id=lc.frame_id,
                timeout=lc.timeout,
            ),
            capacity=lc.queue_size,
            name="lms",
        )
        start = asyncio.create_task(self._lms.start(), name="laser start")
        stopper = asyncio.create_task(stop.wait())
        await asyncio.wait({start, stopper}, return_when=asyncio.FIRST_COMPLETED)
        stopper.cancel()
        if not start.done():
            start.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await start
            return False
        start.result()  # raises DeviceError/DeviceTimeout: nothing to run without the laser
        log.info("laser on %s: %s", lc.port, self._lms.info)
        return True

    # ------------------------------------------------------------------ tasks
    def _drain_odometry(self) -> None:
        sub = self._odom_sub
        if sub is None:
            return
        while (item := sub.try_recv()) is not None:
            self.loop.odom(item[1], item[0])

    def _feed_scan(self, scan: LaserScan, now: float) -> None:
        self._drain_odometry()
        self.report.scans_fed += 1
        self._last_scan_stamp = scan.stamp
        self.loop.scan(scan, now)

    async def _odometry_task(self) -> None:
        assert self._odom_sub is not None
        with contextlib.suppress(BusClosed):
            while True:
                for recv, pose in await self._odom_sub.recv_batch(SENSOR_QUEUE):
                    self.loop.odom(pose, recv)
                await _take_turns()

    async def _lms_task(self) -> None:
        pub = self._pubs["scan"]
        async for scan in self._lms:
            now = time.time()
            data = LASER_SCAN_CODEC.encode(scan)
            pub.put_bytes(data)
            # the bytes just published, decoded: the pipeline sees exactly what is recorded
            self._feed_scan(decode_laser_scan(data), now)
            await _take_turns()

    async def _recording_task(self) -> None:
        """``[laser] source = "recording"``: the file's scans and odometry, paced, through the
        sensor loop with their recorded arrival times (so the housekeeping's timeouts go by the
        recording's clock), each published on the bus as the robot's own first."""
        from agent.recording.feed import RecordingFeed

        lc = self.config.laser
        assert lc.recording is not None
        feed = RecordingFeed(lc.recording, speed=lc.speed, duration=lc.duration)
        self._clock = lambda: self._feed_time
        pub_scan, pub_odom = self._pubs["scan"], self._pubs["odom"]
        log.info("playing %s (robot %s) at %g x recorded speed", lc.recording, feed.robot, lc.speed)
        async for msg in feed:
            self._feed_time = msg.arrival
            if msg.kind == "odom":
                assert isinstance(msg.value, Pose2D)
                pub_odom.put_bytes(POSE_CODEC.encode(msg.value))
                self.loop.odom(msg.value, msg.arrival)
            else:
                assert isinstance(msg.value, LaserScan)
                pub_scan.put_bytes(LASER_SCAN_CODEC.encode(msg.value))
                self._feed_scan(msg.value, msg.arrival)
                await _take_turns()
        log.info(
            "the recording ended: %d scans, %d odometry messages (%d invalid)%s",
            feed.scans,
            feed.odometry,
            feed.invalid_scans + feed.invalid_odometry,
            f", cut at {lc.duration:g} s" if feed.cut else "",
        )

    async def _scan_bus_task(self) -> None:
        assert self._scan_sub is not None
        with contextlib.suppress(BusClosed):
            while True:
                for recv, scan in await self._scan_sub.recv_batch(SENSOR_QUEUE):
                    self._feed_scan(scan, recv)
                    await _take_turns()

    async def _housekeeping_task(self) -> None:
        interval = self.config.state.save_interval
        while True:
            await asyncio.sleep(TICK)
            self._drain_odometry()
            before = self.sync.stats.no_odometry
            self.loop.tick(self._clock())
            if self.sync.stats.no_odometry > before and time.monotonic() - self._warned_no_odom > 10.0:
                self._warned_no_odom = time.monotonic()
                log.warning(
                    "scans are waiting in vain for odometry on %s (%d dropped so far); is the base running?",
                    self.keys.odom,
                    self.sync.stats.no_odometry,
                )
            saving = self._save_task is not None and not self._save_task.done()
            if self._dirty and not saving and time.monotonic() - self._last_save >= interval:
                # on a task of its own: a save waits for the concepts (a reasoning may be running)
                self._save_task = asyncio.create_task(self._save(), name="save")
                self._save_task.add_done_callback(self._save_done)
            self._update_concepts_cell()
            if self.live is not None and self.live.watched:
                self.live.tick()
                if self.live.concepts_due():
                    with contextlib.suppress(Exception):  # names on the areas are a nicety
                        self.live.on_concepts(self.concepts.snapshot() if self.concepts is not None else None)

    # ------------------------------------------------------------------ per scan
    def _observe(self, m: Matched) -> None:
        """A scan left out by ``[laser] max_rate``: people, local map and doorways only."""
        assert self.pipeline is not None
        self.pipeline.observe(m.scan, m.pose)

    def _step(self, m: Matched) -> None:
        """One scan through the pipeline and out on the bus (the sensor loop's step)."""
        pipeline = self.pipeline
        assert pipeline is not None
        t0 = time.perf_counter()
        result = pipeline.process(m.scan, m.pose)
        self._publish(result)
        add_step(self.map, result)
        self._last_processed_stamp = m.scan.stamp
        self._process_ms.append((time.perf_counter() - t0) * 1e3)
        if self._ready is None and self.session is not None:
            # the map and the models are loaded, the kernels compiled, a scan went through
            self._ready = declare_ready(self.session, self.robot, "agent")
            log.info("ready: the first scan is processed (%s)", self.keys.ready("agent"))
        if pipeline.tracking_errors > self._tracking_errors:  # on the tracker's thread
            self._tracking_errors = pipeline.tracking_errors
            self._ratelog(
                "tracking",
                "pose tracking failed on a scan (%d so far; that scan keeps the correction before it): %s",
                pipeline.tracking_errors,
                pipeline.last_tracking_error,
            )
        self._age_ms.append((time.time() - result.stamp) * 1e3)
        for name, seconds in self._compiles.take():
            self.compiled.append(name)
            log.warning(
                "kernel %s was compiled while processing scan %d (%.2f s of the loop): "
                "the warm-up does not reach it (agent/core/warmup.py)",
                name,
                m.scan.seq,
                seconds,
            )

    def _step_failed(self, m: Matched, exc: Exception) -> None:
        """A scan the pipeline failed on: skipped (the loop counts it), said without flooding."""
        self.report.errors = self.loop.errors
        self._ratelog(
            "scan",
            "processing scan %d (stamp %.3f) failed (%d so far); it is skipped",
            m.scan.seq,
            m.scan.stamp,
            self.loop.errors,
            exc=exc,
        )

    def _publish(self, result: StepResult) -> None:
        self._cells["place"].set(place_message(result))
        place = self._cells["place"]()
        assert place is not None
        self._pubs["place"].put_bytes(place)
        self._pubs["tf"].put(frame_transform(result.pose, result.scan.frame_id))
        if result.correction is not None:  # [localization]: the map -> odom correction
            c = result.correction
            m2o = Pose2D(float(c[0]), float(c[1]), float(c[2]), stamp=result.stamp, frame_id="map")
            self._pubs["tf/map"].put(frame_transform(m2o, "odom"))
            self._publish_localization(result)
        assert self.pipeline is not None
        self._pubs["scan/full"].put(full_scan_message(result, self.pipeline.params.rear_beams.max_range))
        if result.people is not None:
            frame = result.people
            seen = bool(frame.legs.shape[0] or frame.tracks)
            if seen or self._people_shown:  # an empty frame once, to clear, then quiet
                people = frame.to_json("odom")
                self._pubs["people"].put(people)
                self._pubs["people/scene"].put(people_scene(people))
            self._people_shown = seen
        if result.graph_changed or result.areas_changed:
            self._publish_state(result.stamp)
        if result.state_changed:
            self._mark_dirty()
        for event in result.events:
            log.info("areas: %s", event)
        if self.live is not None:
            self.live.on_step(result)
        if self.dialogue is not None:
            if result.events:
                self.dialogue.on_area_events(result.events)
            p = result.pose
            for out in self.dialogue.on_scan(result.scan, (p.x, p.y, p.theta), result.people):
                self._send(out)

    def _publish_localization(self, result: StepResult) -> None:
        """``localization/pose`` every scan (the corrected pose, its covariance from the
        tracker's confidence) and ``localization/status`` when the confidence's state changes
        or the tracker reports an event (a correction, one undone); the dialogue hears it."""
        conf = result.localization
        if conf is None:
            return
        p, c = result.pose, result.correction
        assert c is not None
        s_t, s_r = conf.sigma
        self._pubs["localization/pose"].put(
            {
                "schema": "loci.pose/1",
                "stamp": result.stamp,
                "frame_id": "map",
                "x": p.x,
                "y": p.y,
                "theta": p.theta,
                "covariance": [s_t * s_t, 0.0, 0.0, 0.0, s_t * s_t, 0.0, 0.0, 0.0, s_r * s_r],
                "mode": "tracking",
                "map_to_odom": {"x": float(c[0]), "y": float(c[1]), "theta": float(c[2])},
            }
        )
        counts = self._localization_counts
        counts[conf.state] = counts.get(conf.state, 0) + 1
        if conf.event is not None:
            counts[conf.event] = counts.get(conf.event, 0) + 1
        if conf.event is None and self._last_confidence == conf.state:
            return
        if conf.state != self._last_confidence:
            log.log(
                logging.INFO if conf.certain else logging.WARNING,
                "localization: %s (the pose may be %.2f m off)%s",
                conf.state,
                s_t,
                f"; {conf.event} of {conf.deviation[0]:.2f} m" if conf.event else "",
            )
        self._last_confidence = conf.state
        self._pubs["localization/status"].put(
            {
                "schema": "loci.localization/1",
                "stamp": result.stamp,
                **conf.as_dict(),
                "pose": {"x": p.x, "y": p.y, "theta": p.theta},
            }
        )
        if self.dialogue is not None:
            self.dialogue.on_localization(conf)

    def _publish_state(self, stamp: float, *, force: bool = False) -> None:
        """Publish the graph and areas (messages and scenes) if they changed since the last time."""
        pipeline = self.pipeline
        assert pipeline is not None
        graph, areas = pipeline.messages(stamp)
        if force or self._last_graph is None or _body(graph) != _body(self._last_graph):
            self._last_graph = graph
            self._cells["graph"].set(graph)
            data = self._cells["graph"]()
            assert data is not None
            self._pubs["graph"].put_bytes(data)
            self._pubs["graph/scene"].put(graph_scene(graph))
        if force or self._last_areas is None or _body(areas) != _body(self._last_areas):
            self._last_areas = areas
            self._cells["areas"].set(areas)
            data = self._cells["areas"]()
            assert data is not None
            self._pubs["areas"].put_bytes(data)
            self._pubs["areas/scene"].put(areas_scene(areas, graph))
        if self.live is not None:
            self.live.on_state(self._last_graph, self._last_areas)

    async def _save_map(self, request: dict[str, Any]) -> dict[str, Any]:
        """``map/save``: the occupancy map of this run and its place labels into the folder the
        request names (:func:`~agent.core.map_files.save_map`); a copy of the counts is taken
        here, between two scans, and the grid is made and written on a worker thread.

        Raises:
            MapError: the folder is not an absolute path, is a file, already holds a map
                (without ``overwrite``), cannot be written; or no scan is in the map yet.
        """
        folder = Path(request["dir"])
        if not folder.is_absolute():
            raise MapError(
                f"{folder}: give the folder as an absolute path (a folder on the agent's computer; "
                "the agent's working directory is not yours)"
            )
        pipeline = self.pipeline
        if pipeline is None or self.map.lattice_origin is None:
            raise MapError(
                "no map yet: the agent has integrated no scan (is the laser running, and the odometry?)"
            )
        counts = self.map.copy()
        graph = self._last_graph or pipeline.messages()[0]
        overwrite = bool(request.get("overwrite", False))

        def write() -> tuple[Any, list[Path]]:
            grid = counts.grid(self.robot)
            return grid, save_map(folder, grid, graph, overwrite=overwrite)

        try:
            grid, files = await asyncio.to_thread(write)
        except OSError as exc:
            raise MapError(f"cannot save the map in {folder}: {exc}") from exc
        rows, cols = grid.shape
        log.info("saved the map (%d x %d cells, %d scans) in %s", cols, rows, counts.scans, folder)
        return {
            "schema": "loci.map_saved/1",
            "stamp": self._last_processed_stamp or time.time(),
            "dir": str(folder),
            "files": [str(f) for f in files],
            "frame_id": "map" if pipeline.tracker is not None else "odom",
            "resolution": grid.resolution,
            "origin": list(grid.origin),
            "width": cols,
            "height": rows,
            "scans": counts.scans,
        }

    # ------------------------------------------------------------------ dialogue, concepts, camera
    async def _start_concepts(self) -> Any:
        """The conceptual service when ``[conceptual]`` is on (started), else :class:`MemoryConcepts`.

        Raises:
            ConfigError: the service cannot run (no Java, the module missing); the message says why.
        """
        cc = self.config.conceptual
        if not cc.on:
            return MemoryConcepts()
        try:
            from agent.conceptual_service import ConceptualService
        except ImportError as exc:
            raise ConfigError(
                f"[conceptual] is on but the conceptual map cannot be loaded ({exc}); "
                "set conceptual.enabled = false to run without it"
            ) from exc
        import inspect

        kwargs: dict[str, Any] = {}
        if "debounce" in inspect.signature(ConceptualService).parameters:
            kwargs["debounce"] = cc.debounce
        service = ConceptualService(
            Path(cc.state), [Path(p) for p in cc.ontologies], cc.java or None, **kwargs
        )
        await service.start()
        log.info("conceptual map: %s", cc.state)
        return service

    async def _close_concepts(self) -> None:
        close = getattr(self.concepts, "close", None)
        if close is None or isinstance(self.concepts, MemoryConcepts):
            return
        try:
            await close()
        except Exception as exc:
            log.error("closing the conceptual map failed: %s", exc)

    def _load_recogniser(self) -> Any:
        """The object recogniser when the ``[objects]`` database folder exists (else None)."""
        folder = Path(self.config.objects.database)
        if not folder.is_dir():
            return None
        try:
            from knowledge.objects import ObjectDatabase, ObjectRecogniser, RecognitionParams
        except ImportError as exc:
            log.warning("object recognition is not available (%s); look_around will refuse", exc)
            return None
        try:
            params = RecognitionParams(min_inliers=self.config.objects.min_inliers)
        except TypeError:
            params = None
        recogniser = ObjectRecogniser(ObjectDatabase.open(folder), params)
        log.info("object recognition: %s", folder)
        return recogniser

    def _follow_factory(self) -> Callable[[], Any] | None:
        """Makes follow-me controllers with ``[follow]``'s parameters (None: agent.core.follow is missing)."""
        try:
            from agent.core.follow import FollowMe, FollowParams
        except ImportError:
            return None
        fc = self.config.follow
        try:
            params = FollowParams(distance=fc.distance, lost_after=fc.lost_after)
        except TypeError:
            log.warning(
                "agent.core.follow.FollowParams does not take distance/lost_after; using its defaults"
            )
            params = None
        return lambda: FollowMe(params)

    def _start_dialogue(self, session: zenoh.Session, tasks: dict[str, asyncio.Task[Any]]) -> None:
        assert self.dialogue is not None and self._intent_sub is not None
        self._status_sub = subscribe_stream(session, self.robot, "base/status", stats=self.stats)
        intent_stats = self.stats.stream("dialogue/intent")
        dialogue, intent_sub, status_sub = self.dialogue, self._intent_sub, self._status_sub
        self._spawn(
            tasks,
            "dialogue",
            lambda: run_dialogue(
                dialogue,
                intent_sub,
                status_sub,
                self._send,
                invalid=lambda: intent_stats.add("invalid"),
            ),
        )
        if self._recogniser is not None:
            # frames wait their turn (a busy agent recognises the same frames, later: the look
            # around chooses them by stamp); beyond 64 the oldest go, counted
            self._camera_sub = subscribe_stream(session, self.robot, "camera", capacity=64, stats=self.stats)
            self._spawn(tasks, "camera", self._camera_task)

    def _send(self, out: Outgoing) -> None:
        self._pubs[out.stream].put(out.message)
        if self.live is not None and out.stream.startswith("dialogue/"):
            self.live.on_say(out.stream, out.message)

    def _map_changed(self, edit: dict[str, Any]) -> None:
        """The dialogue changed the map (a false doorway removed): say so on ``map/edit`` (a
        recording keeps it, so a replay makes the same change after the same scan), publish
        the new map, save it soon."""
        message = {
            "schema": "loci.map_edit/1",
            "stamp": time.time(),
            **edit,
            "after_scan": self._last_processed_stamp,
        }
        try:
            self._pubs["map/edit"].put(message)
        except Exception:  # the map changed all the same; a replay will miss the edit
            log.exception("publishing the map edit %s failed", edit)
        self._publish_state(time.time())
        self._mark_dirty()

    def _update_concepts_cell(self) -> None:
        cell = self._cells.get("concepts")
        if cell is None or self.concepts is None:
            return
        try:
            snap = self.concepts.snapshot()
        except Exception as exc:
            log.debug("no concepts snapshot yet: %s", exc)
            return
        version = (snap.get("version"), snap.get("reasoned"))
        if version == self._concepts_version:
            return
        self._concepts_version = version
        try:
            cell.set({**snap, "schema": "loci.concepts/1", "stamp": time.time()})
        except ProtocolError as exc:
            log.error("the concepts snapshot is not a valid loci.concepts/1: %s", exc)

    async def _camera_task(self) -> None:
        """Recognise objects in the camera frames a look around chooses (by their stamps:
        :meth:`~agent.conversation.agent.DialogueAgent.frame_due`), in order.

        A frame is decoded off the event loop, and only if its header says it is no larger
        than ``[camera]``'s ``width`` x ``height`` (and its bytes fit such a frame); a larger
        or undecodable frame is counted ``invalid`` on ``camera`` and skipped.
        """
        assert self._camera_sub is not None and self.dialogue is not None
        cam = self.config.camera
        with contextlib.suppress(BusClosed):
            while True:
                frame = await self._camera_sub.recv()
                if frame.jpeg is None or not self.dialogue.frame_due(frame.stamp):
                    continue
                try:
                    image = await asyncio.to_thread(
                        decode_image, frame.jpeg, max_width=cam.width, max_height=cam.height
                    )
                except ProtocolError as exc:
                    self.stats.stream("camera").add("invalid")
                    self._ratelog(
                        "camera/frame", "camera: refused frame %d: %s", frame.seq, exc, level=logging.WARNING
                    )
                    self.dialogue.frame_done(frame.stamp)
                    continue
                try:
                    detections = await asyncio.to_thread(self._recogniser.recognise, image)
                except Exception as exc:
                    self._ratelog(
                        "camera/recognise", "object recognition failed on frame %d", frame.seq, exc=exc
                    )
                    self.dialogue.frame_done(frame.stamp)
                    continue
                for out in await self.dialogue.on_detections(detections, frame.stamp):
                    self._send(out)
                self.dialogue.frame_done(frame.stamp)

    async def _commit_map(self) -> None:
        """Return once every change of the map made so far is on disk (the dialogue awaits
        this before it acknowledges a fact about an area or an answer about a door: the area
        must survive a kill with the fact). A save already under way with an older state
        does not count: this one waits for it and writes again.

        Raises:
            DataError: the map could not be saved (the fact is not acknowledged).
        """
        if self.pipeline is None:
            return
        if self.dialogue is not None and frozenset(self.dialogue.confirmed) != self._saved_confirmed:
            self._mark_dirty()
        wanted = self._gen
        async with self._save_lock:
            if self._saved_gen >= wanted:
                return
            await self._save_locked()
        if self._saved_gen < wanted:
            raise DataError(f"the map could not be saved to {self.config.state.path}; see the log")

    def _save_done(self, task: asyncio.Task[None]) -> None:
        exc = None if task.cancelled() else task.exception()
        if exc is not None:
            self._ratelog("save", "saving the map to %s failed", self.config.state.path, exc=exc)

    async def _save(self) -> None:
        """Save the map (graph, areas, the doorways the tutor confirmed) to ``state.path``."""
        async with self._save_lock:
            await self._save_locked()

    async def _save_locked(self) -> None:
        pipeline = self.pipeline
        assert pipeline is not None
        confirmed = frozenset(self.dialogue.confirmed) if self.dialogue is not None else self._saved_confirmed
        meta = {
            "robot": self.robot,
            "confirmed_doorways": sorted(n for n in confirmed if n in pipeline.graph),
        }
        gen = self._gen  # the state as of now goes into the file
        text = persistence.dumps(pipeline.state_document(meta=meta)) + "\n"
        self._last_save = time.monotonic()
        if self.dialogue is not None and self.concepts is not None:
            try:  # the concepts first: they hold the area events of this map
                await self.dialogue.flush_area_events()
            except Exception as exc:  # the map is saved all the same; the concepts catch up later
                log.error("handing the area events to the concepts before saving failed: %s", exc)
        try:
            await asyncio.to_thread(atomic_write_text, self.config.state.path, text)
        except OSError as exc:
            log.error("saving the map to %s failed: %s", self.config.state.path, exc)
            return
        self._saved_gen = max(self._saved_gen, gen)
        self._saved_confirmed = confirmed
        self.report.saves += 1

    def _tracking_extra(self) -> dict[str, Any]:
        """``[localization]``: the tracker's own time per scan (off the per-scan path when it
        runs on its own thread) and the scans that had to wait for it."""
        pipeline = self.pipeline
        if pipeline is None or pipeline.tracker is None:
            return {}
        return {
            "tracking": {
                "ms": _percentiles(pipeline.tracking_ms),
                "lag": pipeline.params.tracking_lag,
                "waits": pipeline.tracking_waits,
                "errors": pipeline.tracking_errors,
                "confidence": dict(self._localization_counts),
            }
        }

    def _extra(self) -> dict[str, Any]:
        pipeline = self.pipeline
        out: dict[str, Any] = {
            "scans": {
                "fed": self.report.scans_fed,
                "processed": pipeline.scans if pipeline else 0,
                "over_rate": self.loop.over_rate,
            },
            "sync": self.sync.stats.as_dict(),
            "latency_ms": {"process": _percentiles(self._process_ms), "age": _percentiles(self._age_ms)},
            **self._tracking_extra(),
            "errors": self.loop.errors,
            "restarts": self.restarts.as_dict(),
            "saves": self.report.saves,
            "compiles": len(self.compiled),
        }
        if pipeline is not None:
            out["graph"] = {"nodes": len(pipeline.graph), "areas": len(pipeline.areas.areas)}
        if self._lms is not None:
            out["laser"] = {
                **self._lms.stats.as_dict(),
                "behind": self._lms.dropped,
                "waiting": self._lms.waiting,
            }
        return out

    # ------------------------------------------------------------------ shutdown
    async def _shutdown(
        self,
        tasks: dict[str, asyncio.Task[Any]],
        recorder: Recorder | None,
        sink: McapSink | None,
        queryables: list[StateQueryable | RequestQueryable],
        session: zenoh.Session,
    ) -> None:
        try:
            await self._end_starting()
            await self._stop_laser(tasks)
            # scans still waiting get their odometry (or time out) before anything else stops
            deadline = time.monotonic() + self.config.odometry.max_wait + 2 * TICK
            odometry = tasks.get("odometry")
            while (
                self.sync.pending
                and time.monotonic() < deadline
                and odometry is not None
                and not odometry.done()
            ):
                await asyncio.sleep(TICK / 2)
                self._drain_odometry()
                self.loop.tick(self._clock())
            for name in ("housekeeping", "diagnostics", "odometry", "dialogue", "camera", "ros2"):
                await _cancel(tasks.get(name))
            if self._ros2 is not None:
                self._ros2.close()
            for sub in (self._intent_sub, self._status_sub, self._camera_sub):
                if sub is not None:
                    sub.close()
            if self._odom_sub is not None:
                self._odom_sub.close()
            self.loop.close()
            if self._save_task is not None:
                await _cancel(self._save_task, wait_only=True)
            if self.pipeline is not None and (self._dirty or self.pipeline.scans):
                await self._save()  # with the area events handed to the concepts first
            await self._close_concepts()
            if self.pipeline is not None:
                self.pipeline.close()  # the tracker's thread, if it has one
            self._compiles.close()
            self._fill_report()
            with contextlib.suppress(Exception):
                if "diagnostics" in self._pubs:
                    final = {"scans_fed": self.report.scans_fed, "last_scan_stamp": self._last_scan_stamp}
                    self._pubs["diagnostics"].put(
                        diagnostics_message(self.stats, self.robot, extra={**self._extra(), "final": final})
                    )
            if recorder is not None:
                await asyncio.sleep(RECORD_GRACE)
                recorder.stop()
                await _cancel(tasks.get("recorder"), wait_only=True)
        finally:
            if sink is not None:
                sink.close()
                self.report.recorded = sink.messages
            if self._ready is not None:
                with contextlib.suppress(Exception):
                    self._ready.undeclare()
                self._ready = None
            for q in queryables:
                q.close()
            for pub in self._pubs.values():
                pub.close()
            if self.live is not None:
                self.live.close()
            close_session(session)
            self.session = None

    async def _stop_laser(self, tasks: dict[str, asyncio.Task[Any]]) -> None:
        await _cancel(tasks.get("laser"))
        if self._scan_sub is not None:
            self._scan_sub.close()
        if self._lms is not None:
            try:
                await asyncio.wait_for(self._lms.close(), 5.0)
            except Exception as exc:  # the port may be gone; the agent stops anyway
                log.warning("stopping the laser on %s: %s", self.config.laser.port, exc)

    def _fill_report(self) -> None:
        r = self.report
        snap = self.stats.snapshot()
        s = self.sync.stats
        r.scans_processed = self.pipeline.scans if self.pipeline else 0
        r.errors = self.loop.errors
        r.scans_over_rate = self.loop.over_rate
        r.restarts = self.restarts.as_dict()
        r.drops = {
            "driver": self._lms.stats.dropped + self._lms.dropped if self._lms is not None else 0,
            "scan_queue": snap.get("scan", {}).get("dropped", 0) if self._scan_sub is not None else 0,
            "odom_queue": snap.get("odom", {}).get("dropped", 0),
            **s.drops(),
        }
        r.sync = s.as_dict()
        r.invalid = {k: v["invalid"] for k, v in snap.items() if v.get("invalid")}
        if self.pipeline is not None:
            r.nodes = len(self.pipeline.graph)
            r.areas = len(self.pipeline.areas.areas)
        r.state_file = str(self.config.state.path)


def _body(message: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in message.items() if k != "stamp"}


async def _cancel(task: asyncio.Task[Any] | None, *, wait_only: bool = False) -> None:
    if task is None:
        return
    if not wait_only:
        task.cancel()
    with contextlib.suppress(asyncio.CancelledError, Exception):
        await task
