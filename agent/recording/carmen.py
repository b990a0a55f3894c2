"""CARMEN robot logs: text lines in, typed scans and poses out (pure code, no I/O).

A CARMEN log has one message per line; every message line ends with ``ipc_time host
logger_time``. ``ipc_time`` is the message's own time stamp (set by the module that made it:
the laser driver for a scan, the base for odometry); ``logger_time`` is when the logger
received it, in seconds since the logger started. The importer makes ``ipc_time`` the
message's stamp and the logger time its MCAP log time (the arrival time), moved onto the
``ipc_time`` clock by the median difference of the two over the file (``--clock ipc``;
``--clock logger`` uses the logger time for both, ``--clock lines`` makes both up from the
line order for files whose times were printed with too few digits; see :class:`Clock`).

Line types read (fields after the type; ``[..]`` = repeated):

* ``PARAM name value``: the laser setup (:class:`LaserSetup`).
* ``ODOM x y theta tv rv accel``: the base's odometry pose (m, m, rad).
* ``TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta``: a simulator's true pose.
* ``FLASER n [range] x y theta odom_x odom_y odom_theta`` (front laser) and ``RLASER``
  (rear): old-style laser lines; the beam angles are not in the line (:func:`beam_angles`).
* ``RAWLASERk type start_angle fov resolution max_range accuracy [remission_mode] n [range]
  n_rem [remission]`` (k = 1..4): a laser as its driver saw it.
* ``ROBOTLASERk`` as RAWLASERk, then ``laser_x laser_y laser_theta robot_x robot_y
  robot_theta tv rv forward_safety side_safety turn_axis``.

Which pose is which (CARMEN's ``logwrite``; checked on the real files): in FLASER/RLASER and
ROBOTLASER lines the first triple is the **laser's** pose and the second the **robot's**
(odometry) pose; CARMEN's robot module sets the first to the second moved by the laser's
offset, and SLAM tools that correct a log overwrite the first with their corrected pose. In
all three logs of ``../shared/data/logs`` the two triples are identical on every line
(the corrected logs write the corrected pose into both; the raw CSAIL log has
``robot_frontlaser_offset 0``), so a line whose two triples agree holds one pose, the
robot's. The corrected logs also add ``ODOM`` lines with times 0 that repeat the corrected
pose after each FLASER line, and ``NEFF`` lines (particle filter statistics, not CARMEN).
"""

from __future__ import annotations

import math
import re
import statistics
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from agent.recording.imported import ODOM, SCAN, TRUTH, Outcome, Output, Skip, compose, inverse, same_pose
from drivers.messages import LaserScan, Pose2D

Pose = tuple[float, float, float]

#: Laser line type → laser number (1 front, 2 rear, 3, 4).
_OLD_LASERS = {"FLASER": 1, "RLASER": 2}
_NUMBERED = re.compile(r"(RAWLASER|ROBOTLASER)([1-4])$")
#: Message types the importer reads; PARAM, SYNC and comments are not messages.
KNOWN_TYPES = ("PARAM", "SYNC", "ODOM", "TRUEPOS", "FLASER", "RLASER", "RAWLASER1-4", "ROBOTLASER1-4")

#: CARMEN's laser types (``carmen_laser_laser_type_t``): 0 SICK LMS, 1 SICK PLS,
#: 2 Hokuyo URG, 3 simulated, 4 SICK S300, 99 unknown.
SICK_LMS_TYPES = frozenset({0})
#: LMS out-of-range codes in cm units, as logged in metres (8183-8191 cm).
SICK_CODE_MIN_M, SICK_CODE_MAX_M = 81.83, 81.91


