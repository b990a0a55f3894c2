"""Realistic random 360° scans of simple indoor scenes, for tests and benchmarks.

Scenes are sets of wall segments in metres: rectangular rooms with door openings and box
furniture, long corridors with side openings, and door frames between two rooms. Rays are
cast analytically against the segments; a ray that hits nothing within ``max_range``
returns ``max_range``, as a laser does. Nothing here is fitted to the feature code: the
scans only need to look like what a robot in an office sees.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: Scene kinds of :func:`random_scans`.
KINDS = ("room", "corridor", "doorway")


def cast_rays(
    origins: np.ndarray,
    segments: np.ndarray,
    *,
    num_beams: int,
    max_range: float,
    headings: np.ndarray | None = None,
) -> np.ndarray:
    """Beam lengths (S, num_beams) of full-turn scans against wall segments.

    Args:
        origins: (S, 2) robot positions, metres.
        segments: (S, K, 4) segments ``(x0, y0, x1, y1)`` per scan; NaN rows are padding.
        num_beams: beams per scan; beam i points at ``heading + i·2π/num_beams``.
        max_range: length returned by beams that hit nothing (and the cap of all beams).
        headings: (S,) robot headings in rad (default 0).
    """
    origins = np.asarray(origins, dtype=np.float64)
    segments = np.asarray(segments, dtype=np.float64)
    S = origins.shape[0]
    heads = np.zeros(S) if headings is None else np.asarray(headings, dtype=np.float64)
    angles = heads[:, None] + np.arange(num_beams) * (2.0 * math.pi / num_beams)
    ux, uy = np.cos(angles)[:, :, None], np.sin(angles)[:, :, None]  # (S, M, 1)
    ax, ay = segments[:, None, :, 0], segments[:, None, :, 1]  # (S, 1, K)
    ex, ey = segments[:, None, :, 2] - ax, segments[:, None, :, 3] - ay
    wx, wy = ax - origins[:, 0, None, None], ay - origins[:, 1, None, None]
    den = ux * ey - uy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (wx * ey - wy * ex) / den
        s = (wx * uy - wy * ux) / den
        valid = (np.abs(den) > 1e-12) & (t > 1e-9) & (s >= 0.0) & (s <= 1.0)
    t = np.where(valid, t, np.inf).min(axis=2)
    return np.minimum(t, max_range)


def _box(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float, float, float]]:
    return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]


def _wall_with_openings(
    a: tuple[float, float], b: tuple[float, float], openings: Sequence[tuple[float, float]]
) -> list[tuple[float, float, float, float]]:
    """Segment a→b with the parameter intervals ``openings`` (fractions of a→b) removed."""
    segs = []
    start = 0.0
    for lo, hi in sorted(openings):
        if lo > start:
            segs.append((start, lo))
        start = max(start, hi)
    if start < 1.0:
        segs.append((start, 1.0))
    return [
        (
            a[0] + (b[0] - a[0]) * s0,
            a[1] + (b[1] - a[1]) * s0,
            a[0] + (b[0] - a[0]) * s1,
            a[1] + (b[1] - a[1]) * s1,
        )
        for s0, s1 in segs
    ]


def _room(rng: np.random.Generator) -> tuple[list[tuple[float, float, float, float]], tuple[float, float]]:
    W, H = rng.uniform(2.5, 12.0), rng.uniform(2.5, 9.0)
    corners = [(0.0, 0.0), (W, 0.0), (W, H), (0.0, H)]
    doors: dict[int, list[tuple[float, float]]] = {}
    for _ in range(rng.integers(0, 3)):
        side = int(rng.integers(4))
        length = W if side % 2 == 0 else H
        width = rng.uniform(0.8, 1.0) / length
        lo = rng.uniform(0.05, max(0.06, 0.95 - width))
        doors.setdefault(side, []).append((lo, lo + width))
    segs = []
    for side in range(4):
        segs += _wall_with_openings(corners[side], corners[(side + 1) % 4], doors.get(side, []))
    boxes = []
    for _ in range(rng.integers(0, 4)):
        bw, bh = rng.uniform(0.3, 1.5), rng.uniform(0.3, 1.5)
        bx, by = rng.uniform(0.0, max(0.01, W - bw)), rng.uniform(0.0, max(0.01, H - bh))
        boxes.append((bx, by, bx + bw, by + bh))
        segs += _box(bx, by, bx + bw, by + bh)
    for _ in range(100):
        px, py = rng.uniform(0.3, W - 0.3), rng.uniform(0.3, H - 0.3)
        if all(not (x0 - 0.2 < px < x1 + 0.2 and y0 - 0.2 < py < y1 + 0.2) for x0, y0, x1, y1 in boxes):
            break
    return segs, (px, py)


def _corridor(
    rng: np.random.Generator,
) -> tuple[list[tuple[float, float, float, float]], tuple[float, float]]:
    L, w = rng.uniform(15.0, 60.0), rng.uniform(1.5, 3.0)
    openings: list[list[tuple[float, float]]] = [[], []]
    for _ in range(rng.integers(2, 7)):
        lo = rng.uniform(0.02, 0.95)
        openings[int(rng.integers(2))].append((lo, lo + 0.9 / L))
    segs = _wall_with_openings((0.0, 0.0), (L, 0.0), openings[0])
    segs += _wall_with_openings((0.0, w), (L, w), openings[1])
    segs += [(0.0, 0.0, 0.0, w), (L, 0.0, L, w)]
    return segs, (rng.uniform(0.5, L - 0.5), rng.uniform(0.3, w - 0.3))


def doorway_segments(
    room_a: tuple[float, float], room_b: tuple[float, float], door: tuple[float, float], thickness: float
) -> list[tuple[float, float, float, float]]:
    """Two rooms (width, height) left and right of a wall of ``thickness`` centred on x = 0,
    joined by a door opening ``door = (y_low, y_high)`` with its two jamb faces."""
    (wa, h), (wb, hb) = room_a, room_b
    t = 0.5 * thickness
    y0, y1 = door
    segs = [
        (-t, 0.0, -t, y0),
        (-t, y1, -t, h),
        (t, 0.0, t, y0),
        (t, y1, t, hb),
        (-t, y0, t, y0),  # jamb faces
        (-t, y1, t, y1),
    ]
    segs += [(-t - wa, 0.0, -t, 0.0), (-t - wa, h, -t, h), (-t - wa, 0.0, -t - wa, h)]
    segs += [(t, 0.0, t + wb, 0.0), (t, hb, t + wb, hb), (t + wb, 0.0, t + wb, hb)]
    return segs


def _doorway(rng: np.random.Generator) -> tuple[list[tuple[float, float, float, float]], tuple[float, float]]:
    h = rng.uniform(3.0, 8.0)
    width = rng.uniform(0.8, 1.0)
    y0 = rng.uniform(0.5, h - width - 0.5)
    thickness = rng.uniform(0.1, 0.3)
    segs = doorway_segments(
        (rng.uniform(2.5, 8.0), h), (rng.uniform(2.5, 8.0), h), (y0, y0 + width), thickness
    )
    return segs, (rng.uniform(-0.5, 0.5) * thickness, y0 + width * rng.uniform(0.25, 0.75))


def random_scans(
    n: int,
    *,
    rng: np.random.Generator,
    num_beams: int = 360,
    max_range: float = 30.0,
    noise: float = 0.01,
    kinds: Sequence[str] = KINDS,
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` scans (n, num_beams) from random scenes, and the index into ``kinds`` of each.

    Hits get Gaussian noise of ``noise`` metres (standard deviation); beams that hit nothing
    are exactly ``max_range``. The robot's heading is uniform.
    """
    builders = {"room": _room, "corridor": _corridor, "doorway": _doorway}
    unknown = [k for k in kinds if k not in builders]
    if unknown:
        raise ValueError(f"unknown scene kinds {unknown}; choose from {KINDS}")
    which = rng.integers(len(kinds), size=n)
    scenes = [builders[kinds[k]](rng) for k in which]
    K = max(len(segs) for segs, _ in scenes)
    segments = np.full((n, K, 4), np.nan)
    origins = np.empty((n, 2))
    for i, (segs, origin) in enumerate(scenes):
        segments[i, : len(segs)] = segs
        origins[i] = origin
    heads = rng.uniform(0.0, 2.0 * math.pi, size=n)
    out = np.empty((n, num_beams))
    chunk = max(1, 2_000_000 // (num_beams * K))
    for s in range(0, n, chunk):
        e = min(n, s + chunk)
        out[s:e] = cast_rays(
            origins[s:e], segments[s:e], num_beams=num_beams, max_range=max_range, headings=heads[s:e]
        )
    hit = out < max_range
    out[hit] += rng.normal(0.0, noise, size=int(hit.sum()))
    np.clip(out, 0.02, max_range, out=out)
    # noise must not turn a hit into a max-range reading
    out[hit] = np.minimum(out[hit], np.nextafter(max_range, 0.0))
    return out, which
