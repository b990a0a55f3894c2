"""The LMS 2xx telegram codec: CRC, framing, the resynchronising parser, payload contents."""

from __future__ import annotations

import itertools
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.sick import telegrams as tg
from drivers.sick.codec import (
    Acknowledge,
    StreamParser,
    Telegram,
    crc16,
    crc16_reference,
    decode_telegram,
)
from drivers.sick.constants import (
    ACK,
    BAUD_MODES,
    ERR_ABOVE_MAX,
    ERR_CHANNEL1,
    ERR_DAZZLE,
    ERR_NO_ECHO,
    ERR_NOT_VALID,
    ERR_OPERATION_OVERFLOW,
    ERR_SNR_TOO_SMALL,
    NAK,
    MeasuringMode,
    Mode,
    Units,
)
from knowledge.errors import ProtocolError

FAST = settings(
    max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)


# ---------------------------------------------------------------------------- CRC
def test_crc_reproduces_the_known_start_and_stop_telegrams() -> None:
    # from the LMS telegram listing / every LMS driver: start and stop continuous output
    assert Telegram(0x00, 0x20, b"\x24").encode() == bytes.fromhex("02 00 02 00 20 24 34 08")
    assert Telegram(0x00, 0x20, b"\x25").encode() == bytes.fromhex("02 00 02 00 20 25 35 08")
    assert crc16_reference(bytes.fromhex("02 00 02 00 20 24")) == 0x0834


@FAST
@given(st.binary(min_size=0, max_size=900))
def test_table_crc_equals_the_byte_loop(data: bytes) -> None:
    assert crc16(data) == crc16_reference(data)


def test_every_single_bit_flip_of_a_scan_telegram_is_detected() -> None:
    t = tg.MeasuredValues(np.arange(361, dtype=np.uint16) * 7).telegram()
    raw = bytearray(t.encode())
    assert decode_telegram(raw) == t
    for i in range(len(raw)):
        for bit in range(8):
            raw[i] ^= 1 << bit
            with pytest.raises(ProtocolError):
                decode_telegram(raw)
            raw[i] ^= 1 << bit


# ---------------------------------------------------------------------------- round trips
byte = st.integers(0, 255)
u16 = st.integers(0, 0xFFFF)
variants = st.sampled_from([(180, 50), (180, 100), (100, 25), (100, 50), (100, 100)])


@st.composite
def measured_values(draw: st.DrawFn) -> tg.MeasuredValues:
    n = draw(st.sampled_from([1, 101, 181, 201, 361, 401]))
    values = draw(st.lists(u16, min_size=n, max_size=n))
    return tg.MeasuredValues(
        np.array(values, dtype=np.uint16),
        units=draw(st.sampled_from([Units.CM, Units.MM])),
        partial_index=draw(st.integers(0, 3)),
        partial=draw(st.booleans()),
        realtime_index=draw(st.none() | byte),
    )


@st.composite
def configs(draw: st.DrawFn) -> tg.ScannerConfig:
    return tg.ScannerConfig(
        blanking=draw(u16),
        stop_threshold=draw(byte),
        peak_threshold=draw(byte),
        availability=draw(byte),
        measuring_mode=draw(byte),
        units=draw(byte),
        temporary_field=draw(byte),
        subtractive_fields=draw(byte),
        multiple_evaluation=draw(byte),
        restart=draw(byte),
        restart_time=draw(byte),
        multiple_evaluation_suppressed=draw(byte),
        contour=draw(st.binary(min_size=15, max_size=15)),
        pixel_oriented_evaluation=draw(byte),
        single_value_evaluation_mode=draw(byte),
        restart_times_bc=draw(u16),
        dazzle_multiple_evaluation=draw(u16),
    )


ascii7 = st.text(alphabet="ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.", min_size=1, max_size=7)


@st.composite
def statuses(draw: st.DrawFn) -> tg.ScannerStatus:
    a, r = draw(variants)
    return tg.ScannerStatus(
        software_version=draw(ascii7),
        operating_mode=draw(byte),
        device_status=draw(byte),
        variant_type=draw(byte),
        motor_revolutions=draw(u16),
        measuring_mode=draw(byte),
        angle_deg=a,
        resolution_cdeg=r,
        baud_field=draw(u16),
        address=draw(byte),
        units=draw(byte),
        laser_on=draw(st.booleans()),
        prom_version=draw(ascii7),
    )