class LineError(ValueError):
    """A line that cannot be read; ``reason`` is its skip reason."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


# ---- lines -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Times:
    """The end of a message line: ``ipc`` stamp (s), the sending ``host``, ``logger`` time (s);
    ``ipc_text`` is ``ipc`` as printed (its digits tell its precision)."""

    ipc: float
    host: str
    logger: float
    ipc_text: str


@dataclass(frozen=True)
class LaserGeometry:
    """What RAWLASER/ROBOTLASER lines say about their laser (angles in rad, range in m)."""

    laser_type: int
    start_angle: float
    fov: float
    resolution: float
    max_range: float


@dataclass(frozen=True, eq=False)
class LaserLine:
    """A laser line. ``geometry`` is None for FLASER/RLASER; the poses are None for RAWLASER."""

    kind: str
    laser: int
    ranges: np.ndarray
    times: Times
    geometry: LaserGeometry | None = None
    laser_pose: Pose | None = None
    robot_pose: Pose | None = None


@dataclass(frozen=True)
class OdomLine:
    pose: Pose
    times: Times


@dataclass(frozen=True)
class TruePosLine:
    true_pose: Pose
    odom_pose: Pose
    times: Times


@dataclass(frozen=True)
class ParamLine:
    name: str
    value: str


@dataclass(frozen=True)
class OtherLine:
    """A line that is not a message: a comment, SYNC, or an unknown type (``kind``)."""

    kind: str


Line = LaserLine | OdomLine | TruePosLine | ParamLine | OtherLine


def _floats(tokens: list[str], what: str) -> np.ndarray:
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not _is_number(t))
        raise LineError("bad_line", f"{what}: {bad!r} is not a number") from None


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _float(text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise LineError("bad_line", f"{what} {text!r} is not a number") from None


def _count(text: str, what: str) -> int:
    try:
        v = float(text)
    except ValueError:
        raise LineError("bad_line", f"{what} {text!r} is not a number") from None
    if not (v.is_integer() and 0 <= v < 100_000):
        raise LineError("bad_line", f"{what} {text!r} is not a count")
    return int(v)


def _times(tok: list[str]) -> Times:
    return Times(_float(tok[-3], "ipc_time"), tok[-2], _float(tok[-1], "logger_time"), tok[-3])


def _pose(tok: list[str], at: int, what: str) -> Pose:
    x, y, th = (_float(tok[at + i], what) for i in range(3))
    if not all(math.isfinite(v) for v in (x, y, th)):
        raise LineError("bad_line", f"{what} ({x}, {y}, {th}) is not finite")
    return (x, y, th)


def _need(tok: list[str], n: int, kind: str) -> None:
    if len(tok) < n:
        raise LineError(
            "truncated_line", f"{kind} line has {len(tok)} fields, needs {n} (cut in the middle?)"
        )


def _exact(tok: list[str], n: int, kind: str) -> None:
    _need(tok, n, kind)
    if len(tok) != n:
        raise LineError("bad_line", f"{kind} line has {len(tok)} fields, expected {n}")


def parse_line(text: str) -> Line:
    """One line of a CARMEN log as a typed record.

    Raises:
        LineError: the line is cut short (``truncated_line``), has a field that is not a
            number or counts that do not add up (``bad_line``), or a laser without beams
            (``zero_beams``).
    """
    tok = text.split()
    if not tok or tok[0].startswith("#"):
        return OtherLine("#")
    kind = tok[0]
    if kind == "PARAM":
        _need(tok, 3, kind)
        value = " ".join(tok[2:-3]) if len(tok) >= 6 else tok[2]
        return ParamLine(tok[1], value)
    if kind == "ODOM":
        _exact(tok, 10, kind)
        return OdomLine(_pose(tok, 1, "ODOM pose"), _times(tok))
    if kind == "TRUEPOS":
        _exact(tok, 10, kind)
        return TruePosLine(_pose(tok, 1, "TRUEPOS true pose"), _pose(tok, 4, "TRUEPOS odometry"), _times(tok))
    if kind in _OLD_LASERS:
        _need(tok, 2, kind)
        n = _count(tok[1], f"{kind} beam count")
        if n == 0:
            raise LineError("zero_beams", f"{kind} line with 0 beams")
        _exact(tok, n + 11, kind)
        return LaserLine(
            kind,
            _OLD_LASERS[kind],
            _floats(tok[2 : 2 + n], f"{kind} range"),
            _times(tok),
            laser_pose=_pose(tok, 2 + n, f"{kind} laser pose"),
            robot_pose=_pose(tok, 5 + n, f"{kind} odometry pose"),
        )
    m = _NUMBERED.match(kind)
    if m:
        return _numbered_laser(tok, m.group(1), int(m.group(2)))
    if kind == "SYNC":
        return OtherLine(kind)
    return OtherLine(kind)


def _layout(tok: list[str], tail: int) -> tuple[int, int, int, int] | None:
    """``(count_at, n, rem_at, n_rem)`` of the RAWLASER/ROBOTLASER layout whose field count
    adds up, trying the newer one (``remission_mode`` before the beam count) first."""
    for count_at in (8, 7):
        if not (_is_number(tok[count_at]) and float(tok[count_at]).is_integer()):
            continue
        n = int(float(tok[count_at]))
        rem_at = count_at + 1 + n
        if n < 0 or rem_at >= len(tok) or not _is_number(tok[rem_at]):
            continue
        n_rem = float(tok[rem_at])
        if n_rem.is_integer() and n_rem >= 0 and len(tok) == rem_at + 1 + int(n_rem) + tail:
            return count_at, n, rem_at, int(n_rem)
    return None


def _numbered_laser(tok: list[str], family: str, laser: int) -> LaserLine:
    """RAWLASERk / ROBOTLASERk, with or without the ``remission_mode`` field (newer CARMEN
    writes it before the beam count, older does not): the layout whose field count adds up."""
    kind = tok[0]
    tail = 3 + (11 if family == "ROBOTLASER" else 0)  # poses, velocities, times
    _need(tok, 9, kind)
    layout = _layout(tok, tail)
    if layout is None:
        n = _count(tok[8], f"{kind} beam count")
        if n == 0:
            raise LineError("zero_beams", f"{kind} line with 0 beams")
        if len(tok) < 9 + n + 1 + tail:
            raise LineError(
                "truncated_line",
                f"{kind} line has {len(tok)} fields, too few for {n} beams (cut in the middle?)",
            )
        raise LineError("bad_line", f"{kind} line: its {len(tok)} fields do not fit the {kind} layout")
    count_at, n, rem_at, n_rem = layout
    if n == 0:
        raise LineError("zero_beams", f"{kind} line with 0 beams")
    geometry = LaserGeometry(
        laser_type=_count(tok[1], f"{kind} laser type"),
        start_angle=_float(tok[2], f"{kind} start angle"),
        fov=_float(tok[3], f"{kind} field of view"),
        resolution=_float(tok[4], f"{kind} angular resolution"),
        max_range=_float(tok[5], f"{kind} maximum range"),
    )
    ranges = _floats(tok[count_at + 1 : count_at + 1 + n], f"{kind} range")
    laser_pose = robot_pose = None
    if family == "ROBOTLASER":
        at = rem_at + 1 + n_rem
        laser_pose = _pose(tok, at, f"{kind} laser pose")
        robot_pose = _pose(tok, at + 3, f"{kind} robot pose")
    return LaserLine(kind, laser, ranges, _times(tok), geometry, laser_pose, robot_pose)


# ---- the laser setup from PARAM lines ---------------------------------------------------

_LASER_NAMES = {1: "front", 2: "rear", 3: "laser3", 4: "laser4"}


@dataclass(frozen=True)
class LaserSetup:
    """A laser as the PARAM lines describe it.

    Attributes:
        mount: the laser's pose on the robot (x m, y m, yaw rad): ``robot_frontlaser_offset``
            (metres ahead of the centre) with ``robot_frontlaser_side_offset`` and
            ``robot_frontlaser_angular_offset`` when the log has them; the rear laser is
            taken to sit ``robot_rearlaser_offset`` behind the centre, facing backwards.
        fov: the field of view of FLASER/RLASER lines, rad (``laser_front_laser_fov``,
            degrees when the value is above 2π; default π).
        laser_type: ``laser_front_laser_type`` as logged (``LMS``, ``PLS``, ``HOKUYOURG``, ...).
    """

    mount: Pose = (0.0, 0.0, 0.0)
    fov: float = math.pi
    laser_type: str = ""


def laser_setup(params: dict[str, str], laser: int) -> LaserSetup:
    """The setup of laser ``laser`` (1 front, 2 rear, ...) from a log's PARAM values."""

    def num(name: str, default: float) -> float:
        try:
            v = float(params.get(name, default))
        except ValueError:
            return default
        return v if math.isfinite(v) else default

    name = _LASER_NAMES[laser]
    if laser == 1:
        mount = (
            num("robot_frontlaser_offset", 0.0),
            num("robot_frontlaser_side_offset", 0.0),
            num("robot_frontlaser_angular_offset", 0.0),
        )
    elif laser == 2:
        mount = (
            -num("robot_rearlaser_offset", 0.0),
            num("robot_rearlaser_side_offset", 0.0),
            math.pi + num("robot_rearlaser_angular_offset", 0.0),
        )
    else:
        mount = (0.0, 0.0, 0.0)
    fov = num(f"laser_{name}_laser_fov", math.pi)
    if fov > 2 * math.pi + 1e-3:
        fov = math.radians(fov)
    if not 0 < fov <= 2 * math.pi + 1e-3:
        fov = math.pi
    return LaserSetup(mount=mount, fov=fov, laser_type=params.get(f"laser_{name}_laser_type", ""))


