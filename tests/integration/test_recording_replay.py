"""Replay pacing: recorded speed takes about the recorded time, as fast as possible is much faster."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import pytest

from agent.bus.bridge import RawSample
from agent.recording.recorder import McapSink
from agent.recording.replay import RecordedMessage, Replay

MS = 1_000_000  # ns


def _recording(path: Path, log_times_ms: list[int]) -> Path:
    with McapSink(path) as sink:
        for i, t in enumerate(log_times_ms):
            payload = f'{{"schema": "loci.say/1", "text": "{i}"}}'.encode()
            sink.write(
                RawSample(
                    "loci/r/dialogue/say",
                    payload,
                    "application/json;loci.say/1",
                    1_700_000_000_000 * MS + t * MS,
                )
            )
    return path


def _timed(replay: Replay) -> tuple[float, list[RecordedMessage]]:
    t0 = time.monotonic()
    msgs = list(replay)
    return time.monotonic() - t0, msgs


def test_recorded_speed_takes_the_recorded_time(tmp_path: Path) -> None:
    path = _recording(tmp_path / "r.mcap", [50 * i for i in range(11)])  # 0.5 s of traffic
    paced, msgs = _timed(Replay(path, speed=1.0))
    fast, again = _timed(Replay(path))
    assert [m.data for m in msgs] == [m.data for m in again] and len(msgs) == 11
    assert msgs[0].schema == "loci.say/1" and msgs[0].zenoh_encoding == "application/json;loci.say/1"
    assert 0.45 <= paced < 3.0  # generous: a loaded machine can only make it slower
    assert fast < paced / 3
    double, _ = _timed(Replay(path, speed=2.0))
    assert 0.2 <= double < paced


def test_long_silences_can_be_cut(tmp_path: Path) -> None:
    path = _recording(tmp_path / "gap.mcap", [0, 10, 20, 10_020, 10_030])  # a 10 s silence
    elapsed, msgs = _timed(Replay(path, speed=1.0, max_gap=0.05))
    assert len(msgs) == 5 and elapsed < 2.0


def test_async_replay_paces_with_the_event_loop(tmp_path: Path) -> None:
    path = _recording(tmp_path / "a.mcap", [40 * i for i in range(6)])  # 0.2 s

    async def main() -> tuple[float, int, int]:
        ticks = 0

        async def ticker() -> None:
            nonlocal ticks
            while True:
                ticks += 1
                await asyncio.sleep(0.01)

        t = asyncio.create_task(ticker())
        t0 = time.monotonic()
        n = 0
        async for _ in Replay(path, speed=1.0):
            n += 1
        elapsed = time.monotonic() - t0
        t.cancel()
        return elapsed, n, ticks

    elapsed, n, ticks = asyncio.run(main())
    assert n == 6 and 0.18 <= elapsed < 2.0
    assert ticks >= 5  # other tasks ran while the replay waited


def test_topic_filter_and_bad_arguments(tmp_path: Path) -> None:
    path = _recording(tmp_path / "f.mcap", [0, 1, 2])
    assert list(Replay(path, topics={"loci/r/scan"})) == []
    assert len(list(Replay(path, topics={"loci/r/dialogue/say"}))) == 3
    with pytest.raises(ValueError, match="speed"):
        Replay(path, speed=0)
    with pytest.raises(ValueError, match="max_gap"):
        Replay(path, max_gap=-1)