requests = st.one_of(
    st.sampled_from(list(Mode)).map(tg.switch_mode),
    st.sampled_from(sorted(BAUD_MODES)).map(tg.set_baud),
    variants.map(lambda v: tg.set_variant(*v)),
    st.sampled_from(
        [
            tg.request_values(),
            tg.request_status(),
            tg.request_type(),
            tg.request_config(),
            tg.request_errors(),
        ]
    ),
    st.just(tg.request_reset()),
)
replies = st.one_of(
    st.integers(0, 2).map(tg.mode_reply),
    st.builds(
        tg.VariantReply, st.booleans(), st.sampled_from([100, 180]), st.sampled_from([25, 50, 100])
    ).map(lambda v: v.telegram()),
    st.text(alphabet="LMS0123456789;", min_size=1, max_size=20).map(tg.type_reply),
    st.lists(st.tuples(byte, byte), max_size=5).map(tg.errors_reply),
    configs().map(lambda c: c.telegram()),
    statuses().map(lambda s: s.telegram()),
    measured_values().map(lambda m: m.telegram()),
)
telegrams = st.one_of(requests, replies)


@FAST
@given(telegrams)
def test_every_telegram_type_round_trips_through_bytes(t: Telegram) -> None:
    raw = t.encode()
    assert len(raw) == len(t)
    assert decode_telegram(raw) == t
    assert StreamParser("any", address=None).feed(raw) == [t]


@FAST
@given(measured_values())
def test_measured_values_round_trip(m: tg.MeasuredValues) -> None:
    back = tg.MeasuredValues.decode(m.telegram(), realtime_index=m.realtime_index is not None)
    assert np.array_equal(back.values, m.values)
    assert (back.units, back.partial_index, back.partial, back.realtime_index) == (
        m.units,
        m.partial_index,
        m.partial,
        m.realtime_index,
    )


@FAST
@given(configs())
def test_configuration_round_trips(c: tg.ScannerConfig) -> None:
    assert tg.ScannerConfig.decode(c.telegram()) == c
    assert len(c.encode()) == 34


@FAST
@given(statuses())
def test_status_round_trips(s: tg.ScannerStatus) -> None:
    assert tg.ScannerStatus.decode(s.telegram()) == s


def test_request_bytes_follow_the_listing() -> None:
    assert tg.set_variant(180, 50).encode()[4:9] == bytes([0x3B, 0xB4, 0x00, 0x32, 0x00])
    assert tg.set_variant(100, 25).encode()[4:9] == bytes([0x3B, 0x64, 0x00, 0x19, 0x00])
    assert tg.set_baud(500000).encode()[4:6] == bytes([0x20, 0x48])
    assert tg.set_baud(38400).encode()[4:6] == bytes([0x20, 0x40])
    assert tg.switch_mode(Mode.INSTALLATION).data == b"\x00SICK_LMS"
    with pytest.raises(ValueError, match="9600, 19200, 38400 or 500000"):
        tg.set_baud(115200)
    with pytest.raises(ValueError, match=r"no 180°/0\.25° variant"):
        tg.set_variant(180, 25)


def test_scan_telegram_lengths_and_counts() -> None:
    assert tg.n_values(180, 50) == 361 and tg.n_values(180, 100) == 181 and tg.n_values(100, 25) == 401
    # a 361-value scan is the well-known 732-byte telegram
    assert len(tg.MeasuredValues(np.zeros(361, dtype=np.uint16)).telegram()) == 732
    assert tg.scan_period_s(180, 50) == pytest.approx(1 / 37.5)
    assert tg.scan_period_s(180, 100) == pytest.approx(1 / 75)


def test_count_word_bits() -> None:
    m = tg.MeasuredValues(np.zeros(361, dtype=np.uint16), units=Units.MM, partial_index=2, partial=True)
    (word,) = struct.unpack_from("<H", m.telegram().data)
    assert word & 0x3FF == 361
    assert (word >> 11) & 0x3 == 2
    assert word & 0x2000
    assert word >> 14 == Units.MM


def test_decode_rejects_a_count_that_does_not_match_the_length() -> None:
    t = tg.MeasuredValues(np.zeros(10, dtype=np.uint16)).telegram()
    bad = Telegram(t.address, t.command, t.data[:-4], t.status)
    with pytest.raises(ProtocolError, match="announces 10 values"):
        tg.MeasuredValues.decode(bad)
    with pytest.raises(ProtocolError, match="expected reply 0xb0"):
        tg.MeasuredValues.decode(tg.mode_reply(0))


