"""Object recognition on rendered camera frames: recognition rate, false detections, time per frame.

The database is taught the pictures of the nine objects of ``sim.world.demo_world``
(one picture each, as the demo does). Each object is then rendered alone in an empty
10 m × 10 m room by the virtual camera (640 × 480, 60° field of view, 1 m high, pixel noise
σ = 2, blur σ = 0.6) at distances 1–6 m and turned 0°, 30°, 45° and 60° away from facing the
camera. A view counts for the recognition rate when the picture's outline lies wholly in the
frame (views that cut the object off are counted apart). Negatives: frames of the empty room
and frames of five objects that were never taught (other kinds and another couch). A false
detection is any reported object that is not in the frame.

Time per frame is ``ObjectRecogniser.recognise`` (SIFT on the frame + matching + RANSAC),
compared with SIFT extraction alone on the same frames (the baseline, same process).

Run: ``python -m tools.bench_objects [--json | --json-file FILE]``.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from agent.commands.options import add_json_file_option, add_json_option, emit_result
from drivers.messages import Pose2D
from knowledge.metric.grid import OccupancyGrid
from knowledge.objects import ObjectDatabase, ObjectRecogniser, extract_features
from sim.camera_view import CameraMount, VirtualCamera
from sim.objects import WorldObject, object_texture
from sim.world import SimWorld, demo_world

DISTANCES = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
TURNS = (0.0, 30.0, 45.0, 60.0)
LATERALS = (0.0, 0.4)
CAM = Pose2D(-4.2, 0.0, 0.0)
STRANGERS = ("bed", "plant", "table", "bucket", "couch")


def _room() -> OccupancyGrid:
    occ = np.zeros((200, 200), bool)
    occ[:2], occ[-2:], occ[:, :2], occ[:, -2:] = True, True, True, True
    return OccupancyGrid.from_masks(occ, 0.05, origin=(-5.0, -5.0, 0.0))


def _camera(grid: OccupancyGrid, objs: tuple[WorldObject, ...], seed: int) -> VirtualCamera:
    return VirtualCamera(
        SimWorld(grid, objs), mount=CameraMount(z=1.0), noise_sigma=2.0, blur_sigma=0.6, seed=seed
    )


def _in_frame(cam: VirtualCamera, obj: WorldObject) -> bool:
    """Whether the picture's whole outline projects into the image (camera at CAM, looking along +x)."""
    c = obj.corners()
    depth = c[:, 0] - CAM.x
    if np.any(depth <= 0.1):
        return False
    u = cam.cx - cam.fx * (c[:, 1] - CAM.y) / depth
    v = cam.cy + cam.fy * (cam.mount.z - c[:, 2]) / depth
    return bool(np.all((u >= -0.5) & (u <= cam.width - 0.5) & (v >= -0.5) & (v <= cam.height - 0.5)))


