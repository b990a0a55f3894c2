"""Numbers of the SICK LMS 200/211/221/291 serial protocol (telegram listing of the LMS 2xx).

Sources checked (2026-11): the sicktoolbox sources (``SickLMS.hh``/``SickLMS.cc``, the
``SickLMSBufferMonitor`` framing, BSD licence, Derenick & Miller) for command and reply
codes, payload offsets, variant and baud codes; the ROS ``sicktoolbox_wrapper``
(``sicklms.cpp``) for the error codes at the top of the 13-bit range ("see pg 124 of the
Sick LMS telegram listing"). The CRC reproduces the known telegrams
``02 00 02 00 20 24 34 08`` (start continuous output) and ``02 00 02 00 20 25 35 08``
(stop, i.e. back to output on request); see :mod:`drivers.sick.codec`.

Telegram (both directions)::

    STX 0x02 | ADR | LEN (uint16 LE) | CMD | DATA ... | [STATUS] | CRC (uint16 LE)

``LEN`` counts CMD + DATA (+ STATUS in replies). The host addresses the scanner with ADR
``0x00`` (its address); replies carry ``0x80 | address``. The scanner sends ACK (0x06) or
NAK (0x15) before a reply; a reply's command code is the request's ``| 0x80``.
"""

from __future__ import annotations

from enum import IntEnum

STX = 0x02
ACK = 0x06
NAK = 0x15

#: The scanner's default address (host → scanner telegrams carry it in ADR).
SCANNER_ADDRESS = 0x00
#: Set in ADR of every reply (scanner → host).
REPLY_FLAG = 0x80

#: Header bytes (STX, ADR, LEN) and trailer bytes (CRC).
HEADER_LEN = 4
CRC_LEN = 2
#: Largest LEN (CMD + DATA + STATUS) the LMS 2xx sends (sicktoolbox's payload maximum).
MAX_PAYLOAD = 812

#: Factory power-up baud rate.
POWER_UP_BAUD = 9600

#: The mirror turns at 75 Hz; an interlaced variant needs several turns per complete scan.
MIRROR_HZ = 75.0

#: The installation-mode password (factory default).
INSTALLATION_PASSWORD = b"SICK_LMS"


class Command(IntEnum):
    """Host → scanner command codes."""

    RESET = 0x10
    SWITCH_MODE = 0x20
    REQUEST_VALUES = 0x30
    STATUS = 0x31
    ERRORS = 0x32
    TYPE = 0x3A
    VARIANT = 0x3B
    READ_CONFIG = 0x74
    WRITE_CONFIG = 0x77


class Reply(IntEnum):
    """Scanner → host reply codes (``command | 0x80``; a reset answers 0x91, then 0x90)."""

    READY = 0x90
    RESET = 0x91
    SWITCH_MODE = 0xA0
    VALUES = 0xB0
    STATUS = 0xB1
    ERRORS = 0xB2
    TYPE = 0xBA
    VARIANT = 0xBB
    READ_CONFIG = 0xF4
    WRITE_CONFIG = 0xF7


def reply_code(command: int) -> int:
    """The reply code the scanner answers ``command`` with."""
    return Reply.RESET if command == Command.RESET else (command | 0x80) & 0xFF


class Mode(IntEnum):
    """Operating modes of command 0x20 (the baud codes are modes too)."""

    INSTALLATION = 0x00
    CONTINUOUS = 0x24
    ON_REQUEST = 0x25
    BAUD_38400 = 0x40
    BAUD_19200 = 0x41
    BAUD_9600 = 0x42
    BAUD_500K = 0x48


#: Baud rate → mode code of the 0x20 command.
BAUD_MODES: dict[int, Mode] = {
    9600: Mode.BAUD_9600,
    19200: Mode.BAUD_19200,
    38400: Mode.BAUD_38400,
    500000: Mode.BAUD_500K,
}
MODE_BAUDS: dict[int, int] = {int(m): b for b, m in BAUD_MODES.items()}

