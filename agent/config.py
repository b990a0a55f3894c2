"""The agent's configuration: a TOML file made into frozen dataclasses.

``loci run --config robot.toml`` reads one file; every key has a default, so an empty file
(or none) is a valid configuration. Values are taken, highest precedence first, from

1. the command line (``--robot``, ``--record``, ``--state-dir``, ``--model``),
2. the environment (:data:`ENV_VARS`: ``LOCI_ROBOT``, ``LOCI_LASER_PORT``, ...),
3. the file,
4. the defaults below.

Unknown sections and keys are a :class:`~knowledge.errors.ConfigError` that names them, as
are values of the wrong type (``node_distance = "1"``) or out of range. Relative paths in
the file (``places.model``, ``state.dir``, ``record.path``) are relative to the file's
folder; from the environment or the command line, to the working directory.

Sections (docs/agent.md lists every key):

``[robot]`` name; ``[bus]`` :class:`~agent.bus.session.BusConfig`; ``[laser]`` the LMS on a
serial port or scans from the bus, and the laser's mount on the robot; ``[odometry]`` how
scans wait for odometry; ``[places]`` the place model and the label window N;
``[navigation]`` (and ``[navigation.doorways]``) the graph and the doorway detector;
``[local_map]``, ``[rear_beams]`` the 360° scan of a front laser (Sect. 3.5); ``[state]``
where the graph persists; ``[record]`` an optional MCAP recording; ``[diagnostics]``;
``[camera]`` the camera's frames; ``[conceptual]`` the conceptual map (OWL, reasoner);
``[objects]`` the object database of the recogniser; ``[follow]`` follow-me; ``[people]``
people detection in every scan and the masking of their legs; ``[foxglove]`` the live view
(:mod:`agent.live`); ``[ros2]`` the ROS 2 interface over Zenoh (:mod:`agent.ros2`);
``[localization]`` pose tracking by scan matching (off unless configured).
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from agent.bus.keys import robot_name
from agent.bus.session import DEFAULT_AGENT_ENDPOINT, BusConfig
from agent.core.odom_sync import SyncParams
from agent.live.config import FoxgloveConfig
from agent.ros2.config import Ros2Config
from agent.tables import build_dataclass
from knowledge.errors import ConfigError
from knowledge.metric.local_map import LocalMapParams
from knowledge.metric.rear_beams import FullScanParams
from knowledge.navigation.doorways import DoorwayParams
from knowledge.navigation.graph import GraphParams

T = TypeVar("T")

#: LMS 2xx variants (scan angle in degrees, angular resolution in degrees) the driver reads.
LMS_VARIANTS = ("180/1", "180/0.5", "100/1", "100/0.5", "100/0.25")


def _split_list(text: str) -> list[str]:
    return [p.strip() for p in text.split(",") if p.strip()]


def env_vars(sections: Mapping[str, type]) -> dict[str, tuple[str, str, Callable[[str], Any]]]:
    """Environment variable → (section, key, parser of its text), from the ``env`` metadata of
    the configuration's fields: the one place a variable is named, so code and units agree."""
    out: dict[str, tuple[str, str, Callable[[str], Any]]] = {}
    for section, cls in sections.items():
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            var = f.metadata.get("env")
            if var:
                many = typing.get_origin(hints[f.name]) in (tuple, list)
                out[var] = (section, f.name, _split_list if many else str)
    return out


CONFIG_ENV = "LOCI_CONFIG"

# keys holding paths, resolved against the config file's folder when they come from it
_PATH_KEYS = {
    ("places", "model"),
    ("state", "dir"),
    ("record", "path"),
    ("conceptual", "state"),
    ("objects", "database"),
    ("people", "model"),
    ("foxglove", "labels"),
}
# keys holding lists of paths, resolved the same way
_PATH_LIST_KEYS = {("conceptual", "ontologies")}


# ---------------------------------------------------------------------------- sections


@dataclass(frozen=True)
class RobotConfig:
    """``[robot]``: ``name`` is the second chunk of every key (default: the host name)."""

    name: str = field(default="", metadata={"env": "LOCI_ROBOT"})

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", robot_name(self.name or None))


