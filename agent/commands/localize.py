"""``loci localize``: Monte Carlo localization of a recording in a known map (Sect. 6.3).

The recording is replayed through the agent's pipeline (as ``loci replay`` does: odometry
association and place classification), and every processed scan goes to a particle filter
in MAP (:class:`~knowledge.localization.mcl.ParticleFilter`): from a uniform prior (global
localization) or from ``--initial`` (pose tracking); with ``--labels`` the semantic term of
eq. 6.3 weighs each particle by how likely the scan's class is at its place. Per
measurement update it writes (``--out``) and publishes (``--publish``) ``localization/pose``
(``loci.pose/1``: the robot's pose in the map, its covariance), ``localization/scene``
(``foxglove.SceneUpdate``: the particles, the estimate, its 2σ ellipse) and ``tf/map``
(``foxglove.FrameTransform`` map → odom). When the recording has reference poses
(``pose/truth``) the summary gives the estimate's error against them.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from agent.commands.options import add_bus_options, emit_json

#: knowledge.localization.semantic.OBSERVATIONS (spelled out: the CLI imports numpy only when it runs)
OBSERVATIONS = ("argmax", "histogram")

#: The confusion matrix used without ``--confusion``: the classifier right 70 % of the time,
#: its errors spread evenly over the other classes.
DEFAULT_HIT = 0.7


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "localize",
        help="localize a recording in a known map (Monte Carlo localization with place labels)",
        description=(
            "Replay RUN.mcap through the agent's pipeline and localize each scan in MAP with a particle "
            "filter: a likelihood-field laser model, the map's free space, and (with --labels) the place "
            "classifier's label of the scan against the map's labels (book Sect. 6.3, eq. 6.3). Without "
            "--initial the particles start uniform over the map (global localization). Writes or "
            "publishes the pose with its covariance, the particles and the map -> odom transform."
        ),
        epilog=(
            "Examples:\n"
            "  loci localize out/csail/map.yaml --recording csail.mcap --json   # the map: loci replay --out-dir\n"
            "  loci localize map.yaml --recording run.mcap --labels map.labels.png --out localized.mcap\n"
            "  loci localize map.yaml --recording run.mcap --initial 1.5 2.0 90 --publish"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "map", type=Path, metavar="MAP", help="the map: a map_server .yaml, or an image with --resolution"
    )
    p.add_argument(
        "--recording", type=Path, required=True, metavar="RUN.mcap", help="the recording to localize"
    )
    p.add_argument("--resolution", type=float, metavar="M", help="metres per cell of an image map")
    p.add_argument(
        "--labels",
        type=Path,
        metavar="LABELS.png",
        help="a label image of the map (codes 1 room, 2 corridor, 3 doorway, 4 hallway, or a legend "
        "beside it): turns on the semantic term",
    )
    p.add_argument(
        "--confusion",
        type=Path,
        metavar="FILE.json",
        help='the classifier\'s statistics P(z | y): {"classes": [...], "matrix": [[...]]} (rows: true '
        f"class y; default: right {DEFAULT_HIT * 100:.0f} %% of the time, errors spread evenly)",
    )
    p.add_argument(
        "--initial",
        type=float,
        nargs=3,
        metavar=("X", "Y", "THETA"),
        help="start tracking here (metres, metres, degrees: the robot in the map) instead of global localization",
    )
    sem = p.add_argument_group("the semantic term (with --labels)")
    sem.add_argument(
        "--semantic-weight",
        type=float,
        default=1.0,
        metavar="W",
        help="the factor on the semantic term's log-likelihood (default 1: eq. 6.3 as printed; 0: off)",
    )
    sem.add_argument(
        "--semantic-observation",
        choices=OBSERVATIONS,
        default="argmax",
        help="Pr(z | y) from the scan's most probable class (argmax, the book's) or from its whole "
        "histogram (the mixture of the confusion matrix's columns)",
    )
    sem.add_argument(
        "--semantic-distance",
        type=float,
        default=0.0,
        metavar="M",
        help="metres driven between two semantic weightings, earlier when the class changes (default 0: "
        "every update)",
    )
    sem.add_argument(
        "--semantic-proposal",
        action="store_true",
        help="draw the initial particles and recovery's random particles in proportion to Pr(z | y) "
        "over the free cells instead of uniformly (a semantic sensor resetting)",
    )
    sem.add_argument(
        "--semantic-history",
        type=float,
        default=0.0,
        metavar="M",
        help="with --semantic-proposal: recovery's particles also fit the labels of the last M metres "
        "(default 0: the current label only; the evaluation's target row: 10)",
    )
    sem.add_argument(
        "--semantic-recovery",
        action="store_true",
        help="recovery (augmented MCL) watches how well the particles' places explain the labels as "
        "well as the scans",
    )
    sem.add_argument(
        "--semantic-reset",
        type=float,
        default=0.0,
        metavar="T",
        help="with --semantic-history: at each resampling draw a share 1 - (L_p/L_q)^T of the particles "
        "anew from the history proposal, L_p and L_q the per-label likelihood of the label history at the "
        "particles and at the proposal's places (default 0: off; the evaluation's target row: 1)",
    )
    p.add_argument("--particles", type=int, default=10_000, help="particles (default 10000)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--model", type=Path, metavar="MODEL.npz", help="the place model (default: the recording's)"
    )
    p.add_argument("--out", type=Path, metavar="OUT.mcap", help="write the localization's messages here")
    p.add_argument("--force", action="store_true", help="overwrite OUT.mcap")
    p.add_argument("--publish", action="store_true", help="publish the messages on the bus as they come")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    add_bus_options(p)
    p.set_defaults(handler=_localize)


def _confusion(path: Path | None, classes: tuple[str, ...]) -> Any:
    import numpy as np

    from knowledge.errors import DataError

    k = len(classes)
    if path is None:
        c = np.full((k, k), (1.0 - DEFAULT_HIT) / max(k - 1, 1))
        np.fill_diagonal(c, DEFAULT_HIT)
        return c
    try:
        doc = json.loads(path.read_text())
        names = [str(v) for v in doc["classes"]]
        m = np.asarray(doc["matrix"], dtype=np.float64)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DataError(
            f"{path}: not a confusion file ({{'classes': [...], 'matrix': [[...]]}}): {exc}"
        ) from exc
    if m.shape != (len(names), len(names)):
        raise DataError(f"{path}: the matrix is {m.shape}, not {len(names)} x {len(names)}")
    out = np.full((k, k), 1.0 / k)
    idx = {c: i for i, c in enumerate(names)}
    for a, ca in enumerate(classes):
        if ca in idx:
            row = np.array([m[idx[ca], idx[cb]] if cb in idx else 0.0 for cb in classes]) + 1e-3
            out[a] = row / row.sum()
    return out


def _localize(args: argparse.Namespace) -> int:
    import numpy as np

    from agent.bus.bridge import RawSample
    from agent.bus.codecs import codec_for, frame_transform
    from agent.bus.keys import STREAMS, robot_name, stream_key
    from agent.bus.scene import localization_scene
    from agent.progress import Progress
    from agent.recording.localize import collect_run
    from agent.recording.offline import read_recording_metadata
    from agent.recording.recorder import McapSink, recording_metadata
    from drivers.messages import Pose2D
    from knowledge import labels as lbl
    from knowledge.errors import DataError
    from knowledge.localization.likelihood import LikelihoodField
    from knowledge.localization.mcl import MclParams, ParticleFilter
    from knowledge.localization.se2 import compose, inverse
    from knowledge.localization.semantic import SemanticMap
    from knowledge.metric.grid import OccupancyGrid
    from knowledge.places.model import PlaceModel

    if args.particles < 1:
        raise ValueError(f"--particles must be >= 1, got {args.particles}")
    grid = OccupancyGrid.load(args.map, args.resolution)
    codes = None
    if args.labels is not None:  # checked before the replay, which takes a while
        codes = lbl.read_label_image(args.labels)
        if codes.shape != grid.shape:
            raise DataError(f"{args.labels}: {codes.shape} labels for a {grid.shape} map")
    model = PlaceModel.load(args.model) if args.model else None
    with Progress(enabled=sys.stderr.isatty() and not args.quiet) as progress:
        run = collect_run(args.recording, model=model, progress=progress)
    if not len(run):
        raise DataError(f"{args.recording}: no scan was processed")
    field = LikelihoodField.from_grid(grid)
    semantic = None
    if args.labels is not None and codes is not None:
        legend = {**lbl.CLASS_NAMES, **lbl.read_legend(args.labels)}
        semantic = SemanticMap.from_codes(codes, legend, run.classes, _confusion(args.confusion, run.classes))
    prm = MclParams(
        particles=args.particles,
        semantic_weight=args.semantic_weight,
        semantic_observation=args.semantic_observation,
        semantic_distance=args.semantic_distance,
        semantic_proposal=args.semantic_proposal,
        proposal_history=args.semantic_history,
        semantic_recovery=args.semantic_recovery,
        history_reset=args.semantic_reset,
    )
    pf = ParticleFilter(field, prm, semantic=semantic, rng=np.random.default_rng(args.seed))
    mount = np.asarray(run.mount)
    if args.initial is not None:
        x, y, deg = args.initial
        pf.init_pose(compose([x, y, math.radians(deg)], mount))
        mode = "tracking"
    else:
        pf.init_uniform()
        mode = "global"
    robot = robot_name(args.robot or read_recording_metadata(args.recording).get("robot") or "robot")
    sink = (
        McapSink(args.out, overwrite=args.force, metadata=recording_metadata(robot, writer="loci localize"))
        if args.out
        else None
    )
    session = None
    pubs: dict[str, Any] = {}
    if args.publish:
        from agent.bus.bridge import publish_stream
        from agent.bus.session import DEFAULT_AGENT_ENDPOINT, BusConfig, open_session

        session = open_session(
            BusConfig(
                listen=tuple(args.listen or ("tcp/127.0.0.1:0",)),
                connect=tuple(args.connect or (DEFAULT_AGENT_ENDPOINT,)),
            )
        )
        pubs = {
            s: publish_stream(session, robot, s)
            for s in ("localization/pose", "localization/scene", "tf/map")
        }
    truth_at = {int(i): int(j) for i, j in run.truth_index()}
    errors: list[tuple[int, float]] = []
    updates = 0
    est = None
    try:
        for i, scan in enumerate(run.scans):
            if not pf.update(
                run.odom[i],
                scan.ranges,
                scan.angles,
                range_max=scan.range_max,
                range_min=scan.range_min,
                proba=run.proba[i],
            ):
                continue
            updates += 1
            est = pf.estimate()
            robot_map = compose(est.pose, inverse(mount))
            robot_odom = compose(run.odom[i], inverse(mount))
            m2o = compose(robot_map, inverse(robot_odom))
            message = {
                "schema": "loci.pose/1",
                "stamp": scan.stamp,
                "frame_id": "map",
                "x": round(float(robot_map[0]), 4),
                "y": round(float(robot_map[1]), 4),
                "theta": round(float(robot_map[2]), 5),
                "covariance": [round(float(v), 6) for v in est.covariance.ravel()],
                "mode": mode,
                "share": round(est.share, 4),
                "particles": int(pf.particles.shape[0]),
                "map_to_odom": {"x": float(m2o[0]), "y": float(m2o[1]), "theta": float(m2o[2])},
            }
            out = {
                "localization/pose": message,
                "localization/scene": localization_scene(
                    pf.world_particles(), tuple(est.pose), est.covariance, stamp=scan.stamp
                ),
                "tf/map": frame_transform(
                    Pose2D(float(m2o[0]), float(m2o[1]), float(m2o[2]), stamp=scan.stamp, frame_id="map"),
                    "odom",
                ),
            }
            for stream, msg in out.items():
                codec = codec_for(STREAMS[stream].schema)
                if sink is not None:
                    sink.write(
                        RawSample(
                            stream_key(robot, stream),
                            codec.encode(msg),
                            codec.zenoh_encoding,
                            round(scan.stamp * 1e9),
                        )
                    )
                if stream in pubs:
                    pubs[stream].put(msg)
            if i in truth_at:
                t = run.truth[truth_at[i]]
                errors.append((i, math.hypot(est.pose[0] - t[0], est.pose[1] - t[1])))
    finally:
        if sink is not None:
            sink.close()
        for pub in pubs.values():
            pub.close()
        if session is not None:
            from agent.bus.session import close_session

            close_session(session)
    summary: dict[str, Any] = {
        "recording": str(args.recording),
        "map": str(args.map),
        "mode": mode,
        "semantic": semantic is not None,
        "scans": len(run),
        "updates": updates,
        "particles": int(pf.particles.shape[0]),
    }
    if est is not None:
        final = compose(est.pose, inverse(mount))
        summary["pose"] = {
            "x": round(float(final[0]), 3),
            "y": round(float(final[1]), 3),
            "theta": round(float(final[2]), 4),
        }
        summary["covariance"] = [round(float(v), 6) for v in est.covariance.ravel()]
        summary["share"] = round(est.share, 3)
    if errors:
        from knowledge.localization.evaluation import convergence

        e = np.array([v for _, v in errors])
        k = convergence(e)
        summary["truth"] = {
            "compared": len(errors),
            "final_error": round(float(e[-1]), 3),
            "converged_at_scan": None if k is None else errors[k][0],
            "mean_error_after": None if k is None else round(float(e[k:].mean()), 3),
        }
    if args.json:
        emit_json(summary)
    else:
        p = summary.get("pose", {})
        print(
            f"localized {args.recording.name} in {args.map.name} ({mode}{', semantic' if semantic else ''}): "
            f"{len(run)} scans, {updates} updates; last pose x {p.get('x')} m, y {p.get('y')} m, "
            f"theta {math.degrees(p.get('theta', 0.0)):.1f}° (share {summary.get('share')})"
        )
        if "truth" in summary:
            t = summary["truth"]
            print(
                f"  against pose/truth ({t['compared']} scans): final error {t['final_error']} m; "
                + (
                    f"converged at scan {t['converged_at_scan']}"
                    if t["converged_at_scan"] is not None
                    else "not converged"
                )
            )
        if args.out:
            print(f"wrote {args.out}")
    return 0