# ---------------------------------------------------------------------------- ranges
def test_error_codes_map_to_range_max_or_invalid() -> None:
    codes = np.array(
        [
            ERR_ABOVE_MAX,
            ERR_NO_ECHO,
            ERR_DAZZLE,
            ERR_OPERATION_OVERFLOW,
            ERR_SNR_TOO_SMALL,
            ERR_CHANNEL1,
            8184,
            8185,
            8188,
            1234,
        ]
    )
    flags = np.array([0, 0, 0xE000, 0, 0, 0, 0, 0, 0, 0x2000], dtype=np.uint16)  # field bits must not matter
    ranges, intens = tg.values_to_ranges((codes | flags).astype(np.uint16), Units.MM)
    assert intens is None
    assert ranges[0] == pytest.approx(8.182)
    assert ranges[0] == pytest.approx(tg.range_max_m(Units.MM))
    # "no echo" is a no-return like "> maximum", not an invalid beam
    assert ranges[1] == ranges[0]
    assert np.all(ranges[2:9] == 0.0)
    assert ranges[9] == pytest.approx(1.234)
    assert tg.range_max_m(Units.CM) == pytest.approx(81.82)
    assert ERR_NOT_VALID == ERR_NO_ECHO == 8191


def test_no_echo_is_the_top_of_the_mask_in_every_mode() -> None:
    for mode, mask in ((MeasuringMode.R16_FIELDS_AB, 0x3FFF), (MeasuringMode.R32_FIELD_A, 0x7FFF)):
        above_max = mask - (0x1FFF - ERR_ABOVE_MAX)
        v = np.array([mask, above_max, above_max + 1, mask - 1], dtype=np.uint16)
        ranges, _ = tg.values_to_ranges(v, Units.CM, mode)
        assert ranges[0] == ranges[1] == pytest.approx(tg.range_max_m(Units.CM, mode))
        assert ranges[2] == ranges[3] == 0.0


def test_reflector_mode_reports_intensities() -> None:
    v = np.array([500 | (5 << 13), 700 | (1 << 13)], dtype=np.uint16)
    ranges, intens = tg.values_to_ranges(v, Units.CM, MeasuringMode.R8_80_REFLECTOR_3BIT)
    assert ranges.tolist() == pytest.approx([5.0, 7.0])
    assert intens is not None and intens.tolist() == [5.0, 1.0]


@FAST
@given(st.lists(st.floats(0.001, 8.18), min_size=1, max_size=50), st.sampled_from([Units.CM, Units.MM]))
def test_ranges_survive_the_wire_within_half_a_unit(ranges: list[float], units: int) -> None:
    r = np.array(ranges)
    unit = 0.01 if units == Units.CM else 0.001
    back, _ = tg.values_to_ranges(tg.ranges_to_values(r, units), units)
    ok = r >= unit / 2  # a range that rounds to 0 units is "no valid value"
    assert np.all(np.abs(back[ok] - r[ok]) <= unit / 2 + 1e-6)


def test_far_and_bad_ranges_encode_as_error_codes() -> None:
    v = tg.ranges_to_values(np.array([np.inf, 100.0, np.nan, -1.0, 0.0, -np.inf]), Units.MM)
    assert v.tolist() == [ERR_ABOVE_MAX, ERR_ABOVE_MAX, ERR_DAZZLE, ERR_DAZZLE, ERR_DAZZLE, ERR_DAZZLE]
    back, _ = tg.values_to_ranges(v, Units.MM)
    assert back[:2].tolist() == pytest.approx([tg.range_max_m(Units.MM)] * 2)
    assert np.all(back[2:] == 0.0)  # an invalid reading stays invalid on the way back


# ---------------------------------------------------------------------------- the stream parser
def _split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


def _feed(parser: StreamParser, chunks: list[bytes]) -> list[Telegram | Acknowledge]:
    out: list[Telegram | Acknowledge] = []
    for c in chunks:
        out += parser.feed(c)
    return out


@FAST
@given(st.binary(max_size=3000), st.lists(st.integers(0, 3000), max_size=20))
def test_arbitrary_bytes_never_crash_and_only_valid_telegrams_come_out(data: bytes, cuts: list[int]) -> None:
    parser = StreamParser("any", address=None)
    events = _feed(parser, _split(data, cuts))
    found = [ev for ev in events if isinstance(ev, Telegram)]
    for t in found:
        assert t.encode() in data  # it was on the line, CRC and all
    # every byte is accounted for exactly once: skipped, in a telegram, an ACK/NAK, or pending
    s = parser.stats
    assert s.bytes == len(data)
    assert s.resyncs + sum(len(t) for t in found) + s.acks + s.naks + parser.pending == len(data)


