"""Scan stamps from the scanner's own schedule (drivers.sick.stamps): a host that reads late
or reads a backlog at once must not stamp old scans as new ones (issue 24)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.sick.stamps import ScanClock

P = 1 / 37.5  # an LMS 2xx at 180°/0.5°: two mirror turns per scan
TURNS = 2


def _stream(n: int, rng: np.random.Generator, *, delay: float = 0.004) -> tuple[np.ndarray, np.ndarray]:
    """True measurement times and the arrival estimates of a host reading with random delays."""
    true = 1000.0 + P * np.arange(n)
    return true, true + 0.0005 + rng.exponential(delay, n)


def test_a_steady_stream_is_stamped_on_the_scanners_schedule(rng: np.random.Generator) -> None:
    true, arrived = _stream(400, rng)
    clock = ScanClock(P)
    stamps = np.array([clock.stamp(a, (k * TURNS) % 256) for k, a in enumerate(arrived)])
    assert clock.tick == pytest.approx(P / TURNS)
    err = stamps[10:] - true[10:]
    assert np.abs(err).max() < 0.003  # the least delay of the window, not each read's delay
    assert np.all(stamps <= arrived + 1e-12)  # never later than the scan's own arrival
    assert np.all(np.diff(stamps) > 0.9 * P)  # and spaced as the scanner measured them
    assert clock.stats.scans == 400 and clock.stats.stale == 0


def test_a_backlog_read_at_once_gets_the_times_it_was_measured(rng: np.random.Generator) -> None:
    """The agent's loop stood still 4 s: 30 scans waited in the buffer and were read together
    (then the buffer was full and the scanner's next scans were lost on the line)."""
    true, arrived = _stream(300, rng)
    arrived = arrived.copy()
    frozen = (true > 1002.0) & (true < 1002.0 + 30 * P)
    arrived[frozen] = 1006.0 + np.arange(frozen.sum()) * 1e-4  # all read at once, 4 s later
    lost = (true >= 1002.0 + 30 * P) & (true < 1006.0)
    last_frozen = int(np.flatnonzero(frozen)[-1])
    clock = ScanClock(P)
    stamps = {
        k: clock.stamp(arrived[k], (k * TURNS) % 256, buffered=bool(frozen[k]) and k != last_frozen)
        for k in range(300)
        if not lost[k]
    }
    ks = np.array(sorted(k for k in stamps if k > 10))
    err = np.array([stamps[k] for k in ks]) - true[ks]
    # never earlier than measured, never later than the arrival said
    assert np.all(err >= -1e-9) and np.all(err <= arrived[ks] - true[ks] + 1e-9)
    assert np.abs(err[frozen[ks]]).max() < 0.003  # the backlog: the times it was measured
    assert np.median(err) < 0.002
    assert clock.stats.restamped >= frozen.sum() - 1
    # the arrival alone would have stamped them up to 4 s late
    assert (arrived[frozen] - true[frozen]).max() > 3.9


def test_without_an_index_a_backlog_is_dropped_and_counted(rng: np.random.Generator) -> None:
    _, arrived = _stream(200, rng, delay=0.002)
    arrived = arrived.copy()
    arrived[100:120] = 1010.0 + np.arange(20) * 1e-4
    clock = ScanClock(P)
    stamps = [clock.stamp(a, buffered=100 <= k < 119) for k, a in enumerate(arrived[:120])]
    assert all(s is not None for s in stamps[:100])
    assert stamps[100:120] == [None] * 20  # the last of the backlog arrived at once after the others
    assert clock.stats.stale == 20 and clock.stats.scans == 100


def test_the_index_wraps_across_a_long_gap_by_the_arrival_times() -> None:
    clock = ScanClock(P)
    k = 0
    for i in range(10):
        clock.stamp(1000.0 + i * P, (i * TURNS) % 256)
        k = i
    # 5 s without a scan (a pulled cable): 375 counts, the index wrapped once
    later = k + round(5.0 / P)
    s = clock.stamp(1000.0 + later * P + 0.002, (later * TURNS) % 256)
    assert s == pytest.approx(1000.0 + later * P, abs=0.003)


def test_a_repeated_index_is_a_repeated_telegram() -> None:
    clock = ScanClock(P)
    assert clock.stamp(1000.0, 10) == 1000.0
    assert clock.stamp(1000.0 + P, 12) is not None
    assert clock.stamp(1000.0 + P + 0.001, 12) is None
    assert clock.stats.stale == 1


def test_an_index_that_restarts_resets_the_clock() -> None:
    clock = ScanClock(P)
    for i in range(20):
        clock.stamp(1000.0 + i * P, (100 + i * TURNS) % 256)
    assert clock.tick is not None
    clock.reset()
    assert clock.tick is None
    assert clock.stamp(2000.0, 3) == 2000.0


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="period"):
        ScanClock(0.0)
    with pytest.raises(ValueError, match="finite"):
        ScanClock(P).stamp(float("nan"), 1)


@settings(max_examples=60, deadline=None)
@given(
    delays=st.lists(st.floats(0.0, 0.5), min_size=20, max_size=120),
    step=st.sampled_from([1, 2, 4]),
)
def test_stamps_never_after_arrival_and_never_backwards(delays: list[float], step: int) -> None:
    """Whatever the delays (each arrival at least its measurement time, in order)."""
    true = 1000.0 + P * np.arange(len(delays))
    arrived = np.maximum.accumulate(true + np.array(delays))
    clock = ScanClock(P)
    out = [clock.stamp(a, (k * step) % 256) for k, a in enumerate(arrived)]
    got = [(s, a) for s, a in zip(out, arrived, strict=True) if s is not None]
    stamps = np.array([s for s, _ in got])
    assert all(s <= a + 1e-9 for s, a in got)
    assert np.all(np.diff(stamps) > 0)
