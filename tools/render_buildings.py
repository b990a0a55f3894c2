"""Render the pictures of generated office buildings used in the docs (docs/img/buildings_*.png).

One picture per layout, one with an open hall, and the guided-tour office (living room,
charging station, bucket), annotated. Each picture is the grid in map colours (white free,
black occupied, grey unknown) with the place labels overlaid (room blue, corridor orange,
doorway red, hallway green), door bars and furniture outlines; pictures above ~200 KB are
scaled down.

    python -m tools.render_buildings [--out docs/img] [--seed-offset 0]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from knowledge.fileio import encode_image, write_image
from sim.buildings import generate_building, generate_tour_office, label_building_png

#: name → (seed, options); the seeds were picked for pictures that show each feature clearly.
PICTURES: dict[str, tuple[int, dict[str, Any]]] = {
    "straight": (4, {"layout": "straight", "hall": False}),
    "L": (3, {"layout": "L", "hall": False}),
    "T": (3, {"layout": "T", "hall": False}),
    "loop": (0, {"layout": "loop", "hall": False}),
    "hall": (1, {"layout": "T", "hall": True}),
    "tour": (5, {"tour": True}),
}
MAX_BYTES = 200_000


def render(name: str, seed: int, options: dict[str, Any]) -> tuple[np.ndarray, float]:
    """The picture of one building and the seconds its generation took."""
    opts = dict(options)
    t0 = time.perf_counter()
    b = (
        generate_tour_office(seed, **{k: v for k, v in opts.items() if k != "tour"})
        if opts.pop("tour", False)
        else generate_building(seed, **opts)
    )
    dt = time.perf_counter() - t0
    scale = 2 if max(b.grid.shape) < 900 else 1
    return label_building_png(b, annotate=name == "tour", scale=scale), dt


def fit(img: np.ndarray, path: Path) -> np.ndarray:
    """Shrink ``img`` until its PNG encoding is under :data:`MAX_BYTES`."""
    while len(encode_image(path, img)) > MAX_BYTES and min(img.shape[:2]) > 100:
        img = cv2.resize(img, None, fx=0.8, fy=0.8, interpolation=cv2.INTER_AREA)
    return img


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.render_buildings", description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("docs/img"), help="folder for buildings_<name>.png")
    ap.add_argument(
        "--seed-offset", type=int, default=0, help="add this to every picture's seed (to browse others)"
    )
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    for name, (seed, options) in PICTURES.items():
        path = args.out / f"buildings_{name}.png"
        img, dt = render(name, seed + args.seed_offset, options)
        img = fit(img, path)
        write_image(path, img)
        print(
            f"{path}: seed {seed + args.seed_offset}, {img.shape[1]}x{img.shape[0]} px, "
            f"{path.stat().st_size // 1024} KB, generated in {dt * 1000:.0f} ms"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
