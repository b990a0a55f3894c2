"""What LMS 2xx telegrams say: request builders, typed replies, and measured values ↔ metres.

Pure code, shared by the driver (which builds requests and decodes replies) and the virtual
LMS (which decodes requests and builds replies), so both speak exactly the same bytes.
Payload layouts follow sicktoolbox's ``SickLMS.cc`` (offsets into the reply payload,
``payload[0]`` being the reply code):

* 0xA0 (mode switch): ``[A0, result]`` — 0 ok, 1 not possible, 2 wrong password.
* 0xBB (variant): ``[BB, ok(1)/failed(0), angle u16 (deg), resolution u16 (1/100 deg)]``.
* 0xF4 (configuration): ``[F4, 34 configuration bytes]`` — blanking u16, stop/peak
  threshold, availability, measuring mode, units (0 cm, 1 mm), ... (:class:`ScannerConfig`).
* 0xB1 (status): software version at 1..7, operating mode 8, status 9, variant type 18,
  motor revolutions 67..68, measuring mode 102, angle 107..108, resolution 109..110,
  address 120, units 122, laser on 123, boot PROM version 124..130.
* 0xBA (type): the type string, e.g. ``"LMS200;30106"``.
* 0xB0 (measured values): a count word — bits 0–9 the number of values, bits 11–12 the
  partial-scan index (0.25° steps), bit 13 partial scan, bits 14–15 units (00 cm, 01 mm) —
  then one little-endian word per value whose low 13 bits (8 m/80 m modes) are the range,
  then an optional real-time scan index byte (availability flag 0x02).

Range error codes (8 m/80 m modes; top of the 13-bit range, telegram listing p. 124, as
used by ROS's sicktoolbox_wrapper) and what :func:`values_to_ranges` makes of them:

=====  =============================  ==============================================
code   listing                        in a :class:`~drivers.messages.LaserScan`
=====  =============================  ==============================================
8183   measured value > maximum       ``range_max`` (no return)
8184   (unassigned)                   ``0.0`` (invalid: below ``range_min``)
8185   (unassigned)                   ``0.0`` (invalid)
8186   error reading channel 1        ``0.0`` (invalid)
8187   signal/noise ratio too small   ``0.0`` (invalid)
8188   (unassigned)                   ``0.0`` (invalid)
8189   operation overflow             ``0.0`` (invalid)
8190   dazzle                         ``0.0`` (invalid)
8191   measured value not valid       ``range_max`` (no return: "no echo")
=====  =============================  ==============================================

``range_max`` is one unit below 8183 (81.82 m in cm units, 8.182 m in mm units), so a
no-return carries the sensor's ``range_max`` as :class:`~drivers.messages.LaserScan` wants
for beams that hit nothing. 8191 is a no-return, not an invalid beam: LMS units log it for a
beam that got no echo back. Nothing came back, so nothing was measured along the beam; that
is what a no-return says. (In the Freiburg 079 log, 36,004 of 1,724,760 readings are 81.91 m,
most of them at ±50-90° from the front, where corridor walls are hit at grazing angles.)
The CARMEN importer maps logged 81.83-81.91 m through this same function. Every other code
is an invalid reading.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np

from drivers.sick.codec import Telegram
from drivers.sick.constants import (
    ABOVE_MAX_OFFSET,
    AVAILABILITY_REALTIME_INDEX,
    BAUD_MODES,
    DAZZLE_OFFSET,
    INSTALLATION_PASSWORD,
    RANGE_MASK,
    REFLECTOR_SHIFT,
    REPLY_FLAG,
    SCANNER_ADDRESS,
    UNIT_METRES,
    VARIANTS,
    Command,
    MeasuringMode,
    Mode,
    Reply,
    Units,
)
from knowledge.errors import ProtocolError


def _expect(t: Telegram, code: int) -> None:
    if t.command != code:
        raise ProtocolError(f"expected reply 0x{code:02x}, got 0x{t.command:02x}")


def _reply(code: int, data: bytes, status: int, address: int) -> Telegram:
    return Telegram(REPLY_FLAG | address, code, data, status)


# ---------------------------------------------------------------------------- requests
def switch_mode(
    mode: int, password: bytes = INSTALLATION_PASSWORD, *, address: int = SCANNER_ADDRESS
) -> Telegram:
    """0x20: change the operating mode (or the baud rate; see :data:`~drivers.sick.constants.BAUD_MODES`)."""
    data = bytes([mode]) + (password.ljust(8, b"\0")[:8] if mode == Mode.INSTALLATION else b"")
    return Telegram(address, Command.SWITCH_MODE, data)


def set_baud(baud: int, *, address: int = SCANNER_ADDRESS) -> Telegram:
    """0x20 with the baud code of ``baud`` (9600, 19200, 38400 or 500000)."""
    if baud not in BAUD_MODES:
        raise ValueError(f"the LMS 2xx speaks 9600, 19200, 38400 or 500000 baud, not {baud}")
    return switch_mode(BAUD_MODES[baud], address=address)


def request_values(*, address: int = SCANNER_ADDRESS) -> Telegram:
    """0x30 0x01: send all measured values of one scan (0xB0)."""
    return Telegram(address, Command.REQUEST_VALUES, b"\x01")


def request_status(*, address: int = SCANNER_ADDRESS) -> Telegram:
    return Telegram(address, Command.STATUS)


def request_type(*, address: int = SCANNER_ADDRESS) -> Telegram:
    return Telegram(address, Command.TYPE)


def request_config(*, address: int = SCANNER_ADDRESS) -> Telegram:
    return Telegram(address, Command.READ_CONFIG)


def request_errors(*, address: int = SCANNER_ADDRESS) -> Telegram:
    return Telegram(address, Command.ERRORS)


def request_reset(*, address: int = SCANNER_ADDRESS) -> Telegram:
    return Telegram(address, Command.RESET)


def check_variant(angle_deg: int, resolution_cdeg: int) -> None:
    """Raise ValueError unless (angle, resolution) is a variant the LMS 2xx offers."""
    if angle_deg not in VARIANTS or resolution_cdeg not in VARIANTS[angle_deg]:
        offered = ", ".join(f"{a}°/{r / 100:g}°" for a, rs in VARIANTS.items() for r in rs)
        raise ValueError(
            f"the LMS 2xx has no {angle_deg}°/{resolution_cdeg / 100:g}° variant; it offers {offered}"
        )


def set_variant(angle_deg: int, resolution_cdeg: int, *, address: int = SCANNER_ADDRESS) -> Telegram:
    """0x3B: scan angle (100 or 180°) and resolution (25, 50 or 100 hundredths of a degree)."""
    check_variant(angle_deg, resolution_cdeg)
    return Telegram(address, Command.VARIANT, struct.pack("<HH", angle_deg, resolution_cdeg))


def parse_variant_request(t: Telegram) -> tuple[int, int]:
    """(angle deg, resolution 1/100 deg) asked for by a 0x3B request."""
    if t.command != Command.VARIANT or len(t.data) != 4:
        raise ProtocolError("a variant request is 0x3B with angle and resolution words")
    a, r = struct.unpack("<HH", t.data)
    return int(a), int(r)


# ---------------------------------------------------------------------------- small replies
def mode_reply(result: int, *, status: int = 0, address: int = SCANNER_ADDRESS) -> Telegram:
    return _reply(Reply.SWITCH_MODE, bytes([result]), status, address)


def decode_mode_reply(t: Telegram) -> int:
    """The result byte of 0xA0 (0 ok, 1 not possible, 2 wrong password)."""
    _expect(t, Reply.SWITCH_MODE)
    if not t.data:
        raise ProtocolError("0xA0 reply without its result byte")
    return t.data[0]


@dataclass(frozen=True)
class VariantReply:
    """0xBB: whether the variant was accepted and the variant now active."""

    ok: bool
    angle_deg: int
    resolution_cdeg: int

    def telegram(self, *, status: int = 0, address: int = SCANNER_ADDRESS) -> Telegram:
        data = bytes([1 if self.ok else 0]) + struct.pack("<HH", self.angle_deg, self.resolution_cdeg)
        return _reply(Reply.VARIANT, data, status, address)

    @classmethod
    def decode(cls, t: Telegram) -> VariantReply:
        _expect(t, Reply.VARIANT)
        if len(t.data) < 5:
            raise ProtocolError(f"0xBB reply too short: {len(t.data)} data bytes, need 5")
        a, r = struct.unpack_from("<HH", t.data, 1)
        return cls(t.data[0] == 1, int(a), int(r))


def type_reply(type_string: str, *, status: int = 0, address: int = SCANNER_ADDRESS) -> Telegram:
    return _reply(Reply.TYPE, type_string.encode("ascii"), status, address)


def decode_type_reply(t: Telegram) -> str:
    _expect(t, Reply.TYPE)
    return t.data.decode("ascii", errors="replace").strip(" \0")


def errors_reply(
    errors: list[tuple[int, int]], *, status: int = 0, address: int = SCANNER_ADDRESS
) -> Telegram:
    return _reply(Reply.ERRORS, b"".join(bytes(e) for e in errors), status, address)


def decode_errors_reply(t: Telegram) -> list[tuple[int, int]]:
    """(error type, error number) pairs of 0xB2."""
    _expect(t, Reply.ERRORS)
    d = t.data
    return [(d[i], d[i + 1]) for i in range(0, len(d) - 1, 2)]


# ---------------------------------------------------------------------------- configuration
_CONFIG = struct.Struct("<HBBBBBBBBBBB15sBBHH")


@dataclass(frozen=True)
class ScannerConfig:
    """The 34 configuration bytes of 0x74/0xF4 (blocks A … A4 of the telegram listing).

    Only ``availability``, ``measuring_mode`` and ``units`` matter to the driver; the rest
    is carried through so a configuration round-trips byte for byte.
    """

    blanking: int = 0
    stop_threshold: int = 0
    peak_threshold: int = 0
    availability: int = 0
    measuring_mode: int = MeasuringMode.R8_80_FIELDS_AB_DAZZLE
    units: int = Units.CM
    temporary_field: int = 0
    subtractive_fields: int = 0
    multiple_evaluation: int = 0
    restart: int = 0
    restart_time: int = 0
    multiple_evaluation_suppressed: int = 0
    contour: bytes = bytes(15)
    pixel_oriented_evaluation: int = 0
    single_value_evaluation_mode: int = 0
    restart_times_bc: int = 0
    dazzle_multiple_evaluation: int = 0

    def encode(self) -> bytes:
        return _CONFIG.pack(
            self.blanking,
            self.stop_threshold,
            self.peak_threshold,
            self.availability,
            self.measuring_mode,
            self.units,
            self.temporary_field,
            self.subtractive_fields,
            self.multiple_evaluation,
            self.restart,
            self.restart_time,
            self.multiple_evaluation_suppressed,
            self.contour,
            self.pixel_oriented_evaluation,
            self.single_value_evaluation_mode,
            self.restart_times_bc,
            self.dazzle_multiple_evaluation,
        )

    @classmethod
    def from_bytes(cls, b: bytes) -> ScannerConfig:
        if len(b) < _CONFIG.size:
            raise ProtocolError(f"configuration block too short: {len(b)} bytes, need {_CONFIG.size}")
        return cls(*_CONFIG.unpack_from(b))

    def telegram(self, *, status: int = 0, address: int = SCANNER_ADDRESS) -> Telegram:
        return _reply(Reply.READ_CONFIG, self.encode(), status, address)

    @classmethod
    def decode(cls, t: Telegram) -> ScannerConfig:
        _expect(t, Reply.READ_CONFIG)
        return cls.from_bytes(t.data)

    @property
    def realtime_index(self) -> bool:
        """Whether 0xB0 telegrams carry a real-time scan index after the values."""
        return bool(self.availability & AVAILABILITY_REALTIME_INDEX)

    @property
    def unit_metres(self) -> float:
        if self.units not in UNIT_METRES:
            raise ProtocolError(f"unknown measured-value units code {self.units} (0 is cm, 1 is mm)")
        return UNIT_METRES[self.units]


# ---------------------------------------------------------------------------- status
_STATUS_DATA_LEN = 152  # bytes after the reply code in the virtual LMS's 0xB1


@dataclass(frozen=True)
class ScannerStatus:
    """The fields of 0xB1 the driver reports (offsets in the module docstring)."""

    software_version: str = ""
    operating_mode: int = Mode.ON_REQUEST
    device_status: int = 0
    variant_type: int = 0
    motor_revolutions: int = 0
    measuring_mode: int = MeasuringMode.R8_80_FIELDS_AB_DAZZLE
    angle_deg: int = 180
    resolution_cdeg: int = 50
    baud_field: int = 0
    address: int = 0
    units: int = Units.CM
    laser_on: bool = True
    prom_version: str = ""

    def encode(self) -> bytes:
        """Data bytes (after the reply code); unknown fields are zero."""
        p = bytearray(_STATUS_DATA_LEN + 1)  # indices as in the payload, p[0] = reply code
        p[1:8] = self.software_version.encode("ascii").ljust(7)[:7]
        p[8] = self.operating_mode
        p[9] = self.device_status
        p[18] = self.variant_type
        struct.pack_into("<H", p, 67, self.motor_revolutions)
        p[102] = self.measuring_mode
        struct.pack_into("<HH", p, 107, self.angle_deg, self.resolution_cdeg)
        struct.pack_into("<H", p, 116, self.baud_field)
        p[120] = self.address
        p[122] = self.units
        p[123] = 1 if self.laser_on else 0
        p[124:131] = self.prom_version.encode("ascii").ljust(7)[:7]
        return bytes(p[1:])

    def telegram(self, *, status: int = 0, address: int = SCANNER_ADDRESS) -> Telegram:
        return _reply(Reply.STATUS, self.encode(), status, address)

    @classmethod
    def decode(cls, t: Telegram) -> ScannerStatus:
        _expect(t, Reply.STATUS)
        if len(t.data) < 130:
            raise ProtocolError(f"0xB1 reply too short: {len(t.data)} data bytes, need at least 130")
        p = b"\0" + t.data
        angle, res = struct.unpack_from("<HH", p, 107)
        return cls(
            software_version=p[1:8].decode("ascii", errors="replace").strip(" \0"),
            operating_mode=p[8],
            device_status=p[9],
            variant_type=p[18],
            motor_revolutions=struct.unpack_from("<H", p, 67)[0],
            measuring_mode=p[102],
            angle_deg=int(angle),
            resolution_cdeg=int(res),
            baud_field=struct.unpack_from("<H", p, 116)[0],
            address=p[120],
            units=p[122],
            laser_on=bool(p[123]),
            prom_version=p[124:131].decode("ascii", errors="replace").strip(" \0"),
        )


# ---------------------------------------------------------------------------- measured values
@dataclass(frozen=True, eq=False)
class MeasuredValues:
    """The content of one 0xB0 telegram.

    Attributes:
        values: ``(n,)`` uint16 raw value words (range bits plus flag/reflector bits).
        units: units code from bits 14–15 of the count word (0 cm, 1 mm).
        partial_index: bits 11–12: start offset of a partial scan in 0.25° steps.
        partial: bit 13: the values are a partial scan.
        realtime_index: the real-time scan index byte, or None when absent.
    """

    values: np.ndarray
    units: int = Units.CM
    partial_index: int = 0
    partial: bool = False
    realtime_index: int | None = None

    def __post_init__(self) -> None:
        v = np.asarray(self.values)
        if v.ndim != 1 or v.size > 0x3FF:
            raise ValueError(f"0xB0 carries 1-D values, at most 1023 of them; got shape {v.shape}")
        if v.size and (v.min() < 0 or v.max() > 0xFFFF):
            raise ValueError("measured value words must fit 16 bits")
        object.__setattr__(self, "values", np.ascontiguousarray(v, dtype=np.uint16))

    @property
    def count_word(self) -> int:
        return (
            int(self.values.size)
            | (self.partial_index & 0x3) << 11
            | int(self.partial) << 13
            | (self.units & 0x3) << 14
        )

    def telegram(self, *, status: int = 0, address: int = SCANNER_ADDRESS) -> Telegram:
        data = struct.pack("<H", self.count_word) + self.values.astype("<u2").tobytes()
        if self.realtime_index is not None:
            data += bytes([self.realtime_index & 0xFF])
        return _reply(Reply.VALUES, data, status, address)

    @classmethod
    def decode(cls, t: Telegram, *, realtime_index: bool | None = None) -> MeasuredValues:
        """Decode 0xB0; ``realtime_index`` None infers the trailing index byte from the length."""
        _expect(t, Reply.VALUES)
        d = t.data
        if len(d) < 2:
            raise ProtocolError("0xB0 reply without its count word")
        (word,) = struct.unpack_from("<H", d)
        n = word & 0x3FF
        extra = len(d) - 2 - 2 * n
        if realtime_index is None:
            realtime_index = extra == 1
        if extra != (1 if realtime_index else 0):
            raise ProtocolError(f"0xB0 announces {n} values but carries {len(d) - 2} value bytes")
        values = np.frombuffer(d, dtype="<u2", count=n, offset=2)
        return cls(
            values=values,
            units=(word >> 14) & 0x3,
            partial_index=(word >> 11) & 0x3,
            partial=bool(word & 0x2000),
            realtime_index=d[-1] if realtime_index else None,
        )


def range_mask(measuring_mode: int) -> int:
    if measuring_mode not in RANGE_MASK:
        raise ProtocolError(
            f"measuring mode 0x{measuring_mode:02x} does not report ranges this driver can read "
            "(use one of the 8/80 m, 16 m or 32 m modes)"
        )
    return RANGE_MASK[measuring_mode]


def range_max_m(units: int, measuring_mode: int = MeasuringMode.R8_80_FIELDS_AB_DAZZLE) -> float:
    """The largest valid range in metres: one unit below the "value > maximum" code."""
    above_max = range_mask(measuring_mode) - ABOVE_MAX_OFFSET
    return (above_max - 1) * UNIT_METRES[units]


def values_to_ranges(
    values: np.ndarray, units: int, measuring_mode: int = MeasuringMode.R8_80_FIELDS_AB_DAZZLE
) -> tuple[np.ndarray, np.ndarray | None]:
    """Raw 0xB0 words → ``(ranges (n,) float32 metres, intensities (n,) float32 or None)``.

    Error codes map as the module docstring's table says: "> maximum" (8183) and "no echo"
    (8191, the top of the mask) → ``range_max_m`` (no return), the codes between them → 0.0
    (invalid). Intensities are the reflector levels of the reflector modes.
    """
    if units not in UNIT_METRES:
        raise ProtocolError(f"unknown measured-value units code {units} (0 is cm, 1 is mm)")
    mask = range_mask(measuring_mode)
    v = np.asarray(values, dtype=np.uint16)
    raw = (v & mask).astype(np.int32)
    above_max = mask - ABOVE_MAX_OFFSET
    unit = UNIT_METRES[units]
    ranges = raw.astype(np.float32) * np.float32(unit)
    ranges[raw > above_max] = 0.0
    ranges[(raw == above_max) | (raw == mask)] = np.float32((above_max - 1) * unit)
    intensities = None
    if measuring_mode in REFLECTOR_SHIFT:
        intensities = (v >> REFLECTOR_SHIFT[measuring_mode]).astype(np.float32)
    return ranges, intensities


def ranges_to_values(
    ranges: np.ndarray, units: int, measuring_mode: int = MeasuringMode.R8_80_FIELDS_AB_DAZZLE
) -> np.ndarray:
    """Metres → raw 0xB0 words (what a scanner would send).

    Ranges at or beyond the largest valid value (and +inf) become the "value > maximum" code;
    NaN, -inf, negative or zero ranges become "dazzle" (an invalid reading; the top of the
    mask is "no echo", a no-return).
    """
    if units not in UNIT_METRES:
        raise ValueError(f"unknown measured-value units code {units} (0 is cm, 1 is mm)")
    mask = range_mask(measuring_mode)
    above_max = mask - ABOVE_MAX_OFFSET
    invalid = mask - DAZZLE_OFFSET
    r = np.asarray(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        units_f = np.round(r / UNIT_METRES[units])
        out = np.where(units_f >= above_max, above_max, units_f)
        out = np.where(~np.isfinite(r) & ~np.isposinf(r), invalid, out)
        out = np.where(np.isposinf(r), above_max, out)
        out = np.where(r <= 0, invalid, out)
    return out.astype(np.uint16)


def scan_revolutions(angle_deg: int, resolution_cdeg: int) -> int:
    """Mirror turns per complete scan: the LMS interlaces 1° sweeps for finer resolutions."""
    return max(1, 100 // resolution_cdeg)


def n_values(angle_deg: int, resolution_cdeg: int) -> int:
    """Values in a complete scan of a variant: 181 for 180°/1°, 361 for 180°/0.5°, 401 for 100°/0.25°."""
    return angle_deg * 100 // resolution_cdeg + 1


def scan_period_s(angle_deg: int, resolution_cdeg: int) -> float:
    """Seconds between complete scans (1/75 s per mirror turn)."""
    return scan_revolutions(angle_deg, resolution_cdeg) / 75.0


def angle_min_rad(angle_deg: int) -> float:
    """Angle of the first beam: the scan is centred on the sensor's x axis (LMS 90°)."""
    return -math.radians(angle_deg) / 2.0