@dataclass(frozen=True)
class Mount:
    """``[laser.mount]``: the laser's pose on the robot: ``x``, ``y`` metres (x forward,
    y left of the odometry reference point), ``yaw`` degrees (counter-clockwise)."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in (self.x, self.y, self.yaw)):
            raise ValueError(f"the mount pose must be finite, got ({self.x}, {self.y}, {self.yaw})")

    @property
    def pose(self) -> tuple[float, float, float]:
        """``(x, y, yaw)`` in metres, metres, radians."""
        return (self.x, self.y, math.radians(self.yaw))


#: Where the agent's scans come from (``[laser] source``).
LASER_SOURCES = ("lms", "bus", "recording")


@dataclass(frozen=True)
class LaserConfig:
    """``[laser]``: where scans come from.

    Attributes:
        source: ``"lms"`` (a SICK LMS 2xx on ``port``, read by the agent, which publishes each
            scan on ``loci/<robot>/scan``), ``"bus"`` (subscribe ``loci/<robot>/scan``) or
            ``"recording"`` (the scans *and the odometry* of the MCAP file ``recording``, at
            ``speed`` times recorded speed, through the live agent: published on the bus as
            the robot's own, with their recorded arrival times, so the run gives what
            ``loci replay`` gives, at any speed; the agent stops at the file's end).
            Default: ``"lms"`` when ``port`` is set, else ``"recording"`` when ``recording``
            is, else ``"bus"``.
        port: the scanner's serial device or pyserial URL (``/dev/ttyUSB0``,
            ``socket://host:4001``, the path ``loci sim lms`` prints).
        baud: session baud rate (9600, 19200, 38400, 500000); omitted: 500000 if the port
            takes it, else 38400.
        variant: ``"ANGLE/RESOLUTION"`` in degrees (``"180/0.5"``), or ``"keep"`` (the
            scanner's own). The field of view the pipeline uses is read from each scan.
        frame_id: the scans' frame name.
        queue_size: scans read and not yet processed that are kept for a busy agent (the
            driver reads and stamps on a thread of its own): about 7 s of an LMS 2xx at
            37.5 Hz by default; beyond, the oldest is dropped (counted ``driver``).
        timeout: seconds per request to the scanner.
        mount: the laser's pose on the robot.
        recording: the MCAP file of ``source = "recording"``.
        speed: how fast a recording plays (1: recorded speed).
        duration: play only the first seconds of the recording (omitted: all of it).
        max_rate: scans per second the whole chain processes at most (0, the default: every
            scan). A scan is processed when 0.9 / max_rate s passed since the last processed
            one's stamp, so the robot on any computer and a replay at any speed process the
            same scans; the others (counted ``over_rate``) go through the people tracker, the
            local map and the doorway detector only (``Pipeline.observe``). ``20`` processes
            every second scan of an LMS at 37.5 Hz, for an onboard computer that cannot
            process every scan in time (the demo's setting).
    """

    source: str = field(default="", metadata={"env": "LOCI_LASER_SOURCE"})
    port: str | None = field(default=None, metadata={"env": "LOCI_LASER_PORT"})
    recording: str | None = None
    speed: float = 1.0
    duration: float | None = None
    baud: int | None = None
    variant: str = "180/0.5"
    frame_id: str = "laser"
    queue_size: int = 256
    timeout: float = 1.0
    max_rate: float = 0.0
    mount: Mount = field(default_factory=Mount)

    def __post_init__(self) -> None:
        source = self.source or ("lms" if self.port else "recording" if self.recording else "bus")
        object.__setattr__(self, "source", source)
        if source not in LASER_SOURCES:
            raise ValueError(
                f"source must be 'lms' (a scanner on 'port'), 'bus' or 'recording' (a file on "
                f"'recording'), got {source!r}"
            )
        if source == "recording" and not self.recording:
            raise ValueError(
                "source 'recording' needs 'recording', the MCAP file, e.g. recording = 'run.mcap'"
            )
        if not (math.isfinite(self.speed) and self.speed > 0):
            raise ValueError(f"speed must be > 0 (1 = recorded speed), got {self.speed!r}")
        if self.duration is not None and not (math.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"duration must be > 0 seconds, got {self.duration!r}")
        if source == "lms" and not self.port:
            raise ValueError(
                "source 'lms' needs 'port', the scanner's serial device, e.g. port = '/dev/ttyUSB0'"
            )
        if self.variant != "keep" and self.variant not in LMS_VARIANTS:
            raise ValueError(
                f"variant must be one of {', '.join(LMS_VARIANTS)} or 'keep', got {self.variant!r}"
            )
        if self.baud is not None and self.baud not in (9600, 19200, 38400, 500000):
            raise ValueError(f"baud must be 9600, 19200, 38400 or 500000, got {self.baud}")
        if self.queue_size < 1:
            raise ValueError(f"queue_size must be >= 1 scan, got {self.queue_size}")
        if isinstance(self.max_rate, bool) or not (math.isfinite(self.max_rate) and self.max_rate >= 0):
            raise ValueError(f"max_rate must be scans per second >= 0 (0: every scan), got {self.max_rate!r}")
        if not self.timeout > 0:
            raise ValueError(f"timeout must be > 0 seconds, got {self.timeout}")

    @property
    def angle_resolution(self) -> tuple[int | None, float | None]:
        """``(angle, resolution)`` in degrees for the driver; ``(None, None)`` keeps the scanner's."""
        if self.variant == "keep":
            return None, None
        a, r = self.variant.split("/")
        return int(a), float(r)


@dataclass(frozen=True)
class OdometryConfig(SyncParams):
    """``[odometry]``: how each scan gets the robot's pose at its stamp.

    ``source`` is ``"bus"``: subscribe ``loci/<robot>/odom`` (the only source so far). The
    other keys are :class:`~agent.core.odom_sync.SyncParams` (``max_wait``, ``max_gap``,
    ``still``, ``max_extrapolation``, ``max_future``, ``reorder``, ``horizon``,
    ``max_pending``): how long a scan waits for odometry, across which gaps it is
    interpolated, how far it may be extrapolated, how far ahead a stamp may be, and how long
    scans are held to put late ones in order (docs/agent.md has the table).
    """

    source: str = "bus"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.source != "bus":
            raise ValueError(f"source must be 'bus' (loci/<robot>/odom), got {self.source!r}")

    @property
    def sync(self) -> SyncParams:
        """The association parameters alone (what recordings store)."""
        return SyncParams.from_table(self.to_table())


@dataclass(frozen=True)
class PlacesConfig:
    """``[places]``: ``model`` (a ``.npz`` path, or ``"default"`` for the bundled one),
    ``window``, the N last scan labels a node's majority vote counts, ``hmm``, filter the
    labels along the trajectory with the model's HMM (Sect. 5.4), and ``vote``, which label
    is published and votes for nodes ("filtered" or "raw")."""

    model: str = field(default="default", metadata={"env": "LOCI_MODEL"})
    window: int = 10
    hmm: bool = True
    vote: str = "filtered"

    def __post_init__(self) -> None:
        if self.window < 1:
            raise ValueError(f"window must be >= 1 label, got {self.window}")
        if self.vote not in ("filtered", "raw"):
            raise ValueError(f"vote must be 'filtered' or 'raw', got {self.vote!r}")

    @property
    def model_path(self) -> Path:
        from knowledge.places.model import default_model_path

        return default_model_path() if self.model == "default" else Path(self.model)


@dataclass(frozen=True)
class StateConfig:
    """``[state]``: ``dir`` holds ``navgraph.json`` (default ``$XDG_STATE_HOME/genius-loci/<robot>``);
    it is written at most every ``save_interval`` seconds while the graph changes, and on
    shutdown; ``resume = false`` starts a new map (the old file is replaced at the first save)."""

    dir: str = field(default="", metadata={"env": "LOCI_STATE_DIR"})
    save_interval: float = 2.0
    resume: bool = True

    def __post_init__(self) -> None:
        if not (math.isfinite(self.save_interval) and self.save_interval >= 0):
            raise ValueError(f"save_interval must be >= 0 seconds, got {self.save_interval}")

    @property
    def path(self) -> Path:
        """The state file."""
        return Path(self.dir) / "navgraph.json"


@dataclass(frozen=True)
class RecordConfig:
    """``[record]``: ``path`` of an MCAP recording of ``loci/<robot>/**`` (none when unset;
    ``strftime`` codes such as ``%Y%m%d-%H%M%S`` are expanded at start), flushed every
    ``flush_interval`` seconds; an existing file is an error unless ``overwrite``."""

    path: str | None = field(default=None, metadata={"env": "LOCI_RECORD"})
    flush_interval: float = 1.0
    overwrite: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.flush_interval) and self.flush_interval > 0):
            raise ValueError(f"flush_interval must be > 0 seconds, got {self.flush_interval}")


@dataclass(frozen=True)
class DiagnosticsConfig:
    """``[diagnostics]``: ``period``, seconds between ``loci/<robot>/diagnostics`` messages."""

    period: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.period) and self.period > 0):
            raise ValueError(f"period must be > 0 seconds, got {self.period}")


