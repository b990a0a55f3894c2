"""``loci import``: a real robot log into the MCAP recording ``loci record`` would have made.

The output has what a recording of the robot's bus has: ``loci/<robot>/scan``
(``foxglove.LaserScan``), ``loci/<robot>/odom`` (``foxglove.PoseInFrame``) and, when the log
has them, reference poses on ``loci/<robot>/pose/truth`` (``foxglove.PoseInFrame``, frame
``map``), written through :class:`~agent.recording.recorder.McapSink` as
:class:`~agent.bus.bridge.RawSample` s: MCAP log time = when the message was logged
(received), the message's own stamp inside it. The ``loci`` metadata record names the
robot, the source file and its format, the choices the import made, and the pipeline
parameters of a default run with the log's laser mount (``pipeline``), so ``loci replay``
places the laser where it was.

Inputs (:func:`detect_format`): CARMEN logs, plain or gzipped (:mod:`agent.recording.carmen`),
ROS 1 bags and ROS 2 bags in sqlite3 or MCAP storage (a bag directory, a ``.db3`` or a
``.mcap`` file; :mod:`agent.recording.rosbag`, read with ``rosbags``). Damaged input is
counted and warned about and never stops the import unless ``strict``
(:mod:`agent.recording.imported`). The file is written as ``OUT.partial`` and renamed when
complete, so a stopped import leaves no file that looks finished.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import logging
import math
import re
import tempfile
import time
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agent.bus.bridge import RawSample
from agent.bus.codecs import LASER_SCAN_CODEC, POSE_CODEC
from agent.bus.keys import robot_name, robot_wildcard, stream_key
from agent.recording.carmen import CarmenConverter, CarmenOptions, Survey
from agent.recording.imported import SCAN, ImportStats, Output, Skip, Warnings
from agent.recording.recorder import McapSink, recording_metadata
from agent.recording.rosbag import RosOptions
from knowledge.errors import ConfigError, DataError

log = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"
ROSBAG1_MAGIC = b"#ROSBAG V2.0"
SQLITE_MAGIC = b"SQLite format 3\x00"
GZIP_MAGIC = b"\x1f\x8b"

#: Input formats by name (``--format``).
FORMATS = ("auto", "carmen", "ros1", "ros2")

Progress = Callable[[str, int, int], None]


def detect_format(path: Path) -> str:
    """``carmen``, ``ros1`` or ``ros2`` from a file's first bytes (a directory with a
    ``metadata.yaml`` is a ROS 2 bag).

    Raises:
        DataError: missing, one of our own recordings, or not a format the importer reads.
    """
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return "ros2"
        raise DataError(f"{path}: a directory without metadata.yaml is not a ROS 2 bag")
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    with path.open("rb") as f:
        head = f.read(64)
    if head.startswith(ROSBAG1_MAGIC):
        return "ros1"
    if head.startswith(SQLITE_MAGIC):
        return "ros2"
    if head.startswith(MCAP_MAGIC):
        if is_ros2_mcap(path):
            return "ros2"
        raise DataError(
            f"{path}: an MCAP file that is not a ROS 2 bag (a loci recording? replay it directly)"
        )
    if head.startswith(GZIP_MAGIC):
        return "carmen"
    text = head.decode("ascii", errors="replace")
    if head and all(c.isprintable() or c in "\r\n\t" for c in text):
        return "carmen"
    raise DataError(
        f"{path}: not a CARMEN log (text or gzip), ROS 1 bag, ROS 2 bag (.db3, .mcap, or a "
        "directory with metadata.yaml); give --format if it is one"
    )


def is_ros2_mcap(path: Path) -> bool:
    """Whether an MCAP file is a ROS 2 bag: header profile ``ros2``, or a channel with
    ``cdr`` messages before any message (our recordings have neither)."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Header, Message
    from mcap.stream_reader import StreamReader

    try:
        with path.open("rb") as f:
            if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
                return False
            f.seek(0)
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Header) and record.profile == "ros2":
                    return True
                if isinstance(record, Channel):
                    return record.message_encoding == "cdr"
                if isinstance(record, Message):
                    return False
    except (McapError, OSError, EOFError, ValueError):
        return False
    return False