def run() -> dict[str, Any]:
    grid = _room()
    taught = demo_world().objects
    with tempfile.TemporaryDirectory() as tmp:
        db = ObjectDatabase.open(Path(tmp) / "objects")
        t0 = time.perf_counter()
        for o in taught:
            db.add(o.name.replace("_", " "), [object_texture(o)])
        teach_s = time.perf_counter() - t0
        rec = ObjectRecogniser(ObjectDatabase.open(db.folder))
    cells: dict[tuple[float, float], list[int]] = defaultdict(
        lambda: [0, 0, 0, 0]
    )  # hit, in view, hit cut, cut
    false_pos: list[dict[str, Any]] = []
    misses: list[str] = []
    frames: list[np.ndarray] = []
    seed = 0
    n_pos = 0
    for o in taught:
        name = o.name.replace("_", " ")
        for d in DISTANCES:
            for turn in TURNS:
                for lat in LATERALS:
                    obj = WorldObject(
                        o.name,
                        o.kind,
                        CAM.x + d,
                        lat,
                        math.pi + math.radians(turn),
                        o.width_m,
                        o.height_m,
                        o.elevation_m,
                    )
                    seed += 1
                    cam = _camera(grid, (obj,), seed)
                    img = cam.render(CAM)
                    frames.append(img)
                    found = [x.name for x in rec.recognise(img)]
                    n_pos += 1
                    hit = name in found
                    cell = cells[(d, turn)]
                    if _in_frame(cam, obj):
                        cell[0] += hit
                        cell[1] += 1
                        if not hit:
                            misses.append(f"{name} {d:g} m {turn:g}°")
                    else:
                        cell[2] += hit
                        cell[3] += 1
                    false_pos += [
                        {"shown": name, "reported": f, "distance": d, "turn": turn}
                        for f in found
                        if f != name
                    ]
    n_neg = 0
    for i, yaw in enumerate(np.linspace(0, 2 * math.pi, 12, endpoint=False)):
        for x in (-3.0, 0.0, 3.0):
            img = _camera(grid, (), 1000 + i).render(Pose2D(x, 0.5 * i / 12, float(yaw)))
            frames.append(img)
            n_neg += 1
            false_pos += [{"shown": None, "reported": f.name} for f in rec.recognise(img)]
    for i, kind in enumerate(STRANGERS):
        for d in (1.5, 2.5, 3.5):
            for turn in (0.0, 30.0):
                obj = WorldObject.place(
                    kind, CAM.x + d, 0.2, math.pi + math.radians(turn), name=f"stranger_{kind}"
                )
                img = _camera(grid, (obj,), 2000 + i).render(CAM)
                frames.append(img)
                n_neg += 1
                false_pos += [{"shown": f"stranger {kind}", "reported": f.name} for f in rec.recognise(img)]
    # time per frame, recognition vs SIFT alone (the baseline), on a fixed sample of frames
    sample = frames[:: max(1, len(frames) // 60)]
    t_rec, t_sift = [], []
    for img in sample:
        t = time.perf_counter()
        extract_features(img)
        t_sift.append(time.perf_counter() - t)
        t = time.perf_counter()
        rec.recognise(img)
        t_rec.append(time.perf_counter() - t)
    in_view = sum(c[1] for c in cells.values())
    hits = sum(c[0] for c in cells.values())
    return {
        "objects": len(taught),
        "training_keypoints": int(sum(len(v.features) for v in rec.views)),
        "teach_seconds": teach_s,
        "frames_with_object": n_pos,
        "frames_without_taught_object": n_neg,
        "in_view": in_view,
        "recognised_in_view": hits,
        "recognition_rate": hits / max(in_view, 1),
        "false_detections": len(false_pos),
        "false_detection_list": false_pos,
        "misses": misses,
        "table": {f"{d:g} m/{t:g}°": c for (d, t), c in sorted(cells.items())},
        "ms_per_frame_median": 1000 * float(np.median(t_rec)),
        "ms_per_frame_p90": 1000 * float(np.percentile(t_rec, 90)),
        "ms_sift_only_median": 1000 * float(np.median(t_sift)),
        "ratio_to_sift": float(np.median(t_rec) / np.median(t_sift)),
        "timed_frames": len(sample),
    }


def report(r: dict[str, Any]) -> str:
    lines = [
        f"{r['objects']} objects taught ({r['training_keypoints']} keypoints, {r['teach_seconds']:.2f} s); "
        f"{r['frames_with_object']} frames with one object, {r['frames_without_taught_object']} without a taught one",
        "",
        "recognised / views with the whole picture in the frame (turn = picture turned away from the camera):",
        "",
        "| distance | " + " | ".join(f"{t:g}°" for t in TURNS) + " |",
        "|---|" + "---|" * len(TURNS),
    ]
    for d in DISTANCES:
        row = []
        for t in TURNS:
            hit, n, *_ = r["table"][f"{d:g} m/{t:g}°"]
            row.append(f"{hit}/{n}" if n else "–")
        lines.append(f"| {d:g} m | " + " | ".join(row) + " |")
    cut = sum(c[3] for c in r["table"].values())
    cut_hit = sum(c[2] for c in r["table"].values())
    lines += [
        "",
        f"recognition rate (whole picture in view): {r['recognised_in_view']}/{r['in_view']} = "
        f"{100 * r['recognition_rate']:.1f} %; partly cut off: {cut_hit}/{cut}",
        f"false detections: {r['false_detections']} in {r['frames_with_object'] + r['frames_without_taught_object']} frames",
        f"time per 640x480 frame: median {r['ms_per_frame_median']:.0f} ms, p90 {r['ms_per_frame_p90']:.0f} ms "
        f"(SIFT alone {r['ms_sift_only_median']:.0f} ms: {r['ratio_to_sift']:.2f}x), {r['timed_frames']} frames",
    ]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_objects", description=__doc__.split("\n\n")[0])
    add_json_option(ap)
    add_json_file_option(ap)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    r = run()
    emit_result(args, r, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
