"""``loci import``: a CARMEN log or a ROS bag into the MCAP recording the robot would have made.

See :mod:`agent.recording.importer` for what is written and ``docs/real_logs.md`` for the
options, what each stream becomes and what is counted and skipped.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
from pathlib import Path
from typing import Any

from agent.commands.options import emit_json, positive_seconds

log = logging.getLogger(__name__)

_CARMEN_OPTIONS = ("laser", "beam_angles", "odometry", "truth", "clock", "period", "sick_codes")
_ROS_OPTIONS = ("scan_topic", "odom_topic", "laser_frame", "base_frame", "odom_frame")


def _mount(text: str) -> tuple[float, float, float]:
    parts = text.replace(",", " ").split()
    try:
        x, y, yaw = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected 'X Y YAW' (metres, metres, degrees), e.g. '0.2 0 0', got {text!r}"
        ) from None
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise argparse.ArgumentTypeError(f"the mount must be finite numbers, got {text!r}")
    return (x, y, math.radians(yaw))


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "import",
        help="turn a real robot log (CARMEN log, ROS 1/2 bag) into a recording loci replay reads",
        description=(
            "Import a CARMEN log (plain or .gz) or a ROS bag (ROS 1 .bag; ROS 2 directory, .db3 or "
            ".mcap) into the MCAP recording 'loci record' would have written on the robot: "
            "loci/ROBOT/scan, loci/ROBOT/odom and, where the log has them, reference poses on "
            "loci/ROBOT/pose/truth. The laser's mount goes into the recording, so 'loci replay "
            "OUT.mcap' places the laser where it was. Damaged input (a truncated file or line, an "
            "unknown line type, NaN ranges, time going backwards, a corrupt bag message) is warned "
            "about, counted and skipped; the summary adds up: read = imported + skipped by reason."
        ),
        epilog=(
            "Examples:\n"
            "  loci import freiburg-079-corrected.log.gz fr079.mcap && loci replay fr079.mcap\n"
            "  loci import robot.bag run.mcap --scan-topic /scan --odom-topic /odom\n"
            "  loci import rosbag2_dir run.mcap --odom-topic /tf --base-frame base_footprint\n"
            "See docs/real_logs.md."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", type=Path, metavar="INPUT", help="the CARMEN log or ROS bag")
    p.add_argument("output", type=Path, metavar="OUT.mcap", help="the recording to write")
    p.add_argument(
        "--format",
        choices=("auto", "carmen", "ros1", "ros2"),
        default="auto",
        help="the input's format (default: from its first bytes)",
    )
    p.add_argument("--robot", help="the robot name of the keys (default: from the input's file name)")
    p.add_argument("--force", action="store_true", help="overwrite OUT.mcap if it exists")
    p.add_argument(
        "--strict", action="store_true", help="stop at the first bad input (exit status 2, no output)"
    )
    p.add_argument("--json", action="store_true", help="print the counts as one JSON object")
    p.add_argument(
        "--mount",
        type=_mount,
        metavar="'X Y YAW'",
        help="the laser's pose on the robot (metres, metres, degrees) instead of the log's PARAM lines or /tf",
    )
    c = p.add_argument_group("CARMEN logs")
    c.add_argument(
        "--laser",
        type=int,
        choices=(1, 2, 3, 4),
        help="which laser: 1 front (FLASER, RAWLASER1, ROBOTLASER1), 2 rear, 3, 4 (default: the front one)",
    )
    c.add_argument(
        "--beam-angles",
        choices=("auto", "n", "n-1"),
        help="FLASER/RLASER beam i at -fov/2 + i*fov/n or + i*fov/(n-1) (default auto: n-1 for an odd "
        "beam count such as 181 or 361, n for an even one such as 180 or 360)",
    )
    c.add_argument(
        "--odometry",
        choices=("auto", "laser", "odom"),
        help="odometry from the robot pose in the laser lines (every scan gets the pose at its stamp) "
        "or from the ODOM lines (default auto: laser when the laser lines carry poses)",
    )
    c.add_argument(
        "--truth",
        choices=("auto", "laser", "none"),
        help="reference poses on pose/truth: TRUEPOS lines, plus the laser lines' (corrected) pose where "
        "it differs from their odometry (auto), on every laser line (laser: for SLAM-corrected logs), or "
        "nothing (none)",
    )
    c.add_argument(
        "--clock",
        choices=("auto", "ipc", "logger", "lines"),
        help="stamps from ipc_time with logger_time as the log time (ipc), both from logger_time "
        "(logger), or made up from the line order (lines; auto picks it when the times are printed "
        "with too few digits)",
    )
    c.add_argument(
        "--period",
        type=positive_seconds,
        metavar="S",
        help="seconds between two messages for --clock lines (default 0.1)",
    )
    c.add_argument(
        "--sick-codes",
        choices=("auto", "on", "off"),
        help="map 81.83-81.91 m as the SICK driver maps codes 8183-8191 (8183 and 8191 no return, the "
        "rest invalid) (default auto: for SICK LMS lasers)",
    )
    r = p.add_argument_group("ROS bags")
    r.add_argument(
        "--scan-topic", metavar="TOPIC", help="the sensor_msgs/LaserScan topic (default: the only one)"
    )
    r.add_argument(
        "--odom-topic",
        metavar="TOPIC",
        help="the nav_msgs/Odometry topic, or /tf for the odom -> base transform (default: the only "
        "Odometry topic, else /tf)",
    )
    r.add_argument("--laser-frame", metavar="FRAME", help="the laser's frame (default: the scans' frame_id)")
    r.add_argument(
        "--base-frame",
        metavar="FRAME",
        help="the robot's base (default: the odometry's child frame, else base_link)",
    )
    r.add_argument(
        "--odom-frame",
        metavar="FRAME",
        help="the odometry frame of /tf odometry (default: the odometry's, else odom)",
    )
    p.add_argument(
        "--reference",
        type=Path,
        metavar="LOG",
        help="a corrected copy of the log (a CARMEN log whose laser lines carry SLAM-corrected poses, "
        "or a recording with pose/truth): its scans are matched to the imported ones by their ranges "
        "and their poses written on pose/truth at the imported scans' stamps (the localization "
        "evaluation's truth; docs/localization.md)",
    )
    p.set_defaults(handler=_import)


def _import(args: argparse.Namespace) -> int:
    from agent.progress import Progress
    from agent.recording.carmen import CarmenOptions
    from agent.recording.importer import check_options_for, detect_format, import_log
    from agent.recording.rosbag import RosOptions

    kind = detect_format(args.input) if args.format == "auto" else args.format
    carmen_given = {k: getattr(args, k) for k in _CARMEN_OPTIONS if getattr(args, k) is not None}
    ros_given = {k: getattr(args, k) for k in _ROS_OPTIONS if getattr(args, k) is not None}
    check_options_for(kind, bool(carmen_given), bool(ros_given))
    carmen = CarmenOptions(mount=args.mount, **carmen_given)
    ros = RosOptions(mount=args.mount, **ros_given)

    def emit(text: str) -> None:
        print(f"loci import: warning: {text}", file=sys.stderr)

    on_terminal = sys.stderr.isatty() and not args.quiet
    with Progress(enabled=on_terminal) as progress:
        result = import_log(
            args.input,
            args.output,
            fmt=kind,
            robot=args.robot,
            overwrite=args.force,
            strict=args.strict,
            carmen=carmen,
            ros=ros,
            progress=progress,
            emit=emit,
        )
    reference = None
    if args.reference is not None:
        from agent.recording.reference import add_reference

        reference = add_reference(Path(args.output), args.reference, Path(args.output), overwrite=True)
    if args.json:
        emit_json(
            result.as_dict()
            | (
                {"reference": {"matched": reference.matched, "scans": reference.reference_scans}}
                if reference
                else {}
            )
        )
    else:
        print(result.summary())
        for k, v in result.choices.items():
            print(f"  {k}: {v}")
        m = result.mount
        print(f"  laser mount: x {m[0]:.3f} m, y {m[1]:.3f} m, yaw {math.degrees(m[2]):.1f}°")
        beams = result.stats.beams
        if beams:
            print("  beams: " + ", ".join(f"{n:,} {k}" for k, n in sorted(beams.items())))
        if reference is not None:
            print(f"  {reference.summary()}")
        print(f"replay it with: loci replay {args.output}")
    return 0
