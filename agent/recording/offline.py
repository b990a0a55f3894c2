"""The agent's pipeline run offline on a recording: what ``loci replay`` and ``loci evaluate log`` do.


The recorded ``loci/<robot>/scan`` and ``loci/<robot>/odom`` messages go through the same
:class:`~agent.core.odom_sync.OdomSync` and :class:`~agent.core.pipeline.Pipeline` as in ``loci run``,
in file order, with the recorded arrival times (MCAP log times) standing in for the clock,
as fast as the CPU allows or, with ``--realtime``, at recorded speed. A recording made by
``loci run`` carries what the live run started from and ran with (metadata record ``loci``):
the initial map (a resumed run), the pipeline parameters, the model's path and hash, and
the odometry timeouts; the replay uses them, so it produces the graph and areas the live
run ended with. The live run's last diagnostics message (``extra.final``) names the last
scan it fed; later scans in the file (recorded while the agent was stopping) are skipped.
Changes of the map that scans do not explain — a doorway the tutor said was none — are
recorded as ``loci/<robot>/map/edit`` (``loci.map_edit/1``, naming the last scan processed
before the change); the replay makes each one again right after that scan, so a tour with a
clarification dialogue replays to the same map.

Messages that do not decode are counted and skipped, as the live subscriptions do. A file
whose writer crashed is replayed up to its last complete message, and the output says so.
"""

from __future__ import annotations

import json
import logging
import math
import struct
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Callable

    from agent.core.odom_sync import SyncParams
    from agent.core.pipeline import StepResult

log = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"


#: How long a replay of a recording that does not say how it was associated (an imported
#: log, a recording of foreign publishers) holds each scan so that late ones find their
#: place in stamp order (:class:`~agent.core.odom_sync.SyncParams` ``reorder``). Offline, holding
#: costs nothing.
FOREIGN_REORDER = 1.0


@dataclass
class ReplayOutcome:
    """What :func:`replay_recording` did.

    Every scan message of the robot in the file is accounted for exactly once:
    ``scans == processed + failed + sum(dropped.values()) + invalid_scans + skipped``
    (:meth:`accounting`).

    Attributes:
        pipeline: the pipeline after the last message (its graph, areas, documents).
        messages: scan and odometry messages read; scans, odometry: of each kind.
        invalid_scans, invalid_odometry: those that did not decode.
        skipped: scans after the live run's last one (see the module docstring).
        over_rate: scans left out by the recorded ``max_rate`` (as the robot left them out).
        errors: scans whose processing raised (logged; the scan is skipped, as live).
        truncated: the file ended without its footer (the writer crashed).
        cut: the replay stopped at its ``duration``, before the end of the file.
        live: the live run's final counters, if the recording has them.
        sync: the odometry association's counters; sync_params: its parameters.
        edits, edits_failed: recorded map edits made again, and those that did not fit.
    """

    pipeline: Any
    messages: int = 0
    scans: int = 0
    odometry: int = 0
    invalid_scans: int = 0
    invalid_odometry: int = 0
    skipped: int = 0
    over_rate: int = 0
    errors: int = 0
    edits: int = 0
    edits_failed: int = 0
    truncated: bool = False
    cut: bool = False
    resumed: bool = False
    live: dict[str, Any] | None = None
    sync: dict[str, int] = field(default_factory=dict)
    sync_params: dict[str, Any] = field(default_factory=dict)

    @property
    def invalid(self) -> int:
        return self.invalid_scans + self.invalid_odometry

    @property
    def processed(self) -> int:
        return int(self.pipeline.scans)

    def dropped(self) -> dict[str, int]:
        """The association's drop reasons with a count (reason → scans)."""
        from agent.core.odom_sync import DROP_REASONS

        return {r: int(self.sync.get(r, 0)) for r in DROP_REASONS if self.sync.get(r, 0)}

    def accounting(self) -> dict[str, Any]:
        """Where every scan went; ``balanced`` says that the parts add up to ``scans``."""
        dropped = self.dropped()
        parts = self.processed + self.errors + sum(dropped.values()) + self.invalid_scans + self.skipped
        parts += self.over_rate
        return {
            "scans": self.scans,
            "processed": self.processed,
            "failed": self.errors,
            "dropped": dropped,
            "invalid": self.invalid_scans,
            "skipped": self.skipped,
            "over_rate": self.over_rate,
            "balanced": parts == self.scans,
        }

    def stats(self) -> dict[str, Any]:
        return {
            "messages": self.messages,
            "scans": self.scans,
            "odometry": self.odometry,
            "invalid": self.invalid,
            "invalid_scans": self.invalid_scans,
            "invalid_odometry": self.invalid_odometry,
            "skipped": self.skipped,
            "over_rate": self.over_rate,
            "errors": self.errors,
            "edits": self.edits,
            "edits_failed": self.edits_failed,
            "processed": self.processed,
            "accounting": self.accounting(),
            "truncated": self.truncated,
            "resumed": self.resumed,
            "sync": self.sync,
            "sync_params": self.sync_params,
            "live": self.live,
        }


