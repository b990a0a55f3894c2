"""The LMS 2xx telegram codec: SICK's CRC, framing, and a resynchronising stream parser.

Pure code — no I/O: bytes in, :class:`Telegram` and :class:`Acknowledge` events out. The
parser is fed whatever the serial line delivered (any chunking) and

* hunts for STX (reporting the single-byte ACK 0x06 / NAK 0x15 it meets on the way),
* checks the address (direction) and that LEN is plausible for the command byte,
* waits for the whole telegram and checks the CRC,
* emits the telegram only when the CRC matches. A bad CRC is counted and the telegram
  dropped; hunting resumes at the byte after the rejected STX, so a valid telegram hidden
  behind a spurious STX is still found.

The CRC is SICK's own (telegram listing, "Formation of the CRC16 checksum"): a 16-bit
shift register with generator 0x8005 into which each byte is xored *together with the
previous byte* (``byte | previous << 8``). It covers STX through the last payload byte and is
sent little-endian. It is linear over GF(2), which :func:`crc16` uses to replace the per-byte
loop by one table look-up per byte and an xor-reduction (numpy) for long telegrams.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import Literal

import numpy as np

from drivers.sick.constants import (
    ACK,
    CRC_LEN,
    HEADER_LEN,
    MAX_PAYLOAD,
    NAK,
    REPLY_FLAG,
    STX,
    Command,
    Reply,
)
from knowledge.errors import ProtocolError

CRC_POLY = 0x8005

Direction = Literal["reply", "request", "any"]


# ---------------------------------------------------------------------------- CRC
def crc16_reference(data: bytes | bytearray | memoryview) -> int:
    """SICK's CRC16 of ``data``, computed byte by byte as the telegram listing describes."""
    crc = 0
    prev = 0
    for b in bytes(data):
        crc = ((crc & 0x7FFF) << 1) ^ CRC_POLY if crc & 0x8000 else (crc << 1) & 0xFFFF
        crc ^= b | (prev << 8)
        prev = b
    return crc


def _shift(c: np.ndarray) -> np.ndarray:
    """One step of the CRC register (no input), vectorised over uint32 values < 2**16."""
    return np.where(c & 0x8000, ((c & 0x7FFF) << 1) ^ CRC_POLY, (c << 1) & 0xFFFF)


def _build_table(max_len: int) -> np.ndarray:
    """``T[k, b]``: what byte ``b`` contributes to the CRC when ``k`` bytes follow it.

    The register is linear: a byte enters once as the low half of its own input word and
    once as the high half of the next one, so its contribution is ``L^k(b) ^ L^(k-1)(b<<8)``
    with ``L`` one register shift. The rows are stored last-position-first (row
    ``max_len - 1 - k``) so a telegram of ``n`` bytes uses the contiguous rows
    ``max_len - n ... max_len - 1``.
    """
    b = np.arange(256, dtype=np.uint32)
    low: np.ndarray = b.copy()  # L^k(b)
    high_prev: np.ndarray = np.zeros(256, dtype=np.uint32)  # L^(k-1)(b << 8); nothing for the last byte
    high: np.ndarray = b << 8
    rows = np.empty((max_len, 256), dtype=np.uint16)
    for k in range(max_len):
        rows[max_len - 1 - k] = low ^ high_prev
        low = _shift(low)
        high_prev = high
        high = _shift(high)
    return rows.reshape(-1)


#: Longest CRC-covered span: header + the largest payload.
_MAX_CRC_SPAN = HEADER_LEN + MAX_PAYLOAD
_TABLE = _build_table(_MAX_CRC_SPAN)
_ROW_BASE = np.arange(_MAX_CRC_SPAN, dtype=np.intp) * 256
#: Below this length the plain loop beats the numpy call overhead.
_TABLE_MIN_LEN = 48


def crc16(data: bytes | bytearray | memoryview) -> int:
    """SICK's CRC16 of ``data`` (same result as :func:`crc16_reference`, faster on long spans)."""
    n = len(data)
    if n < _TABLE_MIN_LEN or n > _MAX_CRC_SPAN:
        return crc16_reference(data)
    idx = _ROW_BASE[_MAX_CRC_SPAN - n :] + np.frombuffer(data, dtype=np.uint8)
    return int(np.bitwise_xor.reduce(_TABLE[idx]))


# ---------------------------------------------------------------------------- telegrams
class Acknowledge(IntEnum):
    """The single bytes the scanner sends before a reply: accepted or refused."""

    ACK = ACK
    NAK = NAK