# ---- beam angles --------------------------------------------------------------------------

#: ``n``: beam i at −fov/2 + i·fov/n (the last beam stops one step short of +fov/2);
#: ``n-1``: −fov/2 + i·fov/(n−1) (the beams span the whole field of view).
CONVENTIONS = ("n", "n-1")


def beam_convention(n: int, choice: str = "auto") -> str:
    """The beam-angle convention of an n-beam FLASER/RLASER line.

    ``auto``: an odd count spans the field of view end to end (``n-1``: a SICK LMS sends 181
    or 361 values for 180° at 1° or 0.5°, both ends included); an even count is a scan whose
    last reading was dropped (``n``: 180 or 360 beams, as old CARMEN logs hold).
    """
    if choice in CONVENTIONS:
        return choice
    if choice != "auto":
        raise ValueError(f"beam-angle convention must be auto, n or n-1, got {choice!r}")
    return "n-1" if n % 2 == 1 and n > 1 else "n"


def beam_angles(n: int, fov: float, convention: str) -> tuple[float, float]:
    """``(angle_min, angle_increment)`` of an FLASER/RLASER line (rad)."""
    step = fov / (n - 1) if convention == "n-1" and n > 1 else fov / n
    return -fov / 2.0, step


# ---- clocks -------------------------------------------------------------------------------

