"""Benchmark: LMS 2xx telegram codec throughput against the 500 kbaud line rate.

A buffer of ``n`` measured-value telegrams (0xB0, 361 values — a 180°/0.5° scan, 732 bytes
each) is fed to :class:`~drivers.sick.codec.StreamParser` in serial-read-sized chunks, and
each telegram is also decoded into ranges in metres as the driver does. The baseline is the
line itself: at 500 kbaud with 10 bits per byte (8N1) it carries at most
``500000 / 10 / 732 ≈ 68.3`` such telegrams per second. The ratio says how many such lines
one core could keep up with. Times are CPU seconds of this process (``time.process_time``),
which other jobs on a shared machine disturb less than wall-clock time; both are reported.

    python -m tools.bench_sick [--telegrams 2000] [--chunk 1024] [--json | --json-file FILE]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from drivers.sick import telegrams as tg
from drivers.sick.codec import StreamParser, Telegram, crc16, crc16_reference
from drivers.sick.constants import Units

#: Bits on the line per byte: start bit, 8 data bits, stop bit.
BITS_PER_BYTE = 10


def make_stream(n_telegrams: int, n_values: int = 361, *, seed: int = 0) -> tuple[bytes, int]:
    """``n_telegrams`` 0xB0 telegrams of random ranges back to back; returns (bytes, telegram length)."""
    rng = np.random.default_rng(seed)
    parts = []
    for _ in range(n_telegrams):
        ranges = rng.uniform(0.1, 30.0, n_values)
        parts.append(
            tg.MeasuredValues(tg.ranges_to_values(ranges, Units.CM), units=Units.CM).telegram().encode()
        )
    return b"".join(parts), len(parts[0])


def _timed(fn: Callable[[], int], repeat: int) -> tuple[float, float, int]:
    """Best CPU and wall seconds of ``repeat`` runs, and what the last run returned."""
    best_cpu = best_wall = float("inf")
    out = 0
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        out = fn()
        best_cpu = min(best_cpu, time.process_time() - c0)
        best_wall = min(best_wall, time.perf_counter() - w0)
    return best_cpu, best_wall, out


def run(
    n_telegrams: int = 2000, *, chunk: int = 1024, baud: int = 500_000, repeat: int = 3, seed: int = 0
) -> dict[str, Any]:
    """Measure parsing and decoding throughput; return numbers and ratios to the line rate."""
    if n_telegrams < 1 or chunk < 1 or repeat < 1:
        raise ValueError("need n_telegrams >= 1, chunk >= 1 byte and repeat >= 1")
    stream, tlen = make_stream(n_telegrams, seed=seed)
    chunks = [stream[i : i + chunk] for i in range(0, len(stream), chunk)]
    line_rate = baud / BITS_PER_BYTE / tlen

    def parse() -> int:
        p = StreamParser("reply")
        n = 0
        for c in chunks:
            n += len(p.feed(c))
        return n

    def parse_and_decode() -> int:
        p = StreamParser("reply")
        n = 0
        for c in chunks:
            for ev in p.feed(c):
                if isinstance(ev, Telegram):
                    mv = tg.MeasuredValues.decode(ev, realtime_index=False)
                    tg.values_to_ranges(mv.values, Units.CM)
                    n += 1
        return n

    cpu_p, wall_p, n_p = _timed(parse, repeat)
    cpu_d, wall_d, n_d = _timed(parse_and_decode, repeat)
    if n_p != n_telegrams or n_d != n_telegrams:
        raise RuntimeError(f"the parser found {n_p}/{n_d} of {n_telegrams} telegrams")

    one = stream[: tlen - 2]
    k = 200
    cpu_fast, _, _ = _timed(lambda: sum(crc16(one) for _ in range(k)), repeat)
    cpu_ref, _, _ = _timed(lambda: sum(crc16_reference(one) for _ in range(k)), 1)

    parse_rate = n_telegrams / cpu_p
    decode_rate = n_telegrams / cpu_d
    return {
        "benchmark": "sick_codec",
        "telegrams": n_telegrams,
        "telegram_bytes": tlen,
        "chunk_bytes": chunk,
        "baud": baud,
        "line_telegrams_per_s": round(line_rate, 2),
        "parse_telegrams_per_s": round(parse_rate, 1),
        "parse_wall_telegrams_per_s": round(n_telegrams / wall_p, 1),
        "decode_telegrams_per_s": round(decode_rate, 1),
        "decode_wall_telegrams_per_s": round(n_telegrams / wall_d, 1),
        "parse_ratio_to_line": round(parse_rate / line_rate, 1),
        "decode_ratio_to_line": round(decode_rate / line_rate, 1),
        "decode_us_per_telegram": round(1e6 / decode_rate, 1),
        "crc_table_us": round(cpu_fast / k * 1e6, 2),
        "crc_loop_us": round(cpu_ref / k * 1e6, 2),
    }


def report(r: dict[str, Any]) -> str:
    """The result as text."""
    return "\n".join(
        [
            f"LMS codec, {r['telegrams']} telegrams of {r['telegram_bytes']} bytes, fed {r['chunk_bytes']} bytes at a time",
            f"  line at {r['baud']} baud:   {r['line_telegrams_per_s']:10.1f} telegrams/s (baseline)",
            f"  parse (framing + CRC):  {r['parse_telegrams_per_s']:10.1f} telegrams/s  = {r['parse_ratio_to_line']}x the line",
            f"  parse + decode to m:    {r['decode_telegrams_per_s']:10.1f} telegrams/s  = {r['decode_ratio_to_line']}x the line",
            f"  CRC of one telegram:    {r['crc_table_us']} µs (table) vs {r['crc_loop_us']} µs (byte loop)",
        ]
    )


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_sick", description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--telegrams", type=int, default=2000, help="0xB0 telegrams in the buffer (default: 2000)"
    )
    ap.add_argument(
        "--chunk", type=int, default=1024, help="bytes per feed, like serial reads (default: 1024)"
    )
    ap.add_argument("--baud", type=int, default=500_000, help="line rate to compare with (default: 500000)")
    add_json_option(ap)
    add_json_file_option(ap)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    r = run(args.telegrams, chunk=args.chunk, baud=args.baud)
    emit_result(args, r, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