@dataclass(frozen=True)
class CameraConfig:
    """``[camera]``: where frames come from and their size.

    Attributes:
        source: ``""`` (default): frames arrive on ``loci/<robot>/camera`` from another
            process (the simulator, a camera driver); otherwise what a camera driver opens:
            ``"sim://..."``, a device index ``"0"``, a device path ``"/dev/video0"`` or a
            stream URL ``"rtsp://..."``.
        width, height: pixels wanted from the device.
        fps: frames per second wanted from the device.
    """

    source: str = ""
    width: int = 640
    height: int = 480
    fps: float = 10.0

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1:
            raise ValueError(f"width and height must be >= 1 pixel, got {self.width} x {self.height}")
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"fps must be > 0 frames per second, got {self.fps}")


@dataclass(frozen=True)
class ConceptualConfig:
    """``[conceptual]``: the conceptual map (OWL ontology, HermiT reasoner, Sect. 7.2.4).

    Attributes:
        enabled: run the conceptual service; default (unset): on when the configuration has
            a ``[conceptual]`` section, off otherwise (the reasoner needs Java).
        state: the SQLite file of the map (default ``<state.dir>/concepts.sqlite3``).
        ontologies: extra OWL files loaded besides the bundled one.
        java: the ``java`` executable (``""``: found automatically).
        debounce: seconds the reasoner waits for more changes before it runs.
    """

    enabled: bool | None = None
    state: str = ""
    ontologies: tuple[str, ...] = ()
    java: str = ""
    debounce: float = 0.2

    def __post_init__(self) -> None:
        if not (math.isfinite(self.debounce) and self.debounce >= 0):
            raise ValueError(f"debounce must be >= 0 seconds, got {self.debounce}")

    @property
    def on(self) -> bool:
        return bool(self.enabled)


