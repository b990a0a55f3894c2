"""``loci objects``: teach the robot objects from pictures and recognise them (book Sect. 7.3).

``loci objects add NAME IMAGE...`` stores the SIFT features of one or more pictures of an
object; ``loci objects list`` shows what is known; ``loci objects recognise IMAGE...`` finds
the known objects in camera images (ratio test + RANSAC homography); ``loci objects remove
NAME`` forgets one. The database is a folder (``docs/objects.md``): ``--db DIR``, else
``$LOCI_OBJECTS_DB``, else ``objects/`` in the agent's state folder (``$LOCI_STATE_DIR``,
else ``$XDG_STATE_HOME/genius-loci/<robot>``, the rule of agent/config.py).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from agent.commands.options import fraction, integer

MIN_INLIERS = integer(minimum=4, why="a homography needs 4 points")

#: Environment variable naming the object database folder.
DB_ENV = "LOCI_OBJECTS_DB"


def default_db_dir(env: dict[str, str] | None = None) -> Path:
    """``$LOCI_OBJECTS_DB``, else ``<state dir>/objects`` (state dir: ``$LOCI_STATE_DIR``, else
    ``$XDG_STATE_HOME/genius-loci/<robot>`` with the robot from ``$LOCI_ROBOT`` or the host name)."""
    from agent.bus.keys import robot_name
    from agent.config import default_state_dir

    e = dict(os.environ) if env is None else env
    if e.get(DB_ENV):
        return Path(e[DB_ENV])
    state = e.get("LOCI_STATE_DIR")
    base = Path(state) if state else default_state_dir(robot_name(e.get("LOCI_ROBOT") or None), e)
    return base / "objects"


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "objects",
        help="objects seen by the camera: teach them from pictures, recognise them",
        description=(
            "Object recognition (book Sect. 7.3): SIFT features of pictures of each object, Lowe's ratio "
            "test and a RANSAC homography. The database is a folder: --db DIR, else $LOCI_OBJECTS_DB, "
            "else objects/ in the state folder ($LOCI_STATE_DIR, else $XDG_STATE_HOME/genius-loci/<robot>)."
        ),
    )
    sub = p.add_subparsers(dest="objects_command", metavar="ACTION", required=True)

    def db_option(q: argparse.ArgumentParser) -> None:
        q.add_argument(
            "--db",
            type=Path,
            metavar="DIR",
            help="the object database folder (default: $LOCI_OBJECTS_DB, else <state dir>/objects)",
        )
        q.add_argument("--json", action="store_true", help="print one JSON object instead of text")

    add = sub.add_parser(
        "add",
        help="teach an object from one or more pictures of it",
        description=(
            "Teach an object: store the SIFT features of pictures of it (cropped to the object, seen "
            "from the front; several pictures from different sides or distances help). NAME becomes "
            "the instance name; its kind is the ontology class --kind, else made from NAME "
            "('charging station' -> ChargingStation). Adding to a known NAME adds pictures."
        ),
        epilog="Example: loci objects add television tv_front.png tv_left.png --kind Television",
    )
    add.add_argument("name", metavar="NAME", help="the object's name, e.g. 'television' or 'the red couch'")
    add.add_argument(
        "images", metavar="IMAGE", nargs="+", type=Path, help="pictures of the object (PNG, JPEG, ...)"
    )
    add.add_argument(
        "--kind",
        metavar="KIND",
        help="ontology class, e.g. Television or 'coffee machine' (default: from NAME)",
    )
    add.add_argument("--replace", action="store_true", help="forget NAME's earlier pictures first")
    db_option(add)
    add.set_defaults(handler=_add)

    ls = sub.add_parser(
        "list", help="list the objects taught", description="List the objects of the database."
    )
    db_option(ls)
    ls.set_defaults(handler=_list)

    rec = sub.add_parser(
        "recognise",
        aliases=["recognize"],
        help="find the taught objects in images",
        description=(
            "Find the taught objects in camera images: one line per recognised object with its RANSAC "
            "inliers, score and centre in pixels, best score first."
        ),
        epilog="Example: loci objects recognise frame.png --json",
    )
    rec.add_argument("images", metavar="IMAGE", nargs="+", type=Path, help="images to look at")
    rec.add_argument(
        "--min-inliers",
        type=MIN_INLIERS,
        metavar="N",
        help="RANSAC inliers a detection needs (default: 12)",
    )
    rec.add_argument(
        "--ratio", type=fraction, metavar="R", help="Lowe's ratio test threshold (default: 0.75)"
    )
    db_option(rec)
    rec.set_defaults(handler=_recognise)

    rm = sub.add_parser("remove", help="forget an object", description="Forget an object and its pictures.")
    rm.add_argument("name", metavar="NAME", help="the object's name")
    db_option(rm)
    rm.set_defaults(handler=_remove)


def read_image(path: Path) -> np.ndarray:
    """A BGR uint8 image from a file; ValueError saying why it cannot be read."""
    import cv2

    if not path.is_file():
        raise ValueError(f"{path}: no such image file")
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"{path}: cannot read it as an image (is it a PNG, JPEG, BMP, ... file?)")
    return np.asarray(img)


def _db_dir(args: argparse.Namespace) -> Path:
    return Path(args.db) if args.db is not None else default_db_dir()


def _add(args: argparse.Namespace) -> int:
    from knowledge.objects.database import ObjectDatabase

    images = [read_image(p) for p in args.images]  # every file is checked before anything is written
    db = ObjectDatabase.open(_db_dir(args))
    entry = db.add(args.name, images, kind=args.kind, replace=args.replace)
    if args.json:
        print(json.dumps({"db": str(db.folder), "object": entry.to_json()}, ensure_ascii=False))
    else:
        n = len(entry.image_sizes)
        print(
            f"taught {entry.name!r} ({entry.kind}): {n} picture{'s' if n != 1 else ''}, "
            f"{sum(entry.keypoints)} keypoints, in {db.folder}"
        )
    return 0


def _list(args: argparse.Namespace) -> int:
    from knowledge.objects.database import ObjectDatabase

    db = ObjectDatabase.open(_db_dir(args))
    entries = db.entries()
    if args.json:
        print(
            json.dumps({"db": str(db.folder), "objects": [e.to_json() for e in entries]}, ensure_ascii=False)
        )
        return 0
    if not entries:
        print(f"no objects in {db.folder}; teach one with 'loci objects add NAME IMAGE...'")
        return 0
    width = max(len(e.name) for e in entries)
    for e in entries:
        print(
            f"{e.name:<{width}}  {e.kind:<16} {len(e.image_sizes)} picture(s), {sum(e.keypoints)} keypoints"
        )
    return 0


def _recognise(args: argparse.Namespace) -> int:
    from knowledge.objects.database import ObjectDatabase
    from knowledge.objects.recognition import ObjectRecogniser, RecognitionParams

    images = [(p, read_image(p)) for p in args.images]
    db = ObjectDatabase.open(_db_dir(args))
    if len(db) == 0:
        raise ValueError(f"no objects in {db.folder}: teach some with 'loci objects add NAME IMAGE...' first")
    over: dict[str, Any] = {}
    if args.min_inliers is not None:
        over["min_inliers"] = args.min_inliers
    if args.ratio is not None:
        over["ratio"] = args.ratio
    rec = ObjectRecogniser(db, RecognitionParams(**over))
    results = []
    for path, img in images:
        t0 = time.perf_counter()
        dets = rec.recognise(img)
        seconds = time.perf_counter() - t0
        results.append(
            {
                "image": str(path),
                "width": int(img.shape[1]),
                "height": int(img.shape[0]),
                "seconds": round(seconds, 4),
                "detections": [d.to_json() for d in dets],
            }
        )
        if not args.json:
            if not dets:
                print(f"{path}: nothing recognised")
            for d in dets:
                u, v = d.centre
                print(
                    f"{path}: {d.name} ({d.kind}) {d.inliers} inliers, score {d.score:.2f}, "
                    f"centre ({u:.0f}, {v:.0f}) px"
                )
    if args.json:
        print(json.dumps({"db": str(db.folder), "images": results}, ensure_ascii=False))
    return 0


def _remove(args: argparse.Namespace) -> int:
    from knowledge.objects.database import ObjectDatabase

    db = ObjectDatabase.open(_db_dir(args))
    entry = db.remove(args.name)
    if args.json:
        print(json.dumps({"db": str(db.folder), "removed": entry.to_json()}, ensure_ascii=False))
    else:
        print(f"forgot {entry.name!r} ({entry.kind}) in {db.folder}")
    return 0