CLOCKS = ("auto", "ipc", "logger", "lines")


def time_resolution(text: str) -> float:
    """The resolution (s) of a time as printed: ``1.13486e+09`` → 1e4, ``0.227623`` → 1e-6."""
    mantissa, _, exp = text.lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    try:
        e = int(exp) if exp else 0
    except ValueError:
        return math.inf
    return 10.0 ** (e - decimals)


@dataclass
class Survey:
    """A first pass over a log: what it holds, so the import can be set up before writing.

    Attributes:
        types: line type → lines.
        params: PARAM name → value (the last one).
        timed: message lines with times; coarse: those whose ``ipc_time`` is printed to
            worse than 0.01 s (e.g. ``1.13486e+09``).
        offsets: ``ipc_time − logger_time`` of the timed lines with both times > 0 (sampled).
        comments: the comment lines' text (the first few).
        first_time: the first non-zero ``ipc_time``.
    """

    types: Counter[str] = field(default_factory=Counter)
    params: dict[str, str] = field(default_factory=dict)
    timed: int = 0
    coarse: int = 0
    offsets: list[float] = field(default_factory=list)
    comments: list[str] = field(default_factory=list)
    first_time: float | None = None

    def add(self, text: str) -> None:
        tok = text.split(None, 1)
        if not tok:
            return
        kind = tok[0]
        if kind.startswith("#"):
            if len(self.comments) < 50:
                self.comments.append(text.strip())
            return
        self.types[kind] += 1
        if kind == "PARAM":
            parts = text.split()
            if len(parts) >= 3:
                self.params[parts[1]] = " ".join(parts[2:-3]) if len(parts) >= 6 else parts[2]
            return
        if kind not in ("ODOM", "TRUEPOS") and kind not in _OLD_LASERS and not _NUMBERED.match(kind):
            return
        tail = text.rsplit(None, 3)
        if len(tail) < 4:
            return
        try:
            ipc, logger = float(tail[-3]), float(tail[-1])
        except ValueError:
            return
        if ipc == 0 and logger == 0:
            return
        self.timed += 1
        if time_resolution(tail[-3]) > 0.01:
            self.coarse += 1
        if ipc > 0 and logger > 0:
            if self.first_time is None:
                self.first_time = ipc
            if len(self.offsets) < 20_000:
                self.offsets.append(ipc - logger)

    def scan_source(self, laser: int) -> str | None:
        """The line type the scans of ``laser`` are read from: CARMEN logs one reading up to
        three times (RAWLASERk from the laser module; ROBOTLASERk and FLASER/RLASER from the
        robot module, same ``ipc_time``). Preferred: ROBOTLASERk (angles and poses), then
        FLASER/RLASER (poses), then RAWLASERk."""
        old = {v: k for k, v in _OLD_LASERS.items()}.get(laser)
        for kind in (f"ROBOTLASER{laser}", old, f"RAWLASER{laser}"):
            if kind and self.types[kind]:
                return kind
        return None

    def lasers(self) -> list[int]:
        """Laser numbers with lines, front first."""
        return [k for k in (1, 2, 3, 4) if self.scan_source(k)]

    @property
    def robot_hint(self) -> str | None:
        """The robot's name from a ``# robot: NAME`` comment."""
        for c in self.comments:
            m = re.match(r"#\s*robot:\s*(\S+)", c)
            if m:
                return m.group(1)
        return None