@dataclass(frozen=True)
class ObjectsConfig:
    """``[objects]``: the object instances the camera recognises (Sect. 7.3).

    Attributes:
        database: the folder of the object database (``loci objects add``; default
            ``<state.dir>/objects``); recognition runs when it exists.
        min_inliers: RANSAC inliers a recognition needs.
    """

    database: str = ""
    min_inliers: int = 12

    def __post_init__(self) -> None:
        if self.min_inliers < 4:
            raise ValueError(
                f"min_inliers must be >= 4 (a homography needs 4 points), got {self.min_inliers}"
            )


@dataclass(frozen=True)
class FollowConfig:
    """``[follow]``: follow-me (Sect. 7.4): keep ``distance`` metres behind the person; the
    person is lost after ``lost_after`` seconds without seeing them."""

    distance: float = 1.0
    lost_after: float = 2.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.distance) and self.distance > 0):
            raise ValueError(f"distance must be > 0 metres, got {self.distance}")
        if not (math.isfinite(self.lost_after) and self.lost_after > 0):
            raise ValueError(f"lost_after must be > 0 seconds, got {self.lost_after}")


@dataclass(frozen=True)
class PeopleConfig:
    """``[people]``: detect and track people in every scan (issue 7; published on
    ``loci/<robot>/people``, what follow-me follows).

    Attributes:
        enabled: run the leg detector on every scan (off: no people, no follow-me).
        model: the leg detector (a ``loci.people-model/2`` ``.npz``), or ``"default"`` for the
            bundled one.
        mask: hide the detected legs from the place classifier, the local map and the doorway
            detector (a person walking ahead otherwise makes a corridor look like a room).
    """

    enabled: bool = True
    model: str = "default"
    mask: bool = True

    @property
    def model_path(self) -> Path:
        from knowledge.people.detector import DEFAULT_MODEL

        return DEFAULT_MODEL if self.model == "default" else Path(self.model)


