"""``loci sick``: talk to a SICK LMS 200/211/221/291 laser scanner on a serial line.

``loci sick probe PORT`` initialises the scanner and prints what it says about itself;
``loci sick scan PORT`` streams scans and prints the scan rate and a range summary
(``--json-lines``: each summary as a JSON line as it comes; ``--json``: the final counters as
one JSON object).
PORT is a device (``/dev/ttyUSB0``, a udev symlink, the path ``loci sim lms`` prints) or a
pyserial URL (``socket://host:4001``).
"""

from __future__ import annotations

import argparse
import asyncio
import math
import sys
import time
from typing import TYPE_CHECKING, Any

from agent.commands.options import add_json_option, emit_json, emit_json_line

if TYPE_CHECKING:
    from drivers.sick.driver import LMS2xx

_PORT_HELP = "the scanner's serial port: a device such as /dev/ttyUSB0 or /dev/pts/N, or a URL such as socket://host:4001"
_VARIANTS = ("180/1", "180/0.5", "100/1", "100/0.5", "100/0.25")


def parse_variant(text: str) -> tuple[int, float]:
    """``"180/0.5"`` → ``(180, 0.5)``: scan angle and angular resolution in degrees."""
    try:
        a, r = text.split("/")
        return int(a), float(r)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"a variant is ANGLE/RESOLUTION in degrees, one of {', '.join(_VARIANTS)}; got {text!r}"
        ) from None


def _add_link_options(p: argparse.ArgumentParser, *, default_variant: str | None) -> None:
    p.add_argument("port", metavar="PORT", help=_PORT_HELP)
    p.add_argument(
        "--baud",
        type=int,
        choices=(9600, 19200, 38400, 500000),
        help="session baud rate (default: 500000 if the port supports it, else 38400); "
        "the scanner is found at whatever rate it runs and switched to this one",
    )
    vhelp = f"scan angle and resolution in degrees, one of {', '.join(_VARIANTS)}"
    vhelp += f" (default: {default_variant})" if default_variant else " (default: keep the scanner's)"
    p.add_argument("--variant", type=parse_variant, default=default_variant, help=vhelp)
    p.add_argument("--timeout", type=float, default=1.0, help="seconds to wait for each answer (default: 1)")


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "sick",
        help="SICK LMS 2xx laser scanner: probe it, stream scans",
        description=(
            "Talk to a SICK LMS 200/211/221/291 over its serial line (RS-232/RS-422 adapter, "
            "a serial server, or the virtual LMS of 'loci sim lms'). The scanner's baud rate is "
            "found automatically; on exit it is stopped and put back to 9600 baud."
        ),
    )
    sub = p.add_subparsers(dest="sick_command", metavar="SUBCOMMAND", required=True)

    probe = sub.add_parser(
        "probe",
        help="print what the scanner says about itself",
        description="Initialise the scanner and print its type, software version, variant, units and baud rate.",
    )
    _add_link_options(probe, default_variant=None)
    add_json_option(probe)
    probe.set_defaults(handler=_probe)

    scan = sub.add_parser(
        "scan",
        help="stream scans; print scans per second and a range summary",
        description=(
            "Stream scans and print, every --interval seconds, the scan rate and the minimum, "
            "mean and maximum of the valid ranges (metres) with the number of invalid beams "
            "per scan; at the end the driver's counters (telegrams, CRC errors, resyncs, "
            "reconnects, ...). Runs until Ctrl-C or for --duration seconds; the time is counted "
            "from when the scanner streams (its start-up is reported separately)."
        ),
    )
    _add_link_options(scan, default_variant="180/0.5")
    scan.add_argument(
        "--duration",
        type=float,
        help="stop after this many seconds of scanning, not counting start-up (default: until Ctrl-C)",
    )
    scan.add_argument("--interval", type=float, default=1.0, help="seconds between summaries (default: 1)")
    out = scan.add_mutually_exclusive_group()
    add_json_option(out, help="print one JSON object at the end (the counters) instead of the text")
    out.add_argument(
        "--json-lines",
        action="store_true",
        help="print each summary as a JSON line as it comes, then the counters as the last line",
    )
    scan.set_defaults(handler=_scan)


def _driver(args: argparse.Namespace, *, stream: bool) -> LMS2xx:
    from drivers.sick.driver import LMS2xx

    angle, res = args.variant if args.variant else (None, None)
    return LMS2xx(args.port, baud=args.baud, angle=angle, resolution=res, stream=stream, timeout=args.timeout)


def _probe(args: argparse.Namespace) -> int:
    from drivers.sick.telegrams import range_max_m

    async def run() -> dict[str, Any]:
        lms = _driver(args, stream=False)
        async with lms:
            assert lms.info is not None
            return lms.info.as_dict()

    info = asyncio.run(run())
    if args.json:
        emit_json({"schema": "loci.sick.probe/1", **info})
        return 0
    units = 0 if info["units"] == "cm" else 1
    print(f"SICK LMS on {info['port']}")
    print(f"  type            {info['type_string']}")
    print(f"  software        {info['software_version']} (boot PROM {info['prom_version']})")
    print(
        f"  variant         {info['angle_deg']}° at {info['resolution_deg']:g}° "
        f"({info['n_beams']} beams, {info['scan_rate_hz']:g} scans/s)"
    )
    print(
        f"  units           {info['units']} (longest range {range_max_m(units, info['measuring_mode']):.2f} m)"
    )
    print(f"  measuring mode  0x{info['measuring_mode']:02x}")
    print(f"  baud rate       found at {info['baud_found']}, session at {info['baud']}")
    return 0