@dataclass(frozen=True)
class Clock:
    """How a line's times become a stamp and a log time (both s).

    ``ipc``: stamp = ``ipc_time``, log time = ``logger_time + offset``. ``logger``: both =
    ``logger_time``. ``lines``: both = ``start + k·period`` for the k-th message line.
    """

    mode: str
    offset: float = 0.0
    start: float = 0.0
    period: float = 0.1


def choose_clock(survey: Survey, choice: str = "auto", period: float = 0.1) -> tuple[Clock, str]:
    """The clock of a log and why: ``auto`` is ``ipc`` unless most times are printed too
    coarsely to order the messages (``lines`` then)."""
    if choice not in CLOCKS:
        raise ValueError(f"clock must be one of {', '.join(CLOCKS)}, got {choice!r}")
    if not (math.isfinite(period) and period > 0):
        raise ValueError(f"period must be > 0 seconds, got {period}")
    offset = statistics.median(survey.offsets) if survey.offsets else 0.0
    start = math.floor(survey.first_time or 0.0)
    why = choice
    if choice == "auto":
        if survey.timed and survey.coarse * 2 > survey.timed:
            choice = "lines"
            why = (
                f"lines: {survey.coarse:,} of {survey.timed:,} message times are printed to worse "
                f"than 0.01 s (too few digits to order the messages), so times are made up from "
                f"the line order, one message every {period:g} s"
            )
        else:
            choice = "ipc"
            why = "ipc"
    return Clock(choice, offset=offset, start=start, period=period), why


# ---- the conversion -----------------------------------------------------------------------

ODOMETRY_SOURCES = ("auto", "laser", "odom")
TRUTH_SOURCES = ("auto", "laser", "none")
SICK_CHOICES = ("auto", "on", "off")