@dataclass(frozen=True)
class LocalizationConfig:
    """``[localization]``: correct the odometry by matching each scan against the map built
    so far (:class:`~knowledge.localization.tracking.PoseTracker`; docs/localization.md).
    Off unless configured: the graph, the areas and the local map then live in the corrected
    ``map`` frame and ``tf/map`` carries the map -> odom transform.

    Attributes:
        tracking: run the tracker on every scan.
        max_range: metres; longer beams are not matched.
        beam_step: match every ``beam_step``-th beam.
        accept_fit: the least mean score of a match that is taken.
        lag: scans; the tracker runs on its own thread and scan ``k`` is corrected with what
            it found for scan ``k − lag`` (0: in the per-scan path, adding its 4–9 ms to every
            scan; docs/localization.md "In the agent").
        smoothing: seconds; the correction each scan is given follows the tracker's with
            this time constant (changes of more than 0.2 m or 0.1 rad at once; 0: the
            tracker's as it is).
    """

    tracking: bool = False
    max_range: float = 20.0
    beam_step: int = 2
    accept_fit: float = 0.3
    lag: int = 3
    smoothing: float = 0.25

    def __post_init__(self) -> None:
        if isinstance(self.lag, bool) or not isinstance(self.lag, int) or not 0 <= self.lag <= 100:
            raise ValueError(
                f"localization.lag must be a whole number of scans in [0, 100], got {self.lag!r}"
            )
        if not (math.isfinite(self.smoothing) and 0.0 <= self.smoothing <= 10.0):
            raise ValueError(f"localization.smoothing must be seconds in [0, 10], got {self.smoothing!r}")

    def tracking_params(self) -> Any:
        """The tracker's parameters, or None when tracking is off."""
        if not self.tracking:
            return None
        from knowledge.localization.tracking import TrackingParams

        return TrackingParams(max_range=self.max_range, beam_step=self.beam_step, accept_fit=self.accept_fit)