@dataclass(frozen=True)
class Telegram:
    """One LMS telegram.

    Attributes:
        address: ADR byte: the scanner's address (host → scanner) or ``0x80 | address``
            (replies).
        command: command (request) or reply code.
        data: the bytes between the command and the status/CRC.
        status: the status byte closing a reply; None for host → scanner telegrams.
    """

    address: int
    command: int
    data: bytes = b""
    status: int | None = None

    def __post_init__(self) -> None:
        for name, v in (("address", self.address), ("command", self.command)):
            if not 0 <= v <= 0xFF:
                raise ValueError(f"Telegram.{name} must be a byte (0..255), got {v}")
        if self.status is not None and not 0 <= self.status <= 0xFF:
            raise ValueError(f"Telegram.status must be a byte (0..255) or None, got {self.status}")
        if self.is_reply != (self.status is not None):
            raise ValueError(
                "a reply (address with bit 0x80) needs a status byte and a request must not have one; "
                f"got address 0x{self.address:02x}, status {self.status}"
            )
        if self.payload_len > MAX_PAYLOAD:
            raise ValueError(
                f"telegram payload of {self.payload_len} bytes exceeds the LMS maximum {MAX_PAYLOAD}"
            )
        object.__setattr__(self, "data", bytes(self.data))

    @property
    def is_reply(self) -> bool:
        return bool(self.address & REPLY_FLAG)

    @property
    def payload_len(self) -> int:
        """The LEN field: command + data (+ status)."""
        return 1 + len(self.data) + (self.status is not None)

    def encode(self) -> bytes:
        """The telegram's bytes on the line, CRC included."""
        body = bytearray(struct.pack("<BBH", STX, self.address, self.payload_len))
        body.append(self.command)
        body += self.data
        if self.status is not None:
            body.append(self.status)
        body += struct.pack("<H", crc16(body))
        return bytes(body)

    def __len__(self) -> int:
        """Bytes on the line."""
        return HEADER_LEN + self.payload_len + CRC_LEN


def decode_telegram(raw: bytes | bytearray | memoryview) -> Telegram:
    """Decode exactly one complete telegram (header, payload, CRC); raise ProtocolError if it is not one."""
    b = bytes(raw)
    if len(b) < HEADER_LEN + 1 + CRC_LEN or b[0] != STX:
        raise ProtocolError(f"not an LMS telegram: {len(b)} bytes starting with {b[:1].hex() or 'nothing'}")
    (length,) = struct.unpack_from("<H", b, 2)
    if len(b) != HEADER_LEN + length + CRC_LEN:
        raise ProtocolError(
            f"LEN says {length} payload bytes but the telegram has {len(b) - HEADER_LEN - CRC_LEN}"
        )
    (crc,) = struct.unpack_from("<H", b, HEADER_LEN + length)
    if crc != crc16(b[: HEADER_LEN + length]):
        raise ProtocolError(f"bad CRC 0x{crc:04x} (computed 0x{crc16(b[: HEADER_LEN + length]):04x})")
    return _telegram_from_payload(b[1], b[HEADER_LEN : HEADER_LEN + length])


def _telegram_from_payload(address: int, payload: bytes) -> Telegram:
    if address & REPLY_FLAG:
        if len(payload) < 2:
            raise ProtocolError("a reply telegram needs a command and a status byte")
        return Telegram(address, payload[0], payload[1:-1], payload[-1])
    return Telegram(address, payload[0], payload[1:])


# ---------------------------------------------------------------------------- plausibility
# LEN windows (CMD + DATA [+ STATUS]) for the codes we know; others get (1 or 2, MAX_PAYLOAD).
# Replies are kept loose where firmware variants may append bytes.
_REPLY_LEN: dict[int, tuple[int, int]] = {
    Reply.SWITCH_MODE: (3, 8),
    Reply.VALUES: (4, MAX_PAYLOAD),
    Reply.STATUS: (100, MAX_PAYLOAD),
    Reply.VARIANT: (7, 12),
    Reply.READ_CONFIG: (36, 64),
    Reply.WRITE_CONFIG: (37, 64),
    Reply.TYPE: (2, 64),
}
_REQUEST_LEN: dict[int, tuple[int, int]] = {
    Command.RESET: (1, 1),
    Command.SWITCH_MODE: (2, 12),
    Command.REQUEST_VALUES: (1, 6),
    Command.STATUS: (1, 1),
    Command.ERRORS: (1, 1),
    Command.TYPE: (1, 1),
    Command.VARIANT: (5, 5),
    Command.READ_CONFIG: (1, 1),
    Command.WRITE_CONFIG: (35, 35),
}


def plausible_length(address: int, command: int, length: int) -> bool:
    """Whether LEN is possible for this address (direction) and command byte."""
    if address & REPLY_FLAG:
        lo, hi = _REPLY_LEN.get(command, (2, MAX_PAYLOAD))
    else:
        lo, hi = _REQUEST_LEN.get(command, (1, MAX_PAYLOAD))
    return lo <= length <= hi


# ---------------------------------------------------------------------------- stream parser
@dataclass(frozen=True)
class ParserStats:
    """Counters of a :class:`StreamParser` (cumulative).

    Attributes:
        bytes: bytes fed.
        telegrams: telegrams emitted (CRC good).
        crc_errors: complete telegrams dropped for a bad CRC.
        resyncs: bytes skipped while hunting (garbage, rejected STX bytes).
        acks, naks: single ACK/NAK bytes seen between telegrams.
    """

    bytes: int = 0
    telegrams: int = 0
    crc_errors: int = 0
    resyncs: int = 0
    acks: int = 0
    naks: int = 0