class _Window:
    """Scans of one summary interval."""

    def __init__(self) -> None:
        self.n = 0
        self.n_beams = 0
        self.invalid = 0
        self.lo = math.inf
        self.hi = -math.inf
        self.total = 0.0
        self.n_valid = 0

    def add(self, summary: dict[str, float | int]) -> None:
        self.n += 1
        self.n_beams = int(summary["n_beams"])
        self.invalid += int(summary["invalid"])
        valid = self.n_beams - int(summary["invalid"])
        if valid:
            self.lo = min(self.lo, float(summary["min"]))
            self.hi = max(self.hi, float(summary["max"]))
            self.total += float(summary["mean"]) * valid
            self.n_valid += valid

    def report(self, t: float, dt: float) -> dict[str, Any]:
        def num(x: float) -> float | None:
            return round(x, 4) if math.isfinite(x) else None

        return {
            "schema": "loci.sick.summary/1",
            "t": round(t, 3),
            "scans": self.n,
            "scans_per_s": round(self.n / dt, 2) if dt > 0 else None,
            "n_beams": self.n_beams,
            "min": num(self.lo),
            "mean": num(self.total / self.n_valid) if self.n_valid else None,
            "max": num(self.hi),
            "invalid_per_scan": round(self.invalid / self.n, 2) if self.n else None,
        }


def _print_summary(r: dict[str, Any], args: argparse.Namespace) -> None:
    if args.json_lines:
        emit_json_line(r)
        return
    if args.json:
        return  # one object at the end

    def m(x: float | None) -> str:
        return "   -  " if x is None else f"{x:6.2f}"

    print(
        f"{r['t']:7.1f} s  {r['scans_per_s'] or 0:5.1f} scans/s  ranges min {m(r['min'])} "
        f"mean {m(r['mean'])} max {m(r['max'])} m  invalid {r['invalid_per_scan'] or 0:.1f}/{r['n_beams']}",
        flush=True,
    )


def _scan(args: argparse.Namespace) -> int:
    from drivers.sick.driver import summarise
    from knowledge.errors import DeviceTimeout

    if args.interval <= 0:
        raise SystemExit("loci sick scan: --interval must be > 0 seconds")
    if args.duration is not None and args.duration <= 0:
        raise SystemExit("loci sick scan: --duration must be > 0 seconds")

    async def run() -> dict[str, Any]:
        lms = _driver(args, stream=True)
        t_start = time.monotonic()
        async with lms:
            # the clock starts once the scanner streams: finding its baud rate and setting it
            # up (0.3 s, over 2 s when it was left at another rate) is not scanning time
            t0 = time.monotonic()
            startup = t0 - t_start
            end = math.inf if args.duration is None else t0 + args.duration
            assert lms.info is not None
            info = lms.info.as_dict()
            if not (args.json or args.json_lines):
                print(
                    f"{info['type_string']} on {args.port}: {info['angle_deg']}°/{info['resolution_deg']:g}°, "
                    f"{info['units']}, {info['baud']} baud",
                    flush=True,
                )
            window, t_win = _Window(), t0
            n_total = 0
            try:
                while True:
                    now = time.monotonic()
                    if now >= end:
                        break
                    next_report = min(t_win + args.interval, end)
                    try:
                        scan = await lms.recv(timeout=max(0.01, next_report - now))
                        window.add(summarise(scan))
                        n_total += 1
                    except DeviceTimeout:
                        pass
                    now = time.monotonic()
                    if now >= next_report:
                        _print_summary(window.report(now - t0, now - t_win), args)
                        window, t_win = _Window(), now
            except asyncio.CancelledError:
                pass  # Ctrl-C: stop the scanner, then report the counters
            duration = time.monotonic() - t0
            return {
                "schema": "loci.sick.counters/1",
                "startup": round(startup, 3),
                "duration": round(duration, 3),
                "scans": n_total,
                "scans_per_s": round(n_total / duration, 2) if duration > 0 else None,
                "counters": lms.stats.as_dict(),
                "info": info,
            }

    final = asyncio.run(run())
    if args.json_lines:
        emit_json_line(final)
    elif args.json:
        emit_json(final)
    else:
        c = final["counters"]
        print(
            f"{final['scans']} scans in {final['duration']:.1f} s ({final['scans_per_s']} scans/s, "
            f"after {final['startup']:.1f} s of start-up); " + ", ".join(f"{k} {v}" for k, v in c.items()),
            flush=True,
        )
    sys.stdout.flush()
    return 0