@dataclass(frozen=True)
class AgentConfig:
    """The whole configuration (see the module docstring); build it with :func:`load_config`."""

    robot: RobotConfig = field(default_factory=RobotConfig)
    bus: BusConfig = field(default_factory=lambda: BusConfig(listen=(DEFAULT_AGENT_ENDPOINT,)))
    laser: LaserConfig = field(default_factory=LaserConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    places: PlacesConfig = field(default_factory=PlacesConfig)
    navigation: GraphParams = field(default_factory=GraphParams)
    doorways: DoorwayParams = field(default_factory=DoorwayParams)
    local_map: LocalMapParams = field(default_factory=LocalMapParams)
    rear_beams: FullScanParams = field(default_factory=FullScanParams)
    state: StateConfig = field(default_factory=StateConfig)
    record: RecordConfig = field(default_factory=RecordConfig)
    diagnostics: DiagnosticsConfig = field(default_factory=DiagnosticsConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    conceptual: ConceptualConfig = field(default_factory=ConceptualConfig)
    objects: ObjectsConfig = field(default_factory=ObjectsConfig)
    follow: FollowConfig = field(default_factory=FollowConfig)
    people: PeopleConfig = field(default_factory=PeopleConfig)
    foxglove: FoxgloveConfig = field(default_factory=FoxgloveConfig)
    ros2: Ros2Config = field(default_factory=Ros2Config)
    localization: LocalizationConfig = field(default_factory=LocalizationConfig)
    file: Path | None = None

    @property
    def robot_name(self) -> str:
        return self.robot.name


#: Environment variable → (section, key, parser of its text); an empty variable counts as
#: unset. ``LOCI_CONFIG`` names the file when ``--config`` is absent. Made from the fields'
#: ``env`` metadata (:func:`env_vars`).
ENV_VARS = env_vars(
    {
        name: tp
        for name, tp in typing.get_type_hints(AgentConfig).items()
        if isinstance(tp, type) and dataclasses.is_dataclass(tp)
    }
)


# ---------------------------------------------------------------------------- loading

_SECTIONS = (
    "robot",
    "bus",
    "laser",
    "odometry",
    "places",
    "navigation",
    "local_map",
    "rear_beams",
    "state",
    "record",
    "diagnostics",
    "camera",
    "conceptual",
    "objects",
    "follow",
    "people",
    "foxglove",
    "ros2",
    "localization",
)


def default_state_dir(robot: str, env: Mapping[str, str] | None = None) -> Path:
    """``$XDG_STATE_HOME/genius-loci/<robot>`` (``~/.local/state/...`` without XDG_STATE_HOME)."""
    env = os.environ if env is None else env
    base = env.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "genius-loci" / robot


def read_toml(path: str | Path) -> dict[str, Any]:
    """The tables of a TOML file; a missing file or bad TOML is a ConfigError."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such configuration file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML: {exc}") from exc


def load_config(
    path: str | Path | None = None,
    *,
    env: Mapping[str, str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    table: Mapping[str, Any] | None = None,
) -> AgentConfig:
    """Read the configuration: ``overrides`` > ``env`` > the file (or ``table``) > defaults.

    Args:
        path: the TOML file; None: ``$LOCI_CONFIG`` if set, else no file.
        env: the environment (default ``os.environ``); see :data:`ENV_VARS`.
        overrides: command-line values as ``{"section.key": value}`` (None values are ignored).
        table: the file's content already parsed (instead of ``path``).

    Raises:
        ConfigError: unknown sections or keys, wrong types, bad values (the message names them).
    """
    env = os.environ if env is None else env
    if path is None and table is None and env.get(CONFIG_ENV):
        path = env[CONFIG_ENV]
    file = Path(path) if path is not None else None
    raw: dict[str, Any] = dict(read_toml(file) if file is not None else (table or {}))
    origin: dict[tuple[str, str], str] = {}
    data: dict[str, dict[str, Any]] = {}
    for section, content in raw.items():
        if section not in _SECTIONS:
            raise ConfigError(f"unknown section [{section}] (known: {', '.join(_SECTIONS)})")
        if not isinstance(content, Mapping):
            raise ConfigError(f"{section} must be a table: write [{section}] and its keys below it")
        data[section] = dict(content)
        for key in content:
            origin[(section, key)] = str(file) if file else "the configuration"
    base = file.parent if file is not None else None
    if base is not None:
        for section, key in _PATH_KEYS:
            v = data.get(section, {}).get(key)
            if isinstance(v, str) and v and not (key == "model" and v == "default"):
                p = Path(v).expanduser()
                data[section][key] = str(p if p.is_absolute() else base / p)
        for section, key in _PATH_LIST_KEYS:
            v = data.get(section, {}).get(key)
            if isinstance(v, list):
                data[section][key] = [
                    str(q if (q := Path(x).expanduser()).is_absolute() else base / q)
                    if isinstance(x, str)
                    else x
                    for x in v
                ]
    for var, (section, key, parse) in ENV_VARS.items():
        text = env.get(var)
        if text:
            data.setdefault(section, {})[key] = parse(text)
            origin[(section, key)] = var
    for dotted, value in (overrides or {}).items():
        if value is None:
            continue
        section, _, key = dotted.partition(".")
        if section not in _SECTIONS or not key:
            raise ValueError(f"override {dotted!r} must be 'section.key' with a known section")
        data.setdefault(section, {})[key] = str(value) if isinstance(value, Path) else value
        origin[(section, key)] = f"the command line ({dotted})"
    try:
        return _build(data, file, env)
    except ConfigError as exc:
        raise ConfigError(_with_origin(str(exc), origin)) from None


def _with_origin(message: str, origin: Mapping[tuple[str, str], str]) -> str:
    """Append where a value came from when it was not the file (an environment variable...)."""
    for (section, key), where in origin.items():
        named = f"{section}.{key}" in message or (f"[{section}]" in message and key in message)
        if named and where.startswith(("LOCI_", "the command line")):
            return f"{message} (set by {where})"
    return message


def _build(data: Mapping[str, Mapping[str, Any]], file: Path | None, env: Mapping[str, str]) -> AgentConfig:
    def sec(name: str) -> Mapping[str, Any]:
        return data.get(name, {})

    robot = build_dataclass(RobotConfig, sec("robot"), "robot")
    bus_table = dict(sec("bus"))
    if "listen" not in bus_table:
        # the agent listens where `loci record` looks for it; a router's client does not listen
        bus_table["listen"] = [DEFAULT_AGENT_ENDPOINT] if bus_table.get("mode", "peer") == "peer" else []
    bus = BusConfig.from_mapping(bus_table, where="bus")
    places = build_dataclass(PlacesConfig, sec("places"), "places")
    nav = dict(sec("navigation"))
    doors = nav.pop("doorways", {})
    if not isinstance(doors, Mapping):
        raise ConfigError("navigation.doorways must be a table: [navigation.doorways]")
    if "window" in nav:
        raise ConfigError("[navigation]: unknown key 'window' (the label window N is places.window)")
    graph = build_dataclass(GraphParams, {**nav, "window": places.window}, "navigation")
    state = build_dataclass(StateConfig, sec("state"), "state")
    if not state.dir:
        state = dataclasses.replace(state, dir=str(default_state_dir(robot.name, env)))
    conceptual = build_dataclass(ConceptualConfig, sec("conceptual"), "conceptual")
    if conceptual.enabled is None:
        conceptual = dataclasses.replace(conceptual, enabled="conceptual" in data)
    if not conceptual.state:
        conceptual = dataclasses.replace(conceptual, state=str(Path(state.dir) / "concepts.sqlite3"))
    ros2 = build_dataclass(Ros2Config, sec("ros2"), "ros2")
    if ros2.enabled is None:
        ros2 = dataclasses.replace(ros2, enabled="ros2" in data)
    objects = build_dataclass(ObjectsConfig, sec("objects"), "objects")
    if not objects.database:
        objects = dataclasses.replace(objects, database=str(Path(state.dir) / "objects"))
    return AgentConfig(
        robot=robot,
        bus=bus,
        laser=build_dataclass(LaserConfig, sec("laser"), "laser"),
        odometry=build_dataclass(OdometryConfig, sec("odometry"), "odometry"),
        places=places,
        navigation=graph,
        doorways=build_dataclass(DoorwayParams, doors, "navigation.doorways"),
        local_map=build_dataclass(LocalMapParams, sec("local_map"), "local_map"),
        rear_beams=build_dataclass(
            FullScanParams, sec("rear_beams"), "rear_beams", skip=("n_beams", "max_range")
        ),
        state=state,
        record=build_dataclass(RecordConfig, sec("record"), "record"),
        diagnostics=build_dataclass(DiagnosticsConfig, sec("diagnostics"), "diagnostics"),
        camera=build_dataclass(CameraConfig, sec("camera"), "camera"),
        conceptual=conceptual,
        objects=objects,
        follow=build_dataclass(FollowConfig, sec("follow"), "follow"),
        people=build_dataclass(PeopleConfig, sec("people"), "people"),
        foxglove=build_dataclass(FoxgloveConfig, sec("foxglove"), "foxglove"),
        ros2=ros2,
        localization=build_dataclass(LocalizationConfig, sec("localization"), "localization"),
        file=file,
    )
