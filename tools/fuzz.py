"""Reliability probes (issue 18): bad bytes at every input, and the serial line unplugged.

Three probes, each a function the tests run briefly and ``make fuzz`` runs long:

* :func:`fuzz_sick` — telegrams through the LMS stream parser and the driver's scan decoding:
  whole, with bytes flipped, cut short, between garbage, and random byte chunks. It counts
  exceptions other than :class:`~knowledge.errors.ProtocolError` (crashes) and telegrams that
  came out although their bytes with a valid CRC were not on the line (bad-CRC telegrams).
* :func:`fuzz_decoders` — every bus stream's decoder (:data:`~agent.bus.keys.STREAMS`, the
  codec the agent subscribes with): random bytes, valid messages cut short or with bytes
  flipped, JSON nested 100 to 100,000 deep, protobuf nested as deep, and payloads over the
  size limits. A decoder may return a message or raise :class:`ProtocolError`; anything
  else is a crash.
* :func:`replug_cycles` — the virtual LMS on a real pty, unplugged and plugged back ``n``
  times; the seconds from each return of the device to the first new scan.

    python -m tools.fuzz [--telegrams 1000000] [--chunks 1000000] [--messages 10000]
                               [--replugs 30] [--seed 0] [--json]

prints the figures docs/results/reliability.md quotes (``make fuzz``).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from agent.bus.codecs import (
    encode_camera_frame,
    encode_laser_scan,
    encode_pose,
    frame_transform,
)
from agent.bus.keys import STREAMS
from agent.bus.schemas import MAX_JSON_BYTES, SCHEMAS
from agent.commands.options import add_json_option, emit_json
from drivers.messages import CameraFrame, LaserScan, Pose2D
from drivers.sick import telegrams as tg
from drivers.sick.codec import StreamParser, Telegram
from drivers.sick.constants import Units
from knowledge.errors import ProtocolError

__all__ = ["SAMPLES", "fuzz_decoders", "fuzz_sick", "replug_cycles", "sample_payload"]

# ---------------------------------------------------------------------------- valid samples

_NOW = 1_700_000_000.0
_AREA = {"id": 1, "class": "room", "types": ["Room"], "names": ["the lab"], "objects": []}

#: A valid JSON message of each schema a stream carries (the seeds of the mutations).
SAMPLES: dict[str, dict[str, Any]] = {
    "loci.place/1": {
        "schema": "loci.place/1",
        "stamp": _NOW,
        "label": "corridor",
        "probabilities": {"room": 0.2, "corridor": 0.8},
        "node": 3,
    },
    "loci.graph/1": {
        "schema": "loci.graph/1",
        "stamp": _NOW,
        "nodes": [
            {"id": 0, "x": 0.0, "y": 0.0, "kind": "place", "label": "room"},
            {"id": 1, "x": 1.0, "y": 0.0, "kind": "doorway", "label": None, "width": 0.9, "orientation": 1.5},
        ],
        "edges": [[0, 1]],
    },
    "loci.areas/1": {
        "schema": "loci.areas/1",
        "stamp": _NOW,
        "areas": [{"id": 0, "label": "room", "nodes": [0]}],
    },
    "loci.diagnostics/1": {
        "schema": "loci.diagnostics/1",
        "stamp": _NOW,
        "robot": "rosie",
        "streams": {"scan": {"received": 10, "delivered": 9, "dropped": 1, "invalid": 0}},
        "extra": {"errors": 0},
    },
    "loci.utterance/1": {"schema": "loci.utterance/1", "text": "you are in the kitchen", "speaker": "tutor"},
    "loci.intent/1": {
        "schema": "loci.intent/1",
        "id": "i-1",
        "speaker": "tutor",
        "intent": "go_to",
        "args": {"target": {"head": "kitchen", "determiner": "the"}},
    },
    "loci.say/1": {
        "schema": "loci.say/1",
        "text": "I am in a room.",
        "status": "ok",
        "in_reply_to": "i-1",
        "content": {"area": _AREA},
    },
    "loci.ask/1": {
        "schema": "loci.ask/1",
        "id": "q-1",
        "text": "Was there a door here?",
        "choices": ["yes", "no"],
    },
    "loci.twist/1": {"schema": "loci.twist/1", "v": 0.2, "omega": -0.5, "stamp": _NOW},
    "loci.base_goal/1": {
        "schema": "loci.base_goal/1",
        "id": "g-1",
        "path": [{"x": 1.0, "y": 2.0}, {"x": 3.0, "y": 2.0, "theta": 0.5}],
    },
    "loci.base_status/1": {
        "schema": "loci.base_status/1",
        "stamp": _NOW,
        "status": "active",
        "goal": "g-1",
        "pose": {"x": 1.0, "y": 2.0, "theta": 0.1},
    },
    "loci.people/1": {
        "schema": "loci.people/1",
        "stamp": _NOW,
        "legs": [[1.0, 2.0], [1.2, 2.1]],
        "people": [{"x": 1.1, "y": 2.05, "legs": 2}],
        "tracks": [{"id": 4, "x": 1.1, "y": 2.0, "vx": 0.1, "vy": 0.0}],
    },
    "loci.objects/1": {
        "schema": "loci.objects/1",
        "stamp": _NOW,
        "recognitions": [{"name": "television", "kind": "Television", "score": 0.9, "node": 3, "area": 1}],
    },
    "loci.map_edit/1": {"schema": "loci.map_edit/1", "op": "remove_doorway", "node": 7, "after_scan": _NOW},
    "loci.truth/1": {"schema": "loci.truth/1", "stamp": _NOW, "x": 1.0, "y": 2.0, "theta": 0.0, "space": 3},
    "loci.pose/1": {
        "schema": "loci.pose/1",
        "stamp": _NOW,
        "frame_id": "map",
        "x": 1.0,
        "y": 2.0,
        "theta": 0.5,
        "covariance": [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.002],
        "mode": "tracking",
        "map_to_odom": {"x": 0.1, "y": -0.2, "theta": 0.01},
    },
    "loci.localization/1": {
        "schema": "loci.localization/1",
        "stamp": _NOW,
        "state": "uncertain",
        "sigma": 0.31,
        "sigma_theta": 0.05,
        "fit": 0.74,
        "event": "correction",
        "deviation": 0.3,
        "deviation_theta": 0.0,
        "pose": {"x": 1.0, "y": 2.0, "theta": 0.5},
    },
}


def sample_payload(schema: str, rng: np.random.Generator) -> bytes:
    """A valid payload of ``schema`` (a JSON id or a Foxglove type), randomised a little."""
    if schema in SAMPLES:
        return json.dumps(SAMPLES[schema]).encode()
    stamp = _NOW + float(rng.uniform(0, 100))
    if schema == "foxglove.LaserScan":
        n = int(rng.integers(2, 400))
        return encode_laser_scan(
            LaserScan(
                stamp=stamp,
                seq=int(rng.integers(0, 1 << 31)),
                frame_id="laser",
                angle_min=-math.pi / 2,
                angle_increment=math.pi / (n - 1),
                range_max=30.0,
                ranges=rng.uniform(0.1, 30.0, n),
            )
        )
    if schema == "foxglove.PoseInFrame":
        x, y, theta = (float(v) for v in rng.uniform(-3, 3, 3) * (50, 50, 1))
        return encode_pose(Pose2D(x, y, theta, stamp=stamp))
    if schema == "foxglove.CompressedImage":
        jpeg = b"\xff\xd8\xff\xc0\x00\x11\x08\x01\xe0\x02\x80" + rng.bytes(int(rng.integers(0, 200)))
        return encode_camera_frame(CameraFrame(stamp=stamp, seq=1, frame_id="camera", jpeg=jpeg))
    if schema in ("foxglove.SceneUpdate", "foxglove.FrameTransform"):
        return bytes(frame_transform(Pose2D(1.0, 2.0, 0.3, stamp=stamp), "laser").encode())
    raise ValueError(f"no sample of {schema!r}")


# ---------------------------------------------------------------------------- bus decoders


def _deep_json(depth: int, rng: np.random.Generator) -> bytes:
    opener, closer = (b"[", b"]") if rng.random() < 0.5 else (b'{"a":', b"}")
    inner = b"[" * depth + b"]" * depth if opener == b"[" else opener * depth + b"1" + closer * depth
    return b'{"schema":"loci.intent/1","id":"x","speaker":"s","intent":"stop","args":{"a":' + inner + b"}}"


def _deep_protobuf(depth: int) -> bytes:
    data = b""
    for _ in range(depth):
        data = b"\x1a" + _varint(len(data)) + data  # field 3 (length-delimited) holding the rest
    return data


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


def decoder_inputs(
    schema: str, n: int, rng: np.random.Generator, *, huge_every: int = 1
) -> Iterator[tuple[str, bytes]]:
    """``n`` inputs for a decoder of ``schema``: (kind, payload), kinds in turn. Payloads over
    the size limits take time to make (8-17 MB): only one "huge" turn in ``huge_every`` makes
    one, the others give random bytes."""
    kinds = ("random", "truncated", "mutated", "nested", "huge", "valid")
    huge = 0
    for i in range(n):
        kind = kinds[i % len(kinds)]
        if kind == "huge":
            huge += 1
            if huge % huge_every:
                kind = "random"
        valid = sample_payload(schema, rng)
        if kind == "random":
            data = rng.bytes(int(rng.integers(0, 2000)))
        elif kind == "truncated":
            data = valid[: int(rng.integers(0, max(1, len(valid))))]
        elif kind == "mutated":
            buf = bytearray(valid)
            for _ in range(int(rng.integers(1, 9))):
                buf[int(rng.integers(0, len(buf)))] = int(rng.integers(0, 256))
            data = bytes(buf)
        elif kind == "nested":
            depth = int(10 ** rng.uniform(2, 5))
            data = _deep_json(depth, rng) if schema.startswith("loci.") else _deep_protobuf(min(depth, 3000))
        elif kind == "huge":
            size = MAX_JSON_BYTES + 1 if schema.startswith("loci.") else (17 << 20)
            data = valid + b" " * (size - len(valid)) if rng.random() < 0.5 else rng.bytes(size)
        else:
            data = valid
        yield kind, data


def fuzz_decoders(n_per_key: int = 10_000, *, seed: int = 0, huge_every: int = 50) -> dict[str, Any]:
    """Every stream's decoder on ``n_per_key`` inputs; counts of results and crashes by stream.

    Payloads over the size limits are expensive to make (8-17 MB): one in ``huge_every``
    inputs of kind "huge" is kept, the rest are replaced by random bytes.
    """
    from agent.bus.codecs import codec_for

    rng = np.random.default_rng(seed)
    out: dict[str, Any] = {"per_stream": {}, "inputs": 0, "crashes": 0, "examples": []}
    for stream, spec in sorted(STREAMS.items()):
        codec = codec_for(spec.schema)
        counts: Counter[str] = Counter()
        for kind, data in decoder_inputs(spec.schema, n_per_key, rng, huge_every=huge_every):
            counts[f"in:{kind}"] += 1
            try:
                codec.decode(data)
                counts["decoded"] += 1
            except ProtocolError:
                counts["refused"] += 1
            except Exception as exc:  # the finding: not the project's error
                counts["crashes"] += 1
                if len(out["examples"]) < 10:
                    out["examples"].append({"stream": stream, "kind": kind, "error": repr(exc)[:200]})
        out["per_stream"][stream] = dict(counts)
        out["inputs"] += sum(v for k, v in counts.items() if k.startswith("in:"))
        out["crashes"] += counts["crashes"]
    out["json_schemas_checked"] = sorted(set(SAMPLES) & set(SCHEMAS.ids()))
    return out


# ---------------------------------------------------------------------------- SICK parser


def _telegram_pool(rng: np.random.Generator) -> list[bytes]:
    pool = [
        tg.mode_reply(0).encode(),
        tg.mode_reply(1, status=0x10).encode(),
        tg.type_reply("LMS200;30106").encode(),
        tg.request_values().encode(),
        tg.set_baud(500000).encode(),
    ]
    for n in (101, 181, 361):
        for _ in range(4):
            values = tg.ranges_to_values(rng.uniform(0.1, 30.0, n), Units.CM)
            pool.append(tg.MeasuredValues(values, units=Units.CM).telegram().encode())
    return pool


def fuzz_sick(n_telegrams: int = 1_000_000, n_chunks: int = 1_000_000, *, seed: int = 0) -> dict[str, Any]:
    """Mutated telegrams and random chunks through :class:`StreamParser` and 0xB0 decoding.

    A telegram that comes out must have been on the line with its CRC (its encoding is in
    the last bytes fed); one that was not is counted in ``bad_crc_out``.
    """
    rng = np.random.default_rng(seed)
    pool = _telegram_pool(rng)
    counts: Counter[str] = Counter()
    examples: list[str] = []

    def run(parser: StreamParser, window: bytearray, data: bytes) -> None:
        window += data
        del window[: max(0, len(window) - 4096)]
        try:
            events = parser.feed(data)
        except Exception as exc:
            counts["crashes"] += 1
            if len(examples) < 10:
                examples.append(f"parser: {exc!r}"[:200])
            parser.reset()
            return
        for ev in events:
            if not isinstance(ev, Telegram):
                continue
            counts["telegrams_out"] += 1
            if ev.encode() not in window:
                counts["bad_crc_out"] += 1
            if ev.command == tg.Reply.VALUES:
                try:
                    tg.MeasuredValues.decode(ev)
                    counts["scans_decoded"] += 1
                except ProtocolError:
                    counts["scans_refused"] += 1
                except Exception as exc:
                    counts["crashes"] += 1
                    if len(examples) < 10:
                        examples.append(f"0xB0 decode: {exc!r}"[:200])

    parser, window = StreamParser("any", address=None), bytearray()
    for _ in range(n_telegrams):
        raw = bytearray(pool[int(rng.integers(0, len(pool)))])
        r = rng.random()
        if r < 0.4:  # bytes flipped
            for _ in range(int(rng.integers(1, 5))):
                raw[int(rng.integers(0, len(raw)))] ^= 1 << int(rng.integers(0, 8))
            counts["flipped"] += 1
        elif r < 0.6:  # cut short
            raw = raw[: int(rng.integers(1, len(raw)))]
            counts["cut"] += 1
        elif r < 0.8:  # garbage before it
            raw = bytearray(rng.bytes(int(rng.integers(1, 40)))) + raw
            counts["garbage_before"] += 1
        else:
            counts["whole"] += 1
        run(parser, window, bytes(raw))
    parser, window = StreamParser("any", address=None), bytearray()
    for _ in range(n_chunks):
        run(parser, window, rng.bytes(int(rng.integers(0, 64))))
    return {
        "telegrams": n_telegrams,
        "chunks": n_chunks,
        **{
            k: counts[k]
            for k in ("crashes", "bad_crc_out", "telegrams_out", "scans_decoded", "scans_refused")
        },
        "mutations": {k: counts[k] for k in ("whole", "flipped", "cut", "garbage_before")},
        "examples": examples,
    }


# ---------------------------------------------------------------------------- serial replug


def replug_cycles(n: int = 30, *, away: float = 0.4, limit: float = 2.0, seed: int = 0) -> dict[str, Any]:
    """Unplug the virtual LMS ``n`` times; seconds from each replug to the first new scan."""
    from drivers.sick.driver import LMS2xx
    from drivers.sim.lms import VirtualLMS
    from knowledge.metric.grid import OccupancyGrid
    from sim.lms_world import LmsWorld

    occ = np.ones((42, 62), dtype=bool)
    occ[1:-1, 1:-1] = False
    world = LmsWorld(
        OccupancyGrid.from_masks(occ, 0.1, name="box"), (3.0, 2.0, 0.0), noise_std=0.0, seed=seed
    )
    fast: dict[str, Any] = {
        "settle": 0.02,
        "probe_timeout": 0.15,
        "probe_retries": 0,
        "timeout": 0.5,
        "stall_timeout": 2.0,
    }
    times: list[float] = []
    missed = 0

    async def go(link: Path) -> None:
        nonlocal missed
        with VirtualLMS(world, link=link, units="mm") as sim:
            async with LMS2xx(str(sim.link), **fast) as lms:
                await lms.recv(timeout=5.0)
                for i in range(n):
                    sim.unplug()
                    await asyncio.sleep(away)
                    sim.replug(power_cycle=bool(i % 2))
                    back = time.time()
                    while True:
                        try:
                            scan = await lms.recv(timeout=max(0.05, back + 10.0 - time.time()))
                        except Exception:
                            missed += 1
                            break
                        if scan.stamp > back:
                            times.append(time.time() - back)
                            break

    with tempfile.TemporaryDirectory() as tmp:
        asyncio.run(go(Path(tmp) / "lms"))
    s = sorted(times)
    return {
        "cycles": n,
        "resumed": len(times),
        "missed": missed,
        "within_limit": sum(t <= limit for t in times),
        "limit_s": limit,
        "median_s": round(s[len(s) // 2], 3) if s else None,
        "max_s": round(s[-1], 3) if s else None,
        "times_s": [round(t, 3) for t in times],
    }


# ---------------------------------------------------------------------------- command line


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m tools.fuzz",
        description="Reliability probes: the SICK parser, every bus decoder, serial replug (make fuzz).",
    )
    p.add_argument("--telegrams", type=int, default=1_000_000, help="mutated telegrams (default 1,000,000)")
    p.add_argument("--chunks", type=int, default=1_000_000, help="random byte chunks (default 1,000,000)")
    p.add_argument("--messages", type=int, default=10_000, help="inputs per bus key (default 10,000)")
    p.add_argument("--replugs", type=int, default=30, help="serial unplug/replug cycles (default 30)")
    p.add_argument("--seed", type=int, default=0)
    add_json_option(p)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    report: dict[str, Any] = {"seed": args.seed}
    steps: list[tuple[str, Callable[[], dict[str, Any]]]] = [
        ("sick", lambda: fuzz_sick(args.telegrams, args.chunks, seed=args.seed)),
        ("decoders", lambda: fuzz_decoders(args.messages, seed=args.seed)),
        ("replug", lambda: replug_cycles(args.replugs, seed=args.seed)),
    ]
    for name, step in steps:
        t0 = time.perf_counter()
        report[name] = step()
        report[name]["seconds"] = round(time.perf_counter() - t0, 1)
        if not args.json:
            print(
                f"{name}: {json.dumps({k: v for k, v in report[name].items() if k != 'per_stream'})}",
                flush=True,
            )
    if args.json:
        emit_json(report)
    else:
        for stream, counts in report["decoders"]["per_stream"].items():
            print(f"  {stream}: {counts}")
    ok = (
        report["sick"]["crashes"] == 0
        and report["sick"]["bad_crc_out"] == 0
        and report["decoders"]["crashes"] == 0
        and report["replug"]["within_limit"] == report["replug"]["cycles"]
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
