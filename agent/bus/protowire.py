"""The protobuf wire format, just enough to read Foxglove messages and add our own fields.

The Foxglove SDK encodes its message types but cannot decode them, and the ``protobuf``
package is not a dependency; the wire format is small (varints, 64-bit, length-delimited,
32-bit), so the codecs parse it here. Every malformed input raises
:class:`~knowledge.errors.ProtocolError`, never another exception.

Reference: https://protobuf.dev/programming-guides/encoding/
"""

from __future__ import annotations

import struct
from collections.abc import Iterator

import numpy as np

from knowledge.errors import ProtocolError

VARINT, I64, LEN, I32 = 0, 1, 2, 5
_WIRE_NAMES = {VARINT: "varint", I64: "64-bit", LEN: "length-delimited", I32: "32-bit"}
_DOUBLE = struct.Struct("<d")


def _read_varint(data: bytes, pos: int) -> tuple[int, int]:
    result = 0
    shift = 0
    end = len(data)
    while True:
        if pos >= end:
            raise ProtocolError(f"protobuf: varint runs past the end of the message at byte {pos}")
        byte = data[pos]
        pos += 1
        result |= (byte & 0x7F) << shift
        if byte < 0x80:
            return result, pos
        shift += 7
        if shift >= 70:
            raise ProtocolError(f"protobuf: varint longer than 10 bytes at byte {pos}")


def iter_fields(data: bytes) -> Iterator[tuple[int, int, int | bytes]]:
    """Yield ``(field_number, wire_type, value)`` for each field of one message.

    ``value`` is an int for varints, and the raw bytes for 64-bit (8 bytes), 32-bit
    (4 bytes) and length-delimited fields.
    """
    pos = 0
    end = len(data)
    while pos < end:
        key, pos = _read_varint(data, pos)
        number, wire = key >> 3, key & 7
        if number == 0:
            raise ProtocolError(f"protobuf: field number 0 at byte {pos}")
        if wire == VARINT:
            value, pos = _read_varint(data, pos)
            yield number, wire, value
        elif wire in (I64, I32):
            size = 8 if wire == I64 else 4
            if pos + size > end:
                raise ProtocolError(
                    f"protobuf: field {number} ({size} bytes) runs past the end at byte {pos}"
                )
            yield number, wire, data[pos : pos + size]
            pos += size
        elif wire == LEN:
            size, pos = _read_varint(data, pos)
            if pos + size > end:
                raise ProtocolError(
                    f"protobuf: field {number} says {size} bytes but only {end - pos} remain at byte {pos}"
                )
            yield number, wire, data[pos : pos + size]
            pos += size
        else:
            raise ProtocolError(f"protobuf: field {number} has unsupported wire type {wire} at byte {pos}")


def fields_by_number(data: bytes) -> dict[int, list[tuple[int, int | bytes]]]:
    """All fields of a message grouped by number, in order: ``{number: [(wire, value), ...]}``."""
    out: dict[int, list[tuple[int, int | bytes]]] = {}
    for number, wire, value in iter_fields(data):
        out.setdefault(number, []).append((wire, value))
    return out


def _expect(field: str, wire: int, want: int) -> None:
    if wire != want:
        raise ProtocolError(
            f"protobuf: field {field} should be {_WIRE_NAMES[want]}, got {_WIRE_NAMES.get(wire, wire)}"
        )


def last_double(fields: dict[int, list[tuple[int, int | bytes]]], number: int, name: str) -> float:
    """A ``double`` field (last occurrence wins, as protobuf says); 0.0 when absent."""
    items = fields.get(number)
    if not items:
        return 0.0
    wire, value = items[-1]
    _expect(name, wire, I64)
    assert isinstance(value, bytes)
    return float(_DOUBLE.unpack(value)[0])


def last_varint(fields: dict[int, list[tuple[int, int | bytes]]], number: int, name: str) -> int:
    """An integer field as unsigned (last occurrence wins); 0 when absent."""
    items = fields.get(number)
    if not items:
        return 0
    wire, value = items[-1]
    _expect(name, wire, VARINT)
    assert isinstance(value, int)
    return value


def last_int64(fields: dict[int, list[tuple[int, int | bytes]]], number: int, name: str) -> int:
    """An ``int64``/``int32`` field: two's complement of the 64-bit varint; 0 when absent."""
    value = last_varint(fields, number, name) & 0xFFFF_FFFF_FFFF_FFFF
    return value - (1 << 64) if value >= 1 << 63 else value


def last_bytes(fields: dict[int, list[tuple[int, int | bytes]]], number: int, name: str) -> bytes:
    """A ``bytes`` or embedded-message field (last occurrence); ``b""`` when absent."""
    items = fields.get(number)
    if not items:
        return b""
    wire, value = items[-1]
    _expect(name, wire, LEN)
    assert isinstance(value, bytes)
    return value


def last_string(fields: dict[int, list[tuple[int, int | bytes]]], number: int, name: str) -> str:
    """A ``string`` field (UTF-8); ``""`` when absent."""
    raw = last_bytes(fields, number, name)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ProtocolError(f"protobuf: field {name} is not valid UTF-8 ({exc.reason})") from exc


def repeated_doubles(fields: dict[int, list[tuple[int, int | bytes]]], number: int, name: str) -> np.ndarray:
    """A ``repeated double`` field, packed or not, as a ``(n,)`` float64 array."""
    parts: list[np.ndarray] = []
    for wire, value in fields.get(number, ()):
        if wire not in (LEN, I64) or not isinstance(value, bytes):
            _expect(name, wire, LEN)
            continue
        if len(value) % 8:
            raise ProtocolError(
                f"protobuf: packed doubles of {name} are {len(value)} bytes, not a multiple of 8"
            )
        parts.append(np.frombuffer(value, dtype="<f8"))
    if not parts:
        return np.zeros(0)
    return np.concatenate(parts).astype(np.float64, copy=False)


def _varint(value: int) -> bytes:
    out = bytearray()
    value &= 0xFFFF_FFFF_FFFF_FFFF
    while value >= 0x80:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def encode_varint_field(number: int, value: int) -> bytes:
    """One varint field (``uint64``; negative values as 64-bit two's complement)."""
    return _varint(number << 3 | VARINT) + _varint(value)


def encode_double_field(number: int, value: float) -> bytes:
    """One ``double`` field."""
    return _varint(number << 3 | I64) + _DOUBLE.pack(value)


def encode_bytes_field(number: int, value: bytes) -> bytes:
    """One length-delimited field."""
    return _varint(number << 3 | LEN) + _varint(len(value)) + value