#: Reply byte of 0xA0.
MODE_SWITCH_OK = 0x00
MODE_SWITCH_NOT_POSSIBLE = 0x01
MODE_SWITCH_BAD_PASSWORD = 0x02


class Units(IntEnum):
    """Measured-value units (configuration byte E; also bits 14–15 of the 0xB0 count word)."""

    CM = 0x00
    MM = 0x01


#: Metres per unit.
UNIT_METRES: dict[int, float] = {Units.CM: 0.01, Units.MM: 0.001}


class MeasuringMode(IntEnum):
    """Measuring modes (configuration byte D): range and what the upper bits of a value carry."""

    R8_80_FIELDS_AB_DAZZLE = 0x00
    R8_80_REFLECTOR_3BIT = 0x01
    R8_80_FIELDS_ABC = 0x02
    R16_REFLECTOR_2BIT = 0x03
    R16_FIELDS_AB = 0x04
    R32_REFLECTOR_1BIT = 0x05
    R32_FIELD_A = 0x06
    R32_IMMEDIATE = 0x0F
    REFLECTIVITY = 0x3F


#: Bits of a measured value that carry the range, per measuring mode (sicktoolbox).
RANGE_MASK: dict[int, int] = {
    MeasuringMode.R8_80_FIELDS_AB_DAZZLE: 0x1FFF,
    MeasuringMode.R8_80_REFLECTOR_3BIT: 0x1FFF,
    MeasuringMode.R8_80_FIELDS_ABC: 0x1FFF,
    MeasuringMode.R16_REFLECTOR_2BIT: 0x3FFF,
    MeasuringMode.R16_FIELDS_AB: 0x3FFF,
    MeasuringMode.R32_REFLECTOR_1BIT: 0x7FFF,
    MeasuringMode.R32_FIELD_A: 0x7FFF,
    MeasuringMode.R32_IMMEDIATE: 0xFFFF,
}
#: Modes whose upper bits are reflector (intensity) levels: mode → bit shift of the levels.
REFLECTOR_SHIFT: dict[int, int] = {
    MeasuringMode.R8_80_REFLECTOR_3BIT: 13,
    MeasuringMode.R16_REFLECTOR_2BIT: 14,
    MeasuringMode.R32_REFLECTOR_1BIT: 15,
}

# Error codes at the top of the 13-bit range (8 m / 80 m modes), telegram listing p. 124.
# For the 14- and 15-bit modes the same offsets below the top are assumed (unverified).
# What each becomes in a LaserScan is the table in drivers.sick.telegrams (and docs/drivers.md).
#: "Measured value not valid" in the listing; LMS units log it for a beam that got no echo
#: back, so it is a no-return (36,004 of the 1,724,760 readings of the Freiburg 079 log).
ERR_NO_ECHO = 8191
#: The listing's name for 8191, kept for callers that use it.
ERR_NOT_VALID = ERR_NO_ECHO
ERR_DAZZLE = 8190
ERR_OPERATION_OVERFLOW = 8189
ERR_SNR_TOO_SMALL = 8187
ERR_CHANNEL1 = 8186
ERR_ABOVE_MAX = 8183
#: Distance between the top of the range mask and "measured value > maximum".
ABOVE_MAX_OFFSET = 0x1FFF - ERR_ABOVE_MAX
#: Distance between the top of the range mask and "dazzle", the code an invalid reading is
#: encoded with (:func:`~drivers.sick.telegrams.ranges_to_values`).
DAZZLE_OFFSET = 0x1FFF - ERR_DAZZLE

#: Variant (command 0x3B): scan angle in degrees → allowed resolutions in 1/100 degree.
VARIANTS: dict[int, tuple[int, ...]] = {180: (50, 100), 100: (25, 50, 100)}

#: Bit of the configuration's availability byte: a real-time scan index follows the values.
AVAILABILITY_REALTIME_INDEX = 0x02
