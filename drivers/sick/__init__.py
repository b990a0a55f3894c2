"""SICK LMS 200/211/221/291 laser scanners on a serial line.

* :mod:`drivers.sick.constants` — the protocol's numbers (commands, modes, baud codes, error codes);
* :mod:`drivers.sick.codec` — SICK's CRC, telegram framing and the resynchronising stream parser;
* :mod:`drivers.sick.telegrams` — what the telegrams say (requests, typed replies, values ↔ metres);
* :mod:`drivers.sick.driver` — :class:`LMS2xx`, the asyncio driver producing
  :class:`~drivers.messages.LaserScan` messages.

The virtual scanner that speaks the same bytes on a pseudo-terminal is :mod:`drivers.sim.lms`.
"""

from drivers.sick.codec import Acknowledge, ParserStats, StreamParser, Telegram, crc16
from drivers.sick.driver import LMS2xx, LmsStats, ScannerInfo

__all__ = [
    "Acknowledge",
    "LMS2xx",
    "LmsStats",
    "ParserStats",
    "ScannerInfo",
    "StreamParser",
    "Telegram",
    "crc16",
]