@dataclass(frozen=True)
class CarmenOptions:
    """How to read a CARMEN log (the ``loci import`` options).

    Attributes:
        laser: the laser to import (1 front, 2 rear, 3, 4); 0 = the front one if the log has
            it, else the first.
        beam_angles: ``auto``, ``n`` or ``n-1`` (:func:`beam_convention`).
        odometry: ``laser``: the robot pose in the laser lines (every scan gets the odometry
            of its own stamp, as CARMEN's robot module interpolated it); ``odom``: the ODOM
            lines (the base's own messages at its own rate); ``auto``: ``laser`` when the
            scans come from lines that carry poses, else ``odom``.
        truth: what goes on ``pose/truth``: TRUEPOS lines always; ``auto`` adds the laser
            lines' first pose where it differs from their odometry pose beyond the laser's
            mount (a localizer or SLAM corrected it); ``laser`` adds it on every line (for
            corrected logs that write the corrected pose into both triples); ``none``: nothing.
        clock: see :class:`Clock` and :func:`choose_clock`.
        period: seconds between messages for ``clock = lines``.
        sick_codes: map 81.83-81.91 m as the SICK driver maps codes 8183-8191: ``auto`` = for
            SICK LMS lasers (laser type 0, or a log that does not say).
        mount: the laser's mount (x, y, yaw) instead of the PARAM lines'.
    """

    laser: int = 0
    beam_angles: str = "auto"
    odometry: str = "auto"
    truth: str = "auto"
    clock: str = "auto"
    period: float = 0.1
    sick_codes: str = "auto"
    mount: Pose | None = None

    def __post_init__(self) -> None:
        if self.laser not in (0, 1, 2, 3, 4):
            raise ValueError(f"laser must be 1 (front), 2 (rear), 3 or 4, got {self.laser}")
        for name, value, allowed in (
            ("beam_angles", self.beam_angles, ("auto", *CONVENTIONS)),
            ("odometry", self.odometry, ODOMETRY_SOURCES),
            ("truth", self.truth, TRUTH_SOURCES),
            ("clock", self.clock, CLOCKS),
            ("sick_codes", self.sick_codes, SICK_CHOICES),
        ):
            if value not in allowed:
                raise ValueError(f"{name} must be one of {', '.join(allowed)}, got {value!r}")