def default_robot(path: Path) -> str:
    """A robot name from a file name: ``freiburg-079-corrected.log.gz`` → ``freiburg-079-corrected``."""
    name = path.name
    for suffix in (".gz", ".log", ".clf", ".txt", ".bag", ".mcap", ".db3"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
    name = re.sub(r"[^A-Za-z0-9_.-]", "-", name).strip("-.") or "robot"
    if not name[0].isalnum():
        name = "r" + name
    return name[:63]


@dataclass
class ImportResult:
    """What :func:`import_log` did.

    Attributes:
        source, output: the files; format: ``carmen``, ``ros1`` or ``ros2``.
        robot: the robot name of the keys; mount: the laser's mount (x, y, yaw).
        stats: the books (:class:`~agent.recording.imported.ImportStats`).
        seconds: wall time of the import; metadata: the ``loci`` metadata record written.
        warnings: reason → bad-input warnings (shown or not).
        choices: what the import chose (clock, sources, topics) and why, for the summary.
    """

    source: Path
    output: Path
    format: str
    robot: str
    mount: tuple[float, float, float]
    stats: ImportStats
    seconds: float = 0.0
    metadata: dict[str, str] = field(default_factory=dict)
    warnings: dict[str, int] = field(default_factory=dict)
    choices: dict[str, str] = field(default_factory=dict)

    @property
    def scans_per_second(self) -> float:
        return self.stats.written[SCAN] / self.seconds if self.seconds > 0 else math.inf

    def as_dict(self) -> dict[str, Any]:
        return {
            "source": str(self.source),
            "output": str(self.output),
            "format": self.format,
            "robot": self.robot,
            "mount": list(self.mount),
            "seconds": round(self.seconds, 3),
            "scans_per_second": round(self.scans_per_second, 1) if self.seconds > 0 else None,
            "stats": self.stats.as_dict(),
            "warnings": dict(sorted(self.warnings.items())),
            "choices": self.choices,
        }

    def summary(self) -> str:
        unit = "lines" if self.format == "carmen" else "messages"
        return (
            f"imported {self.source.name} ({self.format}) into {self.output}: {self.stats.summary(unit)}; "
            f"{self.seconds:.2f} s ({self.scans_per_second:,.0f} scans/s)"
        )


class _Writer:
    """Outputs → RawSamples → McapSink (keys of one robot)."""

    def __init__(self, sink: McapSink, robot: str) -> None:
        self.sink = sink
        self.keys = {s: stream_key(robot, s) for s in ("scan", "odom", "pose/truth")}

    def write(self, out: Output) -> None:
        if out.stream == SCAN:
            codec: Any = LASER_SCAN_CODEC
        else:
            codec = POSE_CODEC
        self.sink.write(
            RawSample(
                key=self.keys[out.stream],
                payload=codec.encode(out.message),
                encoding=codec.zenoh_encoding,
                recv_ns=round(out.log_time * 1e9),
            )
        )


def _sha256(path: Path) -> str:
    if path.is_dir():
        return ""
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def import_log(
    source: str | Path,
    output: str | Path,
    *,
    fmt: str = "auto",
    robot: str | None = None,
    overwrite: bool = False,
    strict: bool = False,
    carmen: CarmenOptions | None = None,
    ros: RosOptions | None = None,
    progress: Progress | None = None,
    emit: Callable[[str], None] | None = None,
    warn_limit: int = 3,
) -> ImportResult:
    """Import a CARMEN log or a ROS bag into an MCAP recording (see the module docstring).

    Args:
        fmt: ``auto`` (:func:`detect_format`), ``carmen``, ``ros1`` or ``ros2``.
        robot: the robot name of the keys (default: from the file name).
        overwrite: replace an existing output.
        strict: the first bad input is a :class:`DataError` (and no output is left).
        progress: ``progress(stage, done, total)`` callback.
        emit: where warnings go (default: this module's logger).
        warn_limit: warnings shown per reason before they are only counted.

    Raises:
        DataError: unreadable input, an existing output, or (``strict``) bad input.
        ConfigError: topics or options that do not fit the input.
    """
    src, out = Path(source), Path(output)
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    kind = detect_format(src) if fmt == "auto" else fmt
    if out.exists() and not overwrite:
        raise DataError(f"{out} exists; choose another name or allow overwriting (--force)")
    if out.resolve() == src.resolve():
        raise DataError(f"{out}: the output would overwrite the input")
    name = robot_name(robot or default_robot(src))
    warnings = Warnings(emit or log.warning, limit=warn_limit, strict=strict)
    partial = out.with_name(out.name + ".partial")
    t0 = time.perf_counter()
    try:
        if kind == "carmen":
            result = _import_carmen(src, partial, name, carmen or CarmenOptions(), warnings, progress)
        else:
            result = _import_bag(src, partial, name, kind, ros or RosOptions(), warnings, progress)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    partial.replace(out)
    warnings.finish()
    result.output = out
    result.seconds = time.perf_counter() - t0
    result.warnings = dict(warnings.counts)
    return result


def _metadata(
    robot: str, src: Path, kind: str, mount: tuple[float, float, float], extra: dict[str, str]
) -> dict[str, str]:
    from agent.core.pipeline import PipelineParams

    return recording_metadata(
        robot,
        key=robot_wildcard(robot),
        writer="loci import",
        pipeline=json.dumps(PipelineParams(mount=mount).to_table(), sort_keys=True),
        source=str(src.resolve()),
        source_format=kind,
        source_sha256=_sha256(src),
        **extra,
    )


# ---- CARMEN --------------------------------------------------------------------------------


def _carmen_lines(
    path: Path, stats: ImportStats | None, warn: Callable[[str, str], None] | None
) -> Iterator[tuple[int, str, int]]:
    """``(line number, text, bytes of the file read)`` of a plain or gzipped CARMEN log, blank
    lines left out; a truncated or corrupt file ends the lines (counted in ``stats``)."""
    with path.open("rb") as raw:
        gz = raw.read(2) == GZIP_MAGIC
        raw.seek(0)
        f: Any = gzip.GzipFile(fileobj=raw, mode="rb") if gz else raw
        number = 0
        try:
            for number, data in enumerate(f, 1):
                try:
                    text = data.decode("utf-8")
                except UnicodeDecodeError:
                    text = data.decode("latin-1")
                if text.strip():
                    yield number, text, raw.tell()
        except EOFError:
            if stats is not None and warn is not None:
                stats.file_errors["truncated_file"] += 1
                warn(
                    "truncated_file",
                    f"{path}: the file ends early (truncated gzip stream) after line {number}",
                )
        except (OSError, zlib.error) as exc:
            if stats is not None and warn is not None:
                stats.file_errors["corrupt_file"] += 1
                warn("corrupt_file", f"{path}: unreadable after line {number} ({exc})")


def _import_carmen(
    src: Path, dst: Path, robot: str, options: CarmenOptions, warnings: Warnings, progress: Progress | None
) -> ImportResult:
    survey = Survey()
    for _, text, _ in _carmen_lines(src, None, None):
        survey.add(text)
    try:
        conv = CarmenConverter(
            survey, options, warn=lambda reason, text: warnings(reason, f"{src.name} {text}")
        )
    except ValueError as exc:
        raise DataError(f"{src}: {exc}") from exc
    stats = ImportStats()
    meta = _metadata(robot, src, "carmen", conv.mount, conv.describe())
    total = src.stat().st_size
    with McapSink(dst, overwrite=True, metadata=meta) as sink:
        writer = _Writer(sink, robot)
        for number, text, done in _carmen_lines(src, stats, warnings):
            outcome = conv.convert(number, text)
            stats.add(outcome)
            if isinstance(outcome, Skip):
                if outcome.detail:
                    warnings(outcome.reason, f"{src.name} {outcome.detail}")
                continue
            for o in outcome:
                writer.write(o)
            if progress is not None and number % 2000 == 0:
                progress("import", done, total)
        if progress is not None:
            progress("import", total, total)
    stats.notes.update(conv.notes)
    stats.beams.update(conv.beams)
    stats.unknown_types.update(conv.unknown)
    choices = {
        "laser": str(conv.laser),
        "scan_lines": conv.source,
        "odometry": conv.odometry,
        "clock": conv.clock_why,
    }
    return ImportResult(src, dst, "carmen", robot, conv.mount, stats, metadata=meta, choices=choices)


# ---- ROS bags ------------------------------------------------------------------------------


def _open_bag(src: Path, kind: str) -> Any:
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag2 import Reader as Reader2

    try:
        reader: Any = Reader1(src) if kind == "ros1" else Reader2(src)
        reader.open()
    except Exception as exc:  # rosbags raises its own errors, and OSError, KeyError on damage
        raise DataError(f"{src}: cannot open as a {kind.upper().replace('ROS', 'ROS ')} bag: {exc}") from exc
    return reader


def _typestore(reader: Any, kind: str, wanted: set[str], warnings: Warnings) -> tuple[Any, set[str]]:
    """A typestore for the connections of ``wanted`` topics, from the bag's own message
    definitions (a type rosbags does not know still reads), else from rosbags' store of the
    ROS version; returns it and the topics it cannot read."""
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    default = get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.LATEST)
    unreadable: set[str] = set()
    for conn in reader.connections:
        if conn.topic not in wanted:
            continue
        fmt, data = conn.msgdef.format, conn.msgdef.data
        try:
            if fmt == MessageDefinitionFormat.MSG and data:
                store.register(get_types_from_msg(data, conn.msgtype))
            elif fmt == MessageDefinitionFormat.IDL and data:
                sep = "=" * 80 + "\n"
                parts = data.split(sep)[1:] if data.startswith(f"{sep}IDL: ") else [data]
                for part in parts:
                    idl = part.split("\n", 1)[1] if part.startswith("IDL: ") else part
                    store.register(get_types_from_idl(idl))
        except Exception as exc:  # a definition rosbags cannot parse: try its own store
            log.info("%s: the bag's definition of %s does not parse (%s)", conn.topic, conn.msgtype, exc)
    missing = {k: v for k, v in default.fielddefs.items() if k not in store.fielddefs}
    store.register(missing)
    for conn in reader.connections:
        if conn.topic in wanted and conn.msgtype not in store.fielddefs:
            unreadable.add(conn.topic)
            warnings(
                "unknown_message_type",
                f"topic {conn.topic}: message type {conn.msgtype} has no definition in the bag nor in "
                "rosbags' store; its messages are skipped",
            )
    return store, unreadable