@FAST
@given(
    st.lists(st.tuples(st.binary(max_size=60), replies), min_size=1, max_size=6),
    st.binary(max_size=60),
    st.lists(st.integers(0, 5000), max_size=12),
)
def test_telegrams_between_garbage_all_come_out_in_order(
    parts: list[tuple[bytes, Telegram]], tail: bytes, cuts: list[int]
) -> None:
    stream = b"".join(g + t.encode() for g, t in parts) + tail
    # one more valid telegram at the end flushes anything a garbage STX made the parser wait for
    closing = tg.mode_reply(0)
    events = _feed(StreamParser("reply"), [*_split(stream, cuts), closing.encode()])
    got = [e for e in events if isinstance(e, Telegram)]
    assert got[: len(parts)] == [t for _, t in parts]
    assert got[-1] == closing


@FAST
@given(
    st.lists(replies, min_size=2, max_size=5),
    st.lists(st.binary(max_size=20), min_size=5, max_size=5),
    st.data(),
)
def test_a_flipped_bit_loses_at_most_the_telegram_it_hit(
    ts: list[Telegram], garbage: list[bytes], data: st.DataObject
) -> None:
    stream = bytearray(b"".join(g + t.encode() for g, t in zip(garbage, ts, strict=False)))
    i = data.draw(st.integers(0, len(stream) - 1))
    stream[i] ^= 1 << data.draw(st.integers(0, 7))
    closing = tg.mode_reply(0)
    events = StreamParser("reply").feed(bytes(stream) + closing.encode())
    got = [e for e in events if isinstance(e, Telegram)][:-1]
    assert len(got) >= len(ts) - 1
    it = iter(ts)
    assert all(any(g == t for t in it) for g in got)  # an ordered subsequence of what was sent


@FAST
@given(st.lists(replies, min_size=1, max_size=4), st.data())
def test_truncated_telegrams_are_dropped_and_the_rest_recovered(
    ts: list[Telegram], data: st.DataObject
) -> None:
    raws = [t.encode() for t in ts]
    k = data.draw(st.integers(0, len(raws) - 1))
    raws[k] = raws[k][: data.draw(st.integers(1, len(raws[k]) - 1))]
    closing = tg.mode_reply(0)
    events = StreamParser("reply").feed(b"".join(raws) + closing.encode())
    got = [e for e in events if isinstance(e, Telegram)]
    assert got == [t for j, t in enumerate(ts) if j != k] + [closing]


def test_counters() -> None:
    p = StreamParser("reply")
    good = tg.mode_reply(0).encode()
    bad = bytearray(good)
    bad[5] ^= 0x01
    events = p.feed(b"\x11\x22\x33" + bytes([ACK]) + good + bytes([NAK]) + bytes(bad) + good)
    assert [e for e in events if isinstance(e, Telegram)] == [tg.mode_reply(0)] * 2
    assert events[:3] == [Acknowledge.ACK, tg.mode_reply(0), Acknowledge.NAK]
    # hunting resumes after the rejected STX, so bytes of the bad telegram are scanned again
    rest = bad[1:]
    s = p.stats
    assert (s.telegrams, s.crc_errors) == (2, 1)
    assert s.acks == 1 + rest.count(ACK) and s.naks == 1 + rest.count(NAK)
    assert s.resyncs == 3 + 1 + sum(1 for b in rest if b not in (0x02, ACK, NAK)) + rest.count(0x02)


def test_an_implausible_length_is_rejected_without_waiting() -> None:
    p = StreamParser("reply")
    # an "0xA0 reply" claiming 500 payload bytes cannot be one: no waiting for 506 bytes
    assert p.feed(bytes([0x02, 0x80]) + struct.pack("<H", 500) + b"\xa0") == []
    assert p.pending == 0
    # a request seen by a reply parser is rejected too
    assert not any(isinstance(e, Telegram) for e in p.feed(tg.request_status().encode()))


def test_a_garbage_header_does_not_hold_back_a_complete_telegram() -> None:
    p = StreamParser("reply")
    fake = bytes([0x02, 0x80]) + struct.pack("<H", 700) + b"\xb0"  # plausible, would wait for 706 bytes
    assert p.feed(fake + tg.mode_reply(0).encode()) == [tg.mode_reply(0)]


def test_telegram_validation() -> None:
    with pytest.raises(ValueError, match="needs a status byte"):
        Telegram(0x80, 0xA0, b"\x00")
    with pytest.raises(ValueError, match="exceeds the LMS maximum"):
        Telegram(0x00, 0x30, bytes(900))
    with pytest.raises(ProtocolError, match="bad CRC"):
        decode_telegram(bytes.fromhex("02 00 02 00 20 24 34 09"))