_INTERESTING = re.compile(rb"[\x02\x06\x15]")


class StreamParser:
    """Turn a byte stream into telegrams and ACK/NAK events, resynchronising on garbage.

    Args:
        direction: ``"reply"`` accepts only scanner → host telegrams (ADR bit 0x80 set),
            ``"request"`` only host → scanner ones, ``"any"`` both (the bit decides whether a
            status byte ends the payload).
        address: if given, the scanner address (low 7 bits of ADR) telegrams must carry.
    """

    def __init__(self, direction: Direction = "reply", *, address: int | None = 0) -> None:
        if direction not in ("reply", "request", "any"):
            raise ValueError(f"direction must be 'reply', 'request' or 'any', got {direction!r}")
        self.direction: Direction = direction
        self.address = address
        self._buf = bytearray()
        # where a telegram can start: STX, plus the address byte when it is known
        if address is not None and direction != "any":
            adr = address | (REPLY_FLAG if direction == "reply" else 0)
            self._stx = re.compile(re.escape(bytes([STX, adr])))
        else:
            self._stx = re.compile(re.escape(bytes([STX])))
        self._n_bytes = 0
        self._n_telegrams = 0
        self._n_crc = 0
        self._n_resync = 0
        self._n_ack = 0
        self._n_nak = 0

    @property
    def stats(self) -> ParserStats:
        """A frozen snapshot of the counters."""
        return ParserStats(
            self._n_bytes, self._n_telegrams, self._n_crc, self._n_resync, self._n_ack, self._n_nak
        )

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a telegram."""
        return len(self._buf)

    def reset(self) -> None:
        """Forget buffered bytes (after a baud change or reconnect); counters are kept."""
        self._buf.clear()

    def _address_ok(self, adr: int) -> bool:
        is_reply = bool(adr & REPLY_FLAG)
        if self.direction == "reply" and not is_reply:
            return False
        if self.direction == "request" and is_reply:
            return False
        return self.address is None or (adr & 0x7F) == self.address

    def feed(self, data: bytes | bytearray | memoryview) -> list[Telegram | Acknowledge]:
        """Add bytes; return the telegrams and ACK/NAK events completed by them, in order."""
        self._n_bytes += len(data)
        buf = self._buf
        buf += data
        events: list[Telegram | Acknowledge] = []
        pos = 0
        n = len(buf)
        lookahead: int | None = None
        while pos < n:
            m = _INTERESTING.search(buf, pos)
            if m is None:
                self._n_resync += n - pos
                pos = n
                break
            start = m.start()
            self._n_resync += start - pos
            pos = start
            byte = buf[pos]
            if byte == ACK:
                events.append(Acknowledge.ACK)
                self._n_ack += 1
                pos += 1
                continue
            if byte == NAK:
                events.append(Acknowledge.NAK)
                self._n_nak += 1
                pos += 1
                continue
            # STX: need ADR, LEN and CMD to judge the header
            if n - pos < HEADER_LEN + 1:
                break
            adr = buf[pos + 1]
            length = buf[pos + 2] | (buf[pos + 3] << 8)
            if not (self._address_ok(adr) and plausible_length(adr, buf[pos + 4], length)):
                self._n_resync += 1
                pos += 1
                continue
            end = pos + HEADER_LEN + length
            if n < end + CRC_LEN:
                # Incomplete. A complete valid telegram starting later in the buffer means this
                # STX was garbage: reject it now rather than wait for bytes it claims.
                if lookahead is None or 0 <= lookahead < pos:
                    lookahead = self._next_valid_start(pos + 1)  # -1 stays true for later STX
                if lookahead > pos:
                    self._n_resync += 1
                    pos += 1
                    continue
                break
            crc = buf[end] | (buf[end + 1] << 8)
            if crc != crc16(memoryview(buf)[pos:end]):
                self._n_crc += 1
                self._n_resync += 1
                pos += 1
                continue
            events.append(_telegram_from_payload(adr, bytes(buf[pos + HEADER_LEN : end])))
            self._n_telegrams += 1
            pos = end + CRC_LEN
        del buf[:pos]
        return events

    def _next_valid_start(self, start: int) -> int:
        """Offset of the first complete, CRC-valid telegram at or after ``start``; -1 if none."""
        buf = self._buf
        n = len(buf)
        for m in self._stx.finditer(buf, start):
            q = m.start()
            if n - q < HEADER_LEN + 1:
                break
            adr = buf[q + 1]
            length = buf[q + 2] | (buf[q + 3] << 8)
            if not (self._address_ok(adr) and plausible_length(adr, buf[q + 4], length)):
                continue
            end = q + HEADER_LEN + length
            if n < end + CRC_LEN:
                continue
            if buf[end] | (buf[end + 1] << 8) == crc16(memoryview(buf)[q:end]):
                return q
        return -1
