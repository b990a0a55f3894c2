"""MCAP recording: a Zenoh stream into a file, read back, opened by mcap's standard reader, and
a crashed writer's file (cut mid-chunk, no index) read up to its last complete message."""

from __future__ import annotations

import asyncio
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader

from agent.bus.bridge import RawSample, publish_stream
from agent.bus.codecs import codec_for, decode_laser_scan
from agent.bus.keys import STREAMS
from agent.bus.scene import graph_scene
from agent.bus.testing import session_pair, settle
from agent.recording.recorder import McapSink, Recorder, recording_metadata
from agent.recording.replay import McapMessages
from drivers.messages import LaserScan, Pose2D
from knowledge.errors import DataError


def _scan(i: int) -> LaserScan:
    return LaserScan(
        stamp=100.0 + i,
        seq=i,
        frame_id="laser",
        angle_min=-math.pi,
        angle_increment=2 * math.pi / 360,
        range_max=10.0,
        ranges=np.full(360, 1.0 + i, np.float32),
    )


def _place(i: int) -> dict[str, Any]:
    return {
        "schema": "loci.place/1",
        "stamp": 100.0 + i,
        "label": "room",
        "probabilities": {"room": 1.0},
        "node": i,
    }


GRAPH = {
    "schema": "loci.graph/1",
    "stamp": 1.0,
    "nodes": [{"id": 0, "x": 0.0, "y": 0.0, "kind": "place", "label": "room"}],
    "edges": [],
}


def _traffic() -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for i in range(6):
        out.append(("scan", _scan(i)))
        out.append(("odom", Pose2D(0.1 * i, 0.0, 0.0, stamp=100.0 + i)))
        if i % 2 == 0:
            out.append(("place", _place(i)))
    out.append(("graph", GRAPH))
    out.append(("graph/scene", graph_scene(GRAPH)))
    return out