class CarmenConverter:
    """Turns the lines of one CARMEN log into scans, odometry and reference poses.

    Feed every line in order with :meth:`convert` (after a :class:`Survey` of the same file);
    each returns the outputs or a :class:`Skip`. Problems with a line that is still imported
    (NaN ranges, a stamp not after the previous one) go to ``warn(reason, text)`` and into
    :attr:`notes`; beam counts into :attr:`beams`.
    """

    def __init__(
        self,
        survey: Survey,
        options: CarmenOptions = CarmenOptions(),
        warn: Callable[[str, str], None] | None = None,
    ) -> None:
        self.options = options
        self.survey = survey
        lasers = survey.lasers()
        if not lasers:
            raise ValueError("the log has no laser lines (FLASER, RLASER, RAWLASERk or ROBOTLASERk)")
        self.laser = options.laser or lasers[0]
        source = survey.scan_source(self.laser)
        if source is None:
            raise ValueError(
                f"the log has no lines of laser {self.laser}; it has laser(s) {', '.join(map(str, lasers))}"
            )
        self.source = source
        self.setup = laser_setup(survey.params, self.laser)
        self.mount: Pose = options.mount if options.mount is not None else self.setup.mount
        poses = not source.startswith("RAWLASER")
        odometry = options.odometry
        if odometry == "auto":
            odometry = "laser" if poses else "odom"
        if odometry == "laser" and not poses:
            raise ValueError(f"--odometry laser: the scans come from {source} lines, which carry no pose")
        self.odometry = odometry
        self.clock, self.clock_why = choose_clock(survey, options.clock, options.period)
        self.warn = warn or (lambda reason, text: None)
        self.notes: Counter[str] = Counter()
        self.beams: Counter[str] = Counter()
        self.unknown: Counter[str] = Counter()
        self._k = 0
        self._last_log: float | None = None
        self._last_stamp: dict[str, float] = {}
        self._seq = 0
        self._sick_param = self.setup.laser_type.upper() in ("", "LMS", "SICK", "SICKLMS")

    def describe(self) -> dict[str, str]:
        """The choices made, for the recording's metadata."""
        return {
            "carmen_laser": str(self.laser),
            "carmen_scan_lines": self.source,
            "carmen_odometry": self.odometry,
            "carmen_truth": self.options.truth,
            "carmen_clock": self.clock.mode,
            "carmen_clock_offset": f"{self.clock.offset:.6f}",
            "carmen_beam_angles": self.options.beam_angles,
            "carmen_sick_codes": self.options.sick_codes,
        }

    # -- one line --
    def convert(self, number: int, text: str) -> Outcome:
        """The outputs of line ``number`` (1-based), or why it was skipped."""
        kind = text.split(None, 1)[0] if text.strip() else "#"
        skip = self._skip_unparsed(kind)
        if skip is not None:
            return skip
        try:
            line = parse_line(text)
        except LineError as exc:
            return Skip(exc.reason, f"line {number}: {exc}")
        if isinstance(line, OtherLine):
            if line.kind == "#":
                return Skip("comment")
            if line.kind == "SYNC":
                return Skip("sync")
            self.unknown[line.kind] += 1
            return Skip(
                "unknown_type",
                f"line {number}: unknown line type {line.kind!r} (reads {', '.join(KNOWN_TYPES)})",
            )
        if isinstance(line, ParamLine):
            return Skip("param")
        t = line.times
        if t.ipc <= 0 and t.logger <= 0:
            return Skip("no_time", f"line {number}: {text.split()[0]} with times {t.ipc} and {t.logger}")
        stamp, log_time = self._times(t)
        if self._last_log is not None and log_time < self._last_log:
            return Skip(
                "time_backwards",
                f"line {number}: logged at {log_time:.6f} s, before the line before it ({self._last_log:.6f} s)",
            )
        self._last_log = log_time
        if isinstance(line, OdomLine):
            return self._stamped(number, [Output(ODOM, _pose2d(line.pose, stamp, "odom"), log_time)])
        if isinstance(line, TruePosLine):
            return self._stamped(number, [Output(TRUTH, _pose2d(line.true_pose, stamp, "map"), log_time)])
        return self._laser(number, line, stamp, log_time)

    def _skip_unparsed(self, kind: str) -> Skip | None:
        """Lines left out by their type alone (not parsed: the import reads them faster)."""
        m = _NUMBERED.match(kind)
        laser = _OLD_LASERS.get(kind) or (int(m.group(2)) if m else None)
        if laser is not None:
            if laser != self.laser:
                return Skip("other_laser")
            if kind != self.source:
                return Skip("duplicate")
        elif kind == "ODOM" and self.odometry != "odom":
            return Skip("odometry_not_used")
        elif kind == "TRUEPOS" and self.options.truth == "none":
            return Skip("truth_not_used")
        return None

    def _times(self, t: Times) -> tuple[float, float]:
        c = self.clock
        if c.mode == "ipc":
            return t.ipc, t.logger + c.offset
        if c.mode == "logger":
            return t.logger, t.logger
        k = self._k
        self._k += 1
        return c.start + k * c.period, c.start + k * c.period

    def _stamped(self, number: int, outs: list[Output]) -> list[Output]:
        for out in outs:
            if out.stream == TRUTH:
                continue
            last = self._last_stamp.get(out.stream)
            stamp = out.message.stamp
            if last is not None and stamp <= last:
                self.notes["stamp_not_increasing"] += 1
                self.warn(
                    "stamp_not_increasing",
                    f"line {number}: {out.stream} stamp {stamp:.6f} is not after the previous one "
                    f"({last:.6f}); imported as logged",
                )
            self._last_stamp[out.stream] = stamp if last is None else max(stamp, last)
        return outs

    def _laser(self, number: int, line: LaserLine, stamp: float, log_time: float) -> list[Output]:
        scan = self._scan(number, line, stamp)
        outs: list[Output] = []
        if self.odometry == "laser" and line.robot_pose is not None:
            outs.append(Output(ODOM, _pose2d(line.robot_pose, stamp, "odom"), log_time))
        truth = self._truth(line)
        if truth is not None:
            outs.append(Output(TRUTH, _pose2d(truth, stamp, "map"), log_time))
        outs.append(Output(SCAN, scan, log_time))
        return self._stamped(number, outs)

    def _truth(self, line: LaserLine) -> Pose | None:
        """The robot's reference pose in a laser line (see :class:`CarmenOptions`)."""
        first, second = line.laser_pose, line.robot_pose
        if self.options.truth == "none" or first is None or second is None:
            return None
        if same_pose(first, second):
            return first if self.options.truth == "laser" else None
        if self.options.truth == "auto" and same_pose(first, compose(second, self.mount)):
            return None  # the laser's pose as the robot module computed it: no news
        return compose(first, inverse(self.mount))

    def _sick(self, line: LaserLine) -> bool:
        choice = self.options.sick_codes
        if choice != "auto":
            return choice == "on"
        if line.geometry is not None:
            return line.geometry.laser_type in SICK_LMS_TYPES
        return self._sick_param

    def _scan(self, number: int, line: LaserLine, stamp: float) -> LaserScan:
        from drivers.sick.constants import Units
        from drivers.sick.telegrams import range_max_m, values_to_ranges

        r = line.ranges.copy()
        n = r.shape[0]
        bad = ~np.isfinite(r) | (r < 0)
        if bad.any():
            r[bad] = 0.0
            self.notes["bad_ranges"] += 1
            self.beams["bad"] += int(bad.sum())
            self.warn(
                "bad_ranges",
                f"line {number}: {int(bad.sum())} of {n} ranges are NaN, infinite or negative; "
                "imported as invalid beams (0)",
            )
        g = line.geometry
        range_min = 0.0
        if self._sick(line):
            range_max = range_max_m(Units.CM)
            range_min = 0.01
            codes = np.rint(r * 100.0)
            sel = (codes >= 8183) & (codes <= 8191) & (r >= SICK_CODE_MIN_M - 0.005)
            if sel.any():
                mapped, _ = values_to_ranges(codes[sel].astype(np.uint16), Units.CM)
                r[sel] = mapped
                self.beams["sick_no_return"] += int(np.count_nonzero(mapped >= range_max))
                self.beams["sick_invalid"] += int(np.count_nonzero(mapped == 0.0))
        else:
            range_max = g.max_range if g is not None and g.max_range > 0 else float(np.max(r))
            if not range_max > 0:
                range_max = 1.0
        beyond = r > range_max
        if beyond.any():
            r[beyond] = range_max
            self.beams["beyond_range_max"] += int(beyond.sum())
        if g is not None:
            inc = g.resolution
            if n > 1 and abs(g.fov / (n - 1) - abs(inc)) < 1e-5:
                inc = math.copysign(g.fov / (n - 1), inc)  # the printed resolution is rounded
            angle_min = g.start_angle
            if inc < 0:  # beams clockwise: reverse them into our counter-clockwise order
                angle_min, inc, r = angle_min + (n - 1) * inc, -inc, r[::-1].copy()
            if inc == 0:
                inc = (g.fov / (n - 1)) if n > 1 else math.pi / 180
        else:
            angle_min, inc = beam_angles(n, self.setup.fov, beam_convention(n, self.options.beam_angles))
        self._seq += 1
        return LaserScan(
            stamp=stamp,
            seq=self._seq,
            frame_id="laser",
            angle_min=angle_min,
            angle_increment=inc,
            range_max=range_max,
            ranges=r,
            range_min=range_min,
        )


def _pose2d(p: Pose, stamp: float, frame: str) -> Pose2D:
    return Pose2D(p[0], p[1], p[2], stamp=stamp, frame_id=frame)


def survey_lines(lines: Iterable[str]) -> Survey:
    """A :class:`Survey` of every line."""
    s = Survey()
    for text in lines:
        s.add(text)
    return s