def read_recording_metadata(path: Path) -> dict[str, str]:
    """The ``loci`` metadata record of a recording ({} if it has none)."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    from knowledge.errors import DataError

    try:
        with path.open("rb") as f:
            if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
                raise DataError(f"{path}: not an MCAP file (it does not start with the MCAP magic bytes)")
            f.seek(0)
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Metadata) and record.name == "loci":
                    return dict(record.metadata)
                if isinstance(record, Message | Channel | Schema):
                    break
    except FileNotFoundError:
        raise DataError(f"{path}: no such recording") from None
    except (McapError, EOFError, ValueError, struct.error) as exc:
        log.debug("%s: no metadata read (%s)", path, exc)
    return {}


def _survey(path: Path) -> tuple[set[str], dict[str, dict[str, Any]], dict[str, list[dict[str, Any]]]]:
    """A first pass: the topics, the last ``extra.final`` of each diagnostics topic, and the
    map edits of each ``map/edit`` topic (in file order; invalid ones are logged and left out)."""
    from agent.bus.schemas import SCHEMAS
    from agent.recording.replay import McapMessages
    from knowledge.errors import ProtocolError

    topics: set[str] = set()
    finals: dict[str, dict[str, Any]] = {}
    edits: dict[str, list[dict[str, Any]]] = {}
    for msg in McapMessages(path):
        topics.add(msg.topic)
        if msg.topic.endswith("/map/edit"):
            try:
                edits.setdefault(msg.topic, []).append(SCHEMAS.decode(msg.data, "loci.map_edit/1"))
            except ProtocolError as exc:
                log.warning("%s: a map edit on %s is invalid and is not replayed: %s", path, msg.topic, exc)
            continue
        if msg.topic.endswith("/diagnostics"):
            try:
                doc = SCHEMAS.decode(msg.data, "loci.diagnostics/1")
            except ProtocolError:
                continue
            final = doc.get("extra", {}).get("final")
            if isinstance(final, dict):
                finals[msg.topic] = final
    return topics, finals, edits


def recorded_sync_params(meta: dict[str, str]) -> SyncParams | None:
    """The odometry association a recording was made with (None: it does not say)."""
    from agent.core.odom_sync import SyncParams

    if meta.get("sync"):
        return SyncParams.from_table(json.loads(meta["sync"]))
    if meta.get("max_wait") or meta.get("max_gap"):  # written before the full parameters were
        return SyncParams(max_wait=float(meta.get("max_wait", 0.2)), max_gap=float(meta.get("max_gap", 0.5)))
    return None


def replay_recording(
    path: str | Path,
    *,
    robot: str | None = None,
    model: Any = None,
    params: Any = None,
    sync: SyncParams | None = None,
    speed: float | None = None,
    fresh: bool = False,
    on_step: Callable[[StepResult], None] | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    on_pipeline: Callable[[Any], None] | None = None,
    duration: float | None = None,
) -> ReplayOutcome:
    """Replay a recording through the pipeline (see the module docstring).

    Args:
        path: the MCAP file (a ROS 2 bag in MCAP storage is imported with ``loci import``'s
            defaults into a temporary file first).
        robot: whose keys (default: the recording's metadata, else the only robot with scans).
        model: a loaded :class:`~knowledge.places.model.PlaceModel` (default: the recording's
            model file if it is there and has the recorded hash, else the bundled model).
        params: :class:`~agent.core.pipeline.PipelineParams` (default: the recording's).
        sync: :class:`~agent.core.odom_sync.SyncParams` (default: the recording's, else
            :data:`FOREIGN_REORDER` seconds of reordering and the other defaults).
        speed: None = as fast as possible, 1.0 = recorded speed.
        fresh: ignore the initial map the live run resumed from.
        on_step: called with each processed scan's :class:`~agent.core.pipeline.StepResult`.
        progress: ``progress(stage, done, total)`` over the scans (when the file says how many).
        on_pipeline: called once with the pipeline before the first message (the live view
            reads its graph and areas).
        duration: replay only the first seconds of the recording (the rest is not read).

    Raises:
        DataError: the file is missing or not MCAP, or has no scans of the robot.
    """
    from agent.bus.keys import RobotKeys
    from agent.core.odom_sync import SyncParams
    from agent.core.pipeline import Pipeline, PipelineParams
    from agent.core.sensor_loop import SensorLoop
    from agent.recording.feed import RecordingFeed
    from agent.recording.importer import as_loci_recording
    from knowledge.errors import DataError
    from knowledge.fileio import file_sha256
    from knowledge.places.model import PlaceModel, default_model_path

    p = as_loci_recording(Path(path))  # a ROS 2 bag (MCAP storage) is imported first
    meta = read_recording_metadata(p)
    topics, finals, all_edits = _survey(p)
    robot = robot or meta.get("robot")
    if not robot:
        robots = sorted({t.split("/")[1] for t in topics if t.startswith("loci/") and t.endswith("/scan")})
        if len(robots) != 1:
            raise DataError(
                f"{p}: name the robot to replay with --robot (scans of: {', '.join(robots) or 'none'})"
            )
        robot = robots[0]
    keys = RobotKeys(robot)
    if keys.scan not in topics:
        raise DataError(
            f"{p}: no {keys.scan} messages to replay (topics: {', '.join(sorted(topics)) or 'none'})"
        )
    if params is None:
        params = (
            PipelineParams.from_table(json.loads(meta["pipeline"]))
            if meta.get("pipeline")
            else PipelineParams()
        )
    if sync is None:
        sync = recorded_sync_params(meta) or SyncParams(reorder=FOREIGN_REORDER)
    if model is None:
        recorded = Path(meta["model"]) if meta.get("model") else None
        if recorded is not None and recorded.is_file() and file_sha256(recorded) == meta.get("model_sha256"):
            model = PlaceModel.load(recorded)
        else:
            if recorded is not None:
                log.warning(
                    "%s: the recorded model %s is not available as recorded; using the bundled one",
                    p,
                    recorded,
                )
            model = PlaceModel.load(default_model_path())
    initial = meta.get("initial_state")
    outcome_resumed = bool(initial) and not fresh
    if outcome_resumed:
        assert initial is not None
        pipeline = Pipeline.from_state(json.loads(initial), model, params)
    else:
        pipeline = Pipeline(model, params)
    live = finals.get(keys.diagnostics)
    last = live.get("last_scan_stamp") if live else None
    out = ReplayOutcome(pipeline=pipeline, resumed=outcome_resumed, live=live, sync_params=sync.to_table())
    feed = RecordingFeed(
        p,
        robot=robot,
        meta=meta,
        speed=speed,
        until=last if isinstance(last, int | float) else None,
        duration=duration,
    )
    total = _message_count(p, keys.scan)

    edits = deque(sorted(all_edits.get(keys.stream("map/edit"), []), key=_edit_order))

    def apply_edits(up_to: float | None) -> None:
        """Make the edits made after the scans up to ``up_to`` (a scan stamp; None: no scan yet)."""
        limit = -math.inf if up_to is None else up_to
        while edits and _edit_order(edits[0])[0] <= limit:
            edit = edits.popleft()
            if _apply_edit(pipeline, edit):
                out.edits += 1
            else:
                out.edits_failed += 1
                log.warning("%s: map edit %s does not fit the replayed map; not applied", p, edit)

    apply_edits(None)  # edits made before any scan was processed
    if on_pipeline is not None:
        on_pipeline(pipeline)

    def step(m: Any) -> None:
        apply_edits(pipeline.last_stamp)
        result = pipeline.process(m.scan, m.pose)
        if on_step is not None:
            on_step(result)

    def observe(m: Any) -> None:
        pipeline.observe(m.scan, m.pose)

    loop = SensorLoop(sync, step, max_rate=params.max_rate, observe=observe)
    try:
        for message in feed:
            loop.feed(message)
            if progress is not None and total and message.kind == "scan" and loop.scans % 50 == 0:
                progress("replay", feed.scans, total)
        loop.close()
    finally:
        pipeline.close()  # the tracker's thread, if it has one
    if progress is not None and total:
        progress("replay", feed.scans, total)
    apply_edits(pipeline.last_stamp)
    if edits and not feed.cut:
        log.warning("%s: %d map edits came after the last replayed scan; not applied", p, len(edits))
        out.edits_failed += len(edits)
    out.messages = feed.messages
    out.scans = feed.scans
    out.odometry = feed.odometry
    out.invalid_scans = feed.invalid_scans
    out.invalid_odometry = feed.invalid_odometry
    out.skipped = feed.skipped
    out.errors = loop.errors
    out.over_rate = loop.over_rate
    out.truncated = feed.truncated
    out.cut = feed.cut
    out.sync = loop.sync.stats.as_dict()
    return out


def _message_count(path: Path, topic: str) -> int | None:
    """How many messages the file's summary says ``topic`` has (None: no summary)."""
    from mcap.reader import make_reader

    try:
        with path.open("rb") as f:
            summary = make_reader(f).get_summary()
            if summary is None or summary.statistics is None:
                return None
            ids = [c.id for c in summary.channels.values() if c.topic == topic]
            return sum(summary.statistics.channel_message_counts.get(i, 0) for i in ids)
    except Exception:  # a truncated file has no summary; the progress bar then has no total
        return None


def _edit_order(edit: dict[str, Any]) -> tuple[float, float]:
    after = edit["after_scan"]
    return (-math.inf if after is None else float(after), float(edit.get("stamp") or 0.0))


def _apply_edit(pipeline: Any, edit: dict[str, Any]) -> bool:
    """Make one ``loci.map_edit/1`` on the pipeline's map; False when it does not apply."""
    from knowledge.navigation.graph import PLACE
    from knowledge.topology.consistency import remove_doorway

    node = edit["node"]
    if edit["op"] == "remove_doorway" and node in pipeline.graph and pipeline.graph.node(node).kind != PLACE:
        remove_doorway(pipeline.graph, pipeline.areas, node)
        return True
    return False


def summary_line(path: Path, res: ReplayOutcome) -> str:
    """One line that accounts for every scan of the recording (see :meth:`ReplayOutcome.accounting`)."""
    acc = res.accounting()
    pipeline = res.pipeline
    parts = [f"{acc['processed']} processed"]
    dropped = acc["dropped"]
    n_dropped = sum(dropped.values())
    parts.append(
        f"{n_dropped} dropped"
        + (f" ({', '.join(f'{k} {v}' for k, v in dropped.items())})" if dropped else "")
    )
    for key, word in (("invalid", "invalid"), ("failed", "failed"), ("skipped", "after the live run's end")):
        if acc[key]:
            parts.append(f"{acc[key]} {word}")
    s = res.sync
    odom_notes = [
        f"{n} {word}"
        for n, word in (
            (res.invalid_odometry, "invalid"),
            (s.get("odom_out_of_order", 0), "out of order"),
            (s.get("odom_future", 0), "stamped in the future"),
        )
        if n
    ]
    line = (
        f"replayed {path}: {acc['scans']} scans = {' + '.join(parts)}; "
        f"{res.odometry} odometry messages"
        + (f" ({', '.join(odom_notes)} ignored)" if odom_notes else "")
        + f"; {len(pipeline.graph)} nodes, {len(pipeline.areas.areas)} areas"
        + (" (continuing the map the live run resumed)" if res.resumed else "")
        + (f"; {res.edits} map edits made again" if res.edits else "")
        + (f" ({res.edits_failed} did not fit)" if res.edits_failed else "")
    )
    if not acc["balanced"]:  # a bug, not bad data: say so rather than print a sum that does not add up
        log.error("the replay's scan accounting does not add up: %s", acc)
    return line