def test_record_a_zenoh_stream_and_read_it_back(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    traffic = _traffic()

    async def main() -> dict[str, int]:
        with session_pair() as (a, b):
            sink = McapSink(path, metadata=recording_metadata("rosie", note="test"))
            recorder = Recorder(b, sink, "loci/rosie/**", flush_interval=0.1)
            task = asyncio.create_task(recorder.run())
            settle(a, b)
            pubs = {name: publish_stream(a, "rosie", name) for name in {n for n, _ in traffic}}
            other = publish_stream(a, "someone-else", "scan")
            for k, (name, value) in enumerate(traffic, start=1):
                pubs[name].put(value)
                other.put(_scan(0))  # another robot: not recorded
                # sensor streams drop under congestion by design (Policy.DROP_OLDEST): one
                # message in flight at a time, so that a loaded machine's full send queue (5 ms
                # between messages lost one in a make test beside a busy core) does not count
                # as a lost recording; what is tested is the recorder, not the transport's rate
                deadline = time.monotonic() + 5
                while recorder.stats["received"] < k and time.monotonic() < deadline:
                    await asyncio.sleep(0.002)
            recorder.stop()
            await task
            sink.close()
            return recorder.stats

    stats = asyncio.run(asyncio.wait_for(main(), 20))
    assert stats["received"] == len(traffic) and stats["dropped"] == 0

    # our reader: same payloads, schemas and order as published
    got = list(McapMessages(path))
    assert [m.topic for m in got] == [f"loci/rosie/{name}" for name, _ in traffic]
    for m, (name, value) in zip(got, traffic, strict=True):
        codec = codec_for(STREAMS[name].schema)
        assert m.schema == codec.schema
        assert m.zenoh_encoding == codec.zenoh_encoding
        assert m.data == codec.encode(value)
    assert [m.log_time_ns for m in got] == sorted(m.log_time_ns for m in got)
    scans = [decode_laser_scan(m.data) for m in got if m.schema == "foxglove.LaserScan"]
    assert [s.seq for s in scans] == list(range(6)) and scans[3].ranges[0] == 4.0

    # mcap's standard (seeking) reader: the summary, the schemas Foxglove needs, the metadata
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == len(traffic)
        schemas = {s.name: s.encoding for s in summary.schemas.values()}
        assert schemas == {
            "foxglove.LaserScan": "protobuf",
            "foxglove.PoseInFrame": "protobuf",
            "foxglove.SceneUpdate": "protobuf",
            "loci.place/1": "jsonschema",
            "loci.graph/1": "jsonschema",
        }
        encodings = {c.topic: c.message_encoding for c in summary.channels.values()}
        assert encodings["loci/rosie/scan"] == "protobuf" and encodings["loci/rosie/place"] == "json"
        assert len(list(reader.iter_messages())) == len(traffic)
    with path.open("rb") as f:
        (meta,) = [m for m in make_reader(f).iter_metadata() if m.name == "loci"]
        assert meta.metadata["robot"] == "rosie" and meta.metadata["note"] == "test"


def _write_chunked(path: Path, n: int, per_chunk: int) -> list[RawSample]:
    samples = [
        RawSample(
            f"loci/r/{'scan' if i % 3 else 'place'}",
            bytes([i % 251]) * (50 + i),
            "application/octet-stream",
            1_000_000 * (i + 1),
        )
        for i in range(n)
    ]
    with McapSink(path) as sink:
        for i, s in enumerate(samples):
            sink.write(s)
            if (i + 1) % per_chunk == 0:
                sink.flush()
    return samples


def test_a_crashed_writers_file_replays_up_to_its_last_complete_message(tmp_path: Path) -> None:
    full = tmp_path / "full.mcap"
    samples = _write_chunked(full, n=40, per_chunk=8)
    data = full.read_bytes()
    with full.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(chunks) == 5
    # cut in the middle of the fourth chunk: the file has no summary, no footer, a torn chunk
    cut = chunks[3].chunk_start_offset + chunks[3].chunk_length // 2
    torn = tmp_path / "torn.mcap"
    torn.write_bytes(data[:cut])
    complete_until = chunks[2].message_end_time  # the last log time of the last complete chunk
    expected = [s for s in samples if s.recv_ns <= complete_until]
    assert 0 < len(expected) < len(samples)

    reader = McapMessages(torn)
    got = list(reader)
    assert reader.truncated and reader.count == len(expected)
    assert [(m.topic, m.data, m.log_time_ns) for m in got] == [
        (s.key, s.payload, s.recv_ns) for s in expected
    ]

    # cut inside a record's length field, inside the magic, or empty: what is complete, no exception
    first_chunk = sum(s.recv_ns <= chunks[0].message_end_time for s in samples)
    for size, count in ((chunks[1].chunk_start_offset + 3, first_chunk), (5, 0), (0, 0)):
        torn.write_bytes(data[:size])
        r = McapMessages(torn)
        assert len(list(r)) == count and r.truncated

    # the complete file reads to its end without being flagged
    whole = McapMessages(full)
    assert len(list(whole)) == len(samples) and not whole.truncated


def test_recorder_cancelled_mid_stream_leaves_a_valid_file(tmp_path: Path) -> None:
    path = tmp_path / "cancel.mcap"

    async def main() -> int:
        with session_pair() as (a, b), McapSink(path) as sink:
            recorder = Recorder(b, sink, "loci/r/**", flush_interval=0.05)
            task = asyncio.create_task(recorder.run())
            settle(a, b)
            pub = publish_stream(a, "r", "place")
            for i in range(20):
                pub.put(_place(i))
                await asyncio.sleep(0.005)
            await asyncio.sleep(0.1)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            return sink.messages

    written = asyncio.run(asyncio.wait_for(main(), 20))
    msgs = list(McapMessages(path))
    assert len(msgs) == written == 20
    with path.open("rb") as f:
        assert make_reader(f).get_summary() is not None


def test_files_that_are_not_recordings(tmp_path: Path) -> None:
    bad = tmp_path / "notes.mcap"
    bad.write_bytes(b"this is not an MCAP file at all")
    with pytest.raises(DataError, match="not an MCAP file"):
        list(McapMessages(bad))
    with pytest.raises(DataError, match="no such recording"):
        McapMessages(tmp_path / "missing.mcap")
    with pytest.raises(DataError, match="exists"):
        McapSink(bad)
    McapSink(bad, overwrite=True).close()
    assert list(McapMessages(bad)) == []
