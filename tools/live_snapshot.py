"""What a real WebSocket client received from the live view, drawn (docs/foxglove.md's picture).

The Foxglove app cannot be run on a machine without internet access (it is a hosted web app
or a downloaded desktop app), so this tool stands in for its 3D panel: it connects to a
running live view with :mod:`agent.live.probe` (the Foxglove protocol, every message decoded
with the schema the server advertised), subscribes to every channel for ``--seconds``, and
draws the latest message of each layer in the map frame — the occupancy grid ``/map`` and
``/labels`` cell by cell from their RGBA fields, the scan ``/scan`` placed by the ``/tf``
chain map → odom → base_link → laser, the graph ``/graph``, the areas' texts ``/areas``,
the people ``/people`` — with the place histogram ``/place``, the conversation and a table
of the channels received beside it. A JSON file lists the same counts.

    python -m tools.live_snapshot ws://127.0.0.1:8765 --seconds 20 --out docs/img/foxglove_live.png
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from agent.live.probe import Received, connect
from knowledge.fileio import atomic_write_text, write_image


async def gather(url: str, seconds: float) -> tuple[dict[str, list[Received]], dict[str, dict[str, Any]]]:
    probe = await connect(url, timeout=30)
    try:
        await probe.subscribe()
        got = await probe.collect(set(), timeout=0)  # nothing yet
        end = asyncio.get_running_loop().time() + seconds
        while (left := end - asyncio.get_running_loop().time()) > 0:
            r = await probe.receive(left)
            if r is None:
                break
            got.setdefault(r.topic, []).append(r)
        return got, probe.topics
    finally:
        await probe.close()


def _rot(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _compose(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2])


class Canvas:
    """World metres → pixels (y up), around a box."""

    def __init__(self, box: tuple[float, float, float, float], px_per_m: float) -> None:
        self.x0, self.y0, x1, y1 = box
        self.k = px_per_m
        self.w, self.h = int((x1 - self.x0) * px_per_m) + 1, int((y1 - self.y0) * px_per_m) + 1
        self.img = np.full((self.h, self.w, 3), 255, np.uint8)

    def px(self, x: float, y: float) -> tuple[int, int]:
        return round((x - self.x0) * self.k), round(self.h - 1 - (y - self.y0) * self.k)

    def grid(self, g: Any) -> None:
        cells = np.frombuffer(g.data, np.uint8).reshape(-1, g.column_count, g.cell_stride)[..., :4]
        rows = cells.shape[0]
        res = g.cell_size.x
        ox, oy = g.pose.position.x, g.pose.position.y
        img = cells[::-1]  # grid rows run +y; image rows run down
        x0, y1 = self.px(ox, oy + rows * res)
        x1, y0 = self.px(ox + g.column_count * res, oy)
        w, h = max(1, x1 - x0), max(1, y0 - y1)
        tile = cv2.resize(img, (w, h), interpolation=cv2.INTER_NEAREST)
        xs, ys = max(0, x0), max(0, y1)
        xe, ye = min(self.w, x0 + w), min(self.h, y1 + h)
        if xe <= xs or ye <= ys:
            return
        part = tile[ys - y1 : ye - y1, xs - x0 : xe - x0].astype(np.float32)
        alpha = part[..., 3:4] / 255.0
        bgr = part[..., [2, 1, 0]]
        dst = self.img[ys:ye, xs:xe].astype(np.float32)
        self.img[ys:ye, xs:xe] = (alpha * bgr + (1 - alpha) * dst).astype(np.uint8)


def _bgr(c: Any) -> tuple[int, int, int]:
    return (int(255 * c.b), int(255 * c.g), int(255 * c.r))


def draw(got: dict[str, list[Received]], topics: dict[str, dict[str, Any]]) -> np.ndarray:
    latest = {t: v[-1].value for t, v in got.items() if v}
    box = [-5.0, -5.0, 5.0, 5.0]
    for t in ("/map", "/labels"):
        g = latest.get(t)
        if g is not None:
            rows = len(g.data) // max(1, g.row_stride)
            ox, oy = g.pose.position.x, g.pose.position.y
            box = [
                min(box[0], ox),
                min(box[1], oy),
                max(box[2], ox + g.column_count * g.cell_size.x),
                max(box[3], oy + rows * g.cell_size.y),
            ]
    scale = min(40.0, 900.0 / max(box[2] - box[0], box[3] - box[1]))
    cv = Canvas((box[0], box[1], box[2], box[3]), scale)
    for t in ("/map", "/labels"):
        if t in latest:
            cv.grid(latest[t])
    graph = latest.get("/graph")
    if graph is not None and graph.entities:
        e = graph.entities[0]
        for line in e.lines:
            pts = [cv.px(p.x, p.y) for p in line.points]
            for a, b in zip(pts[::2], pts[1::2], strict=False):
                cv2.line(cv.img, a, b, (60, 60, 60), 2, cv2.LINE_AA)
        for s in e.spheres:
            cv2.circle(
                cv.img,
                cv.px(s.pose.position.x, s.pose.position.y),
                max(3, int(s.size.x * scale / 2)),
                _bgr(s.color),
                -1,
                cv2.LINE_AA,
            )
    tf = latest.get("/tf")
    if tf is not None and "/scan" in latest:
        pose = (0.0, 0.0, 0.0)
        for f in tf.transforms:  # map → odom → base_link → laser, in order
            pose = _compose(pose, (f.translation.x, f.translation.y, _rot(f.rotation)))
        scan = latest["/scan"]
        r = np.asarray(scan.ranges)
        a = scan.start_angle + np.arange(r.shape[0]) * (scan.end_angle - scan.start_angle) / max(
            1, r.shape[0] - 1
        )
        ok = np.isfinite(r) & (r > 0.05) & (r < r.max())
        for rr, aa in zip(r[ok], a[ok], strict=True):
            x = pose[0] + rr * math.cos(pose[2] + aa)
            y = pose[1] + rr * math.sin(pose[2] + aa)
            cv2.circle(cv.img, cv.px(x, y), 2, (40, 40, 220), -1)
        px = cv.px(pose[0], pose[1])
        cv2.circle(cv.img, px, 6, (0, 140, 0), -1, cv2.LINE_AA)
        tip = cv.px(pose[0] + 0.6 * math.cos(pose[2]), pose[1] + 0.6 * math.sin(pose[2]))
        cv2.arrowedLine(cv.img, px, tip, (0, 140, 0), 2, cv2.LINE_AA)
    people = latest.get("/people")
    if people is not None and people.entities:
        for c in people.entities[0].cylinders:
            cv2.circle(
                cv.img,
                cv.px(c.pose.position.x, c.pose.position.y),
                max(4, int(c.size.x * scale / 2)),
                (0, 140, 240),
                2,
                cv2.LINE_AA,
            )
    areas = latest.get("/areas")
    if areas is not None and areas.entities:
        for t in areas.entities[0].texts:
            x, y = cv.px(t.pose.position.x, t.pose.position.y)
            for i, line in enumerate(t.text.split("\n")):
                cv2.putText(
                    cv.img,
                    line,
                    (x - 30, y + 18 * i),
                    cv2.FONT_HERSHEY_SIMPLEX,
                    0.55,
                    (0, 0, 0),
                    3,
                    cv2.LINE_AA,
                )
                cv2.putText(
                    cv.img,
                    line,
                    (x - 30, y + 18 * i),
                    cv2.FONT_HERSHEY_SIMPLEX,
                    0.55,
                    _bgr(t.color),
                    1,
                    cv2.LINE_AA,
                )
    side = _side_panel(got, topics, cv.h)
    h = max(cv.h, side.shape[0])
    left = np.full((h, cv.w, 3), 255, np.uint8)
    left[: cv.h] = cv.img
    right = np.full((h, side.shape[1], 3), 248, np.uint8)
    right[: side.shape[0]] = side
    return np.hstack([left, right])


def _side_panel(got: dict[str, list[Received]], topics: dict[str, dict[str, Any]], height: int) -> np.ndarray:
    panel = np.full((max(height, 560), 430, 3), 248, np.uint8)
    y = 28

    def text(s: str, size: float = 0.5, colour: tuple[int, int, int] = (30, 30, 30), bold: int = 1) -> None:
        nonlocal y
        cv2.putText(panel, s, (12, y), cv2.FONT_HERSHEY_SIMPLEX, size, colour, bold, cv2.LINE_AA)
        y += int(34 * size + 8)

    place = got.get("/place", [])
    if place:
        p = place[-1].value
        text(f"/place: {p['label']}  (node {p.get('node')})", 0.65, bold=2)
        for cls, prob in sorted(p["probabilities"].items()):
            cv2.rectangle(panel, (150, y - 13), (150 + int(240 * prob), y + 2), (200, 140, 60), -1)
            text(f"{cls:<9} {prob:5.2f}")
    conv = got.get("/conversation", [])
    if conv:
        y += 6
        text("/conversation", 0.55, bold=2)
        for r in conv[-4:]:
            text(r.value.message[:48], 0.45)
    y += 6
    text("channels received (decoded with the advertised schema)", 0.45, bold=2)
    for topic in sorted(topics):
        n = len(got.get(topic, ()))
        text(
            f"{topic:<14} {topics[topic]['schemaName']:<24} {n:>5}",
            0.42,
            (30, 30, 30) if n else (150, 150, 150),
        )
    return panel[: max(height, y + 10)]


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.live_snapshot", description=__doc__.split("\n\n")[0])
    ap.add_argument("url", help="the live view, e.g. ws://127.0.0.1:8765")
    ap.add_argument("--seconds", type=float, default=15.0, help="how long to listen (default 15)")
    ap.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="PNG",
        help="the picture to write (a file); PNG.json beside it",
    )
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    got, topics = asyncio.run(gather(args.url, args.seconds))
    picture = draw(got, topics)
    write_image(args.out, picture)
    summary = {
        "url": args.url,
        "seconds": args.seconds,
        "channels": {
            t: {
                "schema": topics[t]["schemaName"],
                "encoding": topics[t]["encoding"],
                "messages": len(got.get(t, ())),
            }
            for t in sorted(topics)
        },
    }
    atomic_write_text(args.out.with_suffix(".json"), json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