def _import_bag(
    src: Path,
    dst: Path,
    robot: str,
    kind: str,
    options: RosOptions,
    warnings: Warnings,
    progress: Progress | None,
) -> ImportResult:
    from agent.recording import rosbag as rb

    reader = _open_bag(src, kind)
    try:
        topics = {c.topic: c.msgtype for c in reader.connections}
        scan_topic, odom_topic = rb.choose_topics(topics, options.scan_topic, options.odom_topic)
        store, unreadable = _typestore(reader, kind, {scan_topic, odom_topic, rb.TF, rb.TF_STATIC}, warnings)
        if scan_topic in unreadable or (odom_topic in unreadable):
            raise DataError(
                f"{src}: cannot read the messages of {scan_topic} or {odom_topic} (see the warnings)"
            )
        deser = store.deserialize_ros1 if kind == "ros1" else store.deserialize_cdr

        def decode(conn: Any, raw: bytes) -> Any:
            return deser(raw, conn.msgtype)

        # first pass over the frames: the base, the laser and the mount between them
        tf = rb.TfBuffer()
        base, odom_frame, laser = options.base_frame, options.odom_frame, options.laser_frame
        mount: rb.Mount | None = rb.Mount(options.mount) if options.mount is not None else None
        look = [c for c in reader.connections if c.topic in {scan_topic, odom_topic, rb.TF, rb.TF_STATIC}]
        for conn, _, raw in reader.messages(connections=look):
            try:
                msg = decode(conn, raw)
            except Exception:
                continue
            if conn.topic == scan_topic:
                laser = laser or rb.frame(msg.header.frame_id) or "laser"
            elif conn.topic in (rb.TF, rb.TF_STATIC):
                try:
                    tf.add(msg)
                except rb.BadMessage:
                    continue
            if conn.topic == odom_topic and odom_topic != rb.TF:
                base = base or rb.frame(msg.child_frame_id)
                odom_frame = odom_frame or rb.frame(msg.header.frame_id)
            if laser and (base or odom_topic == rb.TF) and mount is None:
                mount = tf.mount(base or "base_link", laser)
            if laser and base and odom_frame and mount is not None:
                break
        base = base or "base_link"
        odom_frame = odom_frame or "odom"
        laser = laser or "laser"
        if mount is None:
            mount = tf.mount(base, laser)
        if mount is None:
            mount = rb.Mount((0.0, 0.0, 0.0))
            warnings(
                "no_mount",
                f"{src.name}: /tf and /tf_static do not connect {base} to {laser}; the laser is taken "
                "to sit at the base's origin facing forwards (give --mount X Y YAW, or --base-frame/--laser-frame)",
            )
        conv = rb.RosConverter(
            scan_topic,
            odom_topic,
            base_frame=base,
            odom_frame=odom_frame,
            mount=mount,
            laser_frame=laser,
            warn=lambda reason, text: warnings(reason, f"{src.name} {text}"),
        )
        stats = ImportStats()
        choices = {
            "scan_topic": scan_topic,
            "odom_topic": odom_topic,
            "base_frame": base,
            "odom_frame": odom_frame,
            "laser_frame": laser,
            "flipped": str(mount.flipped).lower(),
        }
        storage = "ros1" if kind == "ros1" else f"ros2-{'mcap' if _is_mcap_bag(src) else 'sqlite3'}"
        meta = _metadata(robot, src, storage, mount.pose, {f"ros_{k}": v for k, v in choices.items()})
        total = int(reader.message_count) or 1
        used = conv.topics()
        with McapSink(dst, overwrite=True, metadata=meta) as sink:
            writer = _Writer(sink, robot)
            index = 0
            try:
                for index, (conn, t_ns, raw) in enumerate(reader.messages(), 1):
                    if conn.topic not in used or conn.topic in unreadable:
                        outcome: Any = Skip("other_topic")
                    else:
                        try:
                            msg = decode(conn, raw)
                        except Exception as exc:
                            outcome = Skip("corrupt_message", f"message {index} on {conn.topic}: {exc}")
                        else:
                            outcome = conv.convert(index, conn.topic, t_ns * 1e-9, msg)
                    stats.add(outcome)
                    if isinstance(outcome, Skip):
                        if outcome.detail:
                            warnings(outcome.reason, f"{src.name} {outcome.detail}")
                    else:
                        for o in outcome:
                            writer.write(o)
                    if progress is not None and index % 1000 == 0:
                        progress("import", index, total)
            except DataError:
                raise
            except Exception as exc:  # a damaged bag: keep what was read
                stats.file_errors["corrupt_file"] += 1
                warnings("corrupt_file", f"{src}: unreadable after message {index} ({exc})")
            if progress is not None:
                progress("import", total, total)
        for k, v in conv.notes.items():
            stats.notes[k] += v
    finally:
        reader.close()
    return ImportResult(src, dst, kind, robot, mount.pose, stats, metadata=meta, choices=choices)


