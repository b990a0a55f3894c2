"""When a scan was measured, whatever the host's delays: the stamps of a fixed-rate scanner.

A scanner measures on its own schedule — an LMS 2xx one scan every period of its mirror —
and the host learns of a scan when it reads the telegram's last byte. From that arrival the
driver estimates the sweep's start (the arrival minus the telegram's line time and the
sweep: ``arrived`` below). That estimate is only as good as the reading: a host that reads
late (a busy machine, a reader that was not scheduled) stamps the scan late, and a backlog
read at once — the scans that waited in the port's buffer — gets one stamp for seconds of
scans. Paired with odometry at those stamps, an old scan looks like a new one taken
decimetres further on: the noisy tour's tracked pose locked in a 0.9 m error that way
(issue 24).

:class:`ScanClock` stamps each scan. A scan is ``buffered`` when the read that completed it
held more bytes after it: it waited in the port's buffer, so its arrival says nothing about
when it was measured.

* **With the scanner's scan index** (an LMS 2xx whose availability has real-time indices
  sends a byte counting mirror turns modulo 256), the index is unwrapped into a count ``k``
  and the stamp is ``b + k · tick``: ``tick`` (seconds per count) is learned from the first
  two scans that arrived one period apart, and ``b`` is the lower envelope of
  ``arrived − k · tick`` over the scans of the last ``window`` seconds of the scanner's time
  — the least-delayed arrival fixes the scanner's clock, and every scan, a backlog's
  included, gets the time it was measured. A stamp is never later than the scan's own
  arrival estimate. Unwrapping: a buffered scan follows the scan read before it by the
  index's difference alone (a buffer keeps the oldest bytes: what it holds is contiguous);
  a scan read as it came is put on the latest lap of the index that its arrival allows (it
  is on time: after a pulled cable or a long stall the index may have wrapped many times).
  A scan stamped more than half a period before its arrival is counted ``restamped``. Until
  ``tick`` is known, scans are stamped as without an index.
* **Without an index**, the arrival estimate is the stamp; a buffered scan, or one arriving
  less than half a period after the previous one, came out of a backlog and is dropped,
  counted ``stale``.

A repeated index (the same count again, at once) is a repeated telegram, and a scan whose
stamp would not come after the previous one cannot be placed: both are dropped and counted
``stale``. Times are seconds on any one clock (e.g. the epoch); nothing here reads a clock.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass

__all__ = ["ClockStats", "ScanClock"]

#: The scan index counts modulo this.
INDEX_MODULO = 256
#: Index laps beyond which a scan read as it came means the scanner restarted.
MAX_LAPS = 64


@dataclass
class ClockStats:
    """What :class:`ScanClock` did.

    Attributes:
        scans: scans given a stamp; restamped: of those, stamped from the index more than
            half a period before their arrival (a backlog or a late read); stale: scans
            dropped (a backlog without an index, a repeated index, a scan that cannot be
            placed after the previous one); resets: times the index restarted.
    """

    scans: int = 0
    restamped: int = 0
    stale: int = 0
    resets: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class ScanClock:
    """Stamps for a scanner measuring every ``period`` seconds (see the module docstring).

    Args:
        period: seconds between the scanner's scans.
        window: seconds (of the scanner's time) of scans whose least delay fixes its clock.
    """

    def __init__(self, period: float, *, window: float = 2.0) -> None:
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"period must be a positive number of seconds, got {period!r}")
        if not (math.isfinite(window) and window > 0):
            raise ValueError(f"window must be a positive number of seconds, got {window!r}")
        self.period = float(period)
        self.window = float(window)
        self.stats = ClockStats()
        self.reset()

    def reset(self, period: float | None = None) -> None:
        """Forget the scanner's clock (after a reconnect; ``period``: a new one)."""
        if period is not None:
            if not (math.isfinite(period) and period > 0):
                raise ValueError(f"period must be a positive number of seconds, got {period!r}")
            self.period = float(period)
        self._index: int | None = None  # the last raw index
        self._count = 0  # the unwrapped count of the last scan
        self._tick: float | None = None  # seconds per count, once learned
        self._arrived: float | None = None  # the last arrival estimate
        self._stamp: float | None = None  # the last stamp given
        self._given = False  # the last scan got a stamp
        # (count, arrival − count · tick): the lower envelope's candidates, increasing values
        self._envelope: deque[tuple[int, float]] = deque()

    @property
    def tick(self) -> float | None:
        """Seconds per index count (None until learned)."""
        return self._tick

    def stamp(self, arrived: float, index: int | None = None, *, buffered: bool = False) -> float | None:
        """The stamp of a scan whose arrival puts its sweep's start at ``arrived``, carrying
        ``index`` (None: the scanner sends none), ``buffered`` if more bytes followed it in
        the read that completed it; None: the scan is dropped (counted ``stale``)."""
        if not math.isfinite(arrived):
            raise ValueError(f"arrived must be a finite time, got {arrived!r}")
        if index is None or self._index is None or self._tick is None:
            prev = self._arrived if self._given else None
            stamp = self._by_arrival(arrived, buffered)
            if index is not None:
                self._learn(arrived, int(index) % INDEX_MODULO, stamp, prev)
            elif stamp is not None:
                self._give(stamp, arrived)
            self._given = stamp is not None
            return stamp
        return self._by_index(arrived, int(index) % INDEX_MODULO, buffered)

    # ------------------------------------------------------------------ without the index
    def _by_arrival(self, arrived: float, buffered: bool) -> float | None:
        prev = self._arrived
        self._arrived = arrived
        if buffered or (prev is not None and arrived - prev < 0.5 * self.period):
            self.stats.stale += 1
            return None
        if self._stamp is not None and arrived <= self._stamp:
            self.stats.stale += 1
            return None
        return arrived

    def _learn(self, arrived: float, index: int, stamp: float | None, prev: float | None) -> None:
        """Before ``tick`` is known: count the index, learn ``tick`` from two scans in a row
        that came one period apart (``prev``: the arrival of the one before, if it was
        stamped; scans are stamped by their arrival meanwhile)."""
        if self._index is not None:
            d = (index - self._index) % INDEX_MODULO or INDEX_MODULO
            self._count += d
            if stamp is not None and prev is not None and arrived - prev <= 1.5 * self.period:
                self._tick = self.period / d  # a count per scan, or per mirror turn of an interlaced one
        self._index = index
        if stamp is not None:
            self._give(stamp, arrived)
            if self._tick is not None:
                self._envelope.clear()
                self._envelope.append((self._count, arrived - self._count * self._tick))

    def _give(self, stamp: float, arrived: float) -> None:
        self._stamp = stamp
        self.stats.scans += 1
        if arrived - stamp > 0.5 * self.period:
            self.stats.restamped += 1

    # ------------------------------------------------------------------ with the index
    def _by_index(self, arrived: float, index: int, buffered: bool) -> float | None:
        assert self._tick is not None and self._index is not None and self._arrived is not None
        tick = self._tick
        d = (index - self._index) % INDEX_MODULO
        elapsed = arrived - self._arrived
        if d == 0 and (buffered or elapsed < 0.5 * INDEX_MODULO * tick):
            self._arrived = arrived
            self._given = False
            self.stats.stale += 1  # the same index again at once: a repeated telegram
            return None
        d = d or INDEX_MODULO
        laps = 0
        if not buffered:
            # read as it came: on time, so on the latest lap its arrival allows
            b = self._envelope[0][1] if self._envelope else self._arrived - self._count * tick
            room = arrived + 0.5 * self.period - b - (self._count + d) * tick
            laps = max(0, math.floor(room / (INDEX_MODULO * tick)))
            if laps > MAX_LAPS:  # the index restarted (the scanner was reset)
                self.stats.resets += 1
                period = self.period
                self.reset(period)
                stamp = self._by_arrival(arrived, buffered)
                self._learn(arrived, index, stamp, None)
                self._given = stamp is not None
                return stamp
        self._index, self._arrived = index, arrived
        self._count += d + INDEX_MODULO * laps
        stamp = self._envelope_stamp(arrived)
        if self._stamp is not None and stamp <= self._stamp:
            self.stats.stale += 1  # cannot be placed after the scans already stamped
            self._given = False
            return None
        self._give(stamp, arrived)
        self._given = True
        return stamp

    def _envelope_stamp(self, arrived: float) -> float:
        assert self._tick is not None
        value = arrived - self._count * self._tick
        env = self._envelope
        while env and env[-1][1] >= value:
            env.pop()
        env.append((self._count, value))
        # the window is the scanner's time, not the arrivals': a backlog read seconds late keeps
        # the punctual arrivals before it in the window
        oldest = self._count - self.window / self._tick
        while env[0][0] < oldest:
            env.popleft()
        return env[0][1] + self._count * self._tick