def _is_mcap_bag(src: Path) -> bool:
    if src.is_dir():
        return any(p.suffix == ".mcap" for p in src.iterdir())
    return src.suffix == ".mcap"


# ---- a ROS 2 MCAP given to loci replay -----------------------------------------------------

_TEMP_DIRS: list[tempfile.TemporaryDirectory[str]] = []


def as_loci_recording(path: Path) -> Path:
    """``path`` itself for a loci recording; a ROS 2 bag in MCAP storage is imported first
    into a temporary file (removed when the process ends), which is returned."""
    if not (path.is_file() and is_ros2_mcap(path)):
        return path
    tmp = tempfile.TemporaryDirectory(prefix="loci-import-")
    _TEMP_DIRS.append(tmp)
    out = Path(tmp.name) / (default_robot(path) + ".mcap")
    result = import_log(path, out, fmt="ros2")
    log.warning("%s is a ROS 2 bag: imported it first (%s)", path, result.stats.summary())
    return out


def check_options_for(kind: str, carmen_given: bool, ros_given: bool) -> None:
    """Options of one input kind given for the other are a ConfigError."""
    if kind == "carmen" and ros_given:
        raise ConfigError(
            "--scan-topic, --odom-topic and the frame options are for ROS bags, not CARMEN logs"
        )
    if kind != "carmen" and carmen_given:
        raise ConfigError(
            "--laser, --beam-angles, --odometry, --truth, --clock, --period and --sick-codes are for "
            "CARMEN logs, not ROS bags"
        )
