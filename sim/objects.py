"""Objects of the simulated world and their procedurally drawn pictures.

A :class:`WorldObject` is a flat, vertical, textured rectangle standing in the world — a
picture of a couch, a television, a bookcase — seen by the virtual camera
(:mod:`sim.camera_view`). Its texture is drawn here with OpenCV from a seed derived from
the object's name and kind: shapes, gradients, patterns, text and a little noise, so that
SIFT finds many distinctive keypoints and two objects are not confused. Nothing is
downloaded; the same name always gives the same picture.
"""

from __future__ import annotations

import functools
import math
import string
import zlib
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

Colour = tuple[int, int, int]


@dataclass(frozen=True)
class ObjectKind:
    """A catalogue entry: the default size of a kind of object and its picture's colours.

    Attributes:
        kind: the kind's name (``"couch"``).
        width_m, height_m: default size of the picture, metres.
        elevation_m: default height of its lower edge above the floor, metres.
        palette: BGR colours the drawing prefers.
    """

    kind: str
    width_m: float
    height_m: float
    elevation_m: float
    palette: tuple[Colour, ...]


CATALOGUE: dict[str, ObjectKind] = {
    k.kind: k
    for k in (
        ObjectKind("couch", 2.0, 0.9, 0.0, ((60, 60, 140), (40, 90, 160), (120, 100, 80), (70, 130, 70))),
        ObjectKind("television", 1.1, 0.65, 0.55, ((30, 30, 30), (200, 150, 60), (40, 180, 240))),
        ObjectKind("bookcase", 1.0, 1.9, 0.0, ((40, 80, 120), (30, 60, 100), (60, 110, 150))),
        ObjectKind("charging_station", 0.5, 0.45, 0.0, ((40, 40, 40), (0, 200, 255), (60, 200, 60))),
        ObjectKind("fridge", 0.7, 1.8, 0.0, ((230, 230, 225), (200, 200, 200), (180, 60, 60))),
        ObjectKind("coffee_machine", 0.4, 0.45, 0.9, ((30, 30, 30), (40, 60, 90), (180, 180, 190))),
        ObjectKind("desk", 1.4, 0.75, 0.0, ((60, 100, 150), (40, 70, 110), (200, 200, 200))),
        ObjectKind("monitor", 0.6, 0.4, 0.8, ((20, 20, 20), (150, 90, 40), (230, 230, 230))),
        ObjectKind("bucket", 0.35, 0.4, 0.0, ((200, 80, 30), (30, 150, 230), (60, 60, 200))),
        ObjectKind("table", 1.2, 0.75, 0.0, ((50, 90, 140), (30, 60, 100), (180, 200, 220))),
        ObjectKind("bed", 2.0, 0.8, 0.0, ((200, 180, 160), (140, 80, 60), (230, 230, 240))),
        ObjectKind("plant", 0.6, 1.2, 0.0, ((40, 140, 40), (30, 90, 30), (40, 80, 140))),
        ObjectKind("whiteboard", 1.5, 1.0, 0.8, ((240, 240, 240), (200, 60, 30), (30, 30, 200))),
        ObjectKind("thing", 0.8, 0.8, 0.0, ((120, 120, 120), (60, 160, 200), (160, 80, 160))),
    )
}


@dataclass(frozen=True)
class WorldObject:
    """A flat picture standing upright in the world.

    Attributes:
        name: unique instance name (``"tv1"``); it seeds the texture.
        kind: a :data:`CATALOGUE` kind (``"television"``) or any other word.
        x, y: world position of the centre of the picture's lower edge, metres.
        yaw: direction the picture faces (its outward normal), radians; it is seen from
            that side only.
        width_m, height_m: the picture's size, metres.
        elevation_m: height of its lower edge above the floor, metres.
    """

    name: str
    kind: str
    x: float
    y: float
    yaw: float
    width_m: float
    height_m: float
    elevation_m: float = 0.0

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("a WorldObject needs a non-empty name")
        vals = (self.x, self.y, self.yaw, self.width_m, self.height_m, self.elevation_m)
        if not all(math.isfinite(v) for v in vals):
            raise ValueError(f"WorldObject {self.name}: position, yaw and size must be finite, got {vals}")
        if self.width_m <= 0 or self.height_m <= 0 or self.elevation_m < 0:
            raise ValueError(
                f"WorldObject {self.name}: need width_m > 0, height_m > 0, elevation_m >= 0 (metres)"
            )

    @classmethod
    def place(
        cls,
        kind: str,
        x: float,
        y: float,
        yaw: float,
        *,
        name: str | None = None,
        width_m: float | None = None,
        height_m: float | None = None,
        elevation_m: float | None = None,
    ) -> WorldObject:
        """An object of a catalogue kind with its default size (any field may be overridden)."""
        k = CATALOGUE.get(kind, CATALOGUE["thing"])
        return cls(
            name or kind,
            kind,
            x,
            y,
            yaw,
            k.width_m if width_m is None else width_m,
            k.height_m if height_m is None else height_m,
            k.elevation_m if elevation_m is None else elevation_m,
        )

    @property
    def normal(self) -> np.ndarray:
        """``(2,)`` unit vector the picture faces."""
        return np.array([math.cos(self.yaw), math.sin(self.yaw)])

    @property
    def right(self) -> np.ndarray:
        """``(2,)`` unit vector along the picture from its left to its right edge (as seen from the front)."""
        return np.array([-math.sin(self.yaw), math.cos(self.yaw)])

    def corners(self) -> np.ndarray:
        """``(4, 3)`` world ``(x, y, z)`` of the corners: top-left, top-right, bottom-right, bottom-left."""
        c = np.array([self.x, self.y])
        half = self.right * (self.width_m / 2.0)
        left, right = c - half, c + half
        z0, z1 = self.elevation_m, self.elevation_m + self.height_m
        return np.array([[*left, z1], [*right, z1], [*right, z0], [*left, z0]])


# ------------------------------------------------------------------------------------- textures
#: Pixels along the longer side of a texture.
TEXTURE_LONG_SIDE = 480
#: The shorter side never goes below this many pixels.
TEXTURE_MIN_SIDE = 160


def texture(name_or_kind: str, *, kind: str | None = None, aspect: float | None = None) -> np.ndarray:
    """The picture of an object: ``(h, w, 3)`` uint8 BGR, read-only, deterministic.

    Args:
        name_or_kind: an instance name (``"tv1"``) or a catalogue kind (``"television"``).
        kind: the kind to draw when ``name_or_kind`` is an instance name (default: the
            name itself if it is a catalogue kind, else a generic ``"thing"``).
        aspect: width / height of the picture (default: the kind's catalogue size).
    """
    k = kind if kind is not None else (name_or_kind if name_or_kind in CATALOGUE else "thing")
    entry = CATALOGUE.get(k, CATALOGUE["thing"])
    a = entry.width_m / entry.height_m if aspect is None else float(aspect)
    if not (math.isfinite(a) and a > 0):
        raise ValueError(f"texture aspect must be a positive width/height ratio, got {aspect}")
    if a >= 1:
        w, h = TEXTURE_LONG_SIDE, max(TEXTURE_MIN_SIDE, round(TEXTURE_LONG_SIDE / a))
    else:
        w, h = max(TEXTURE_MIN_SIDE, round(TEXTURE_LONG_SIDE * a)), TEXTURE_LONG_SIDE
    return _texture(name_or_kind, k, h, w)


def object_texture(obj: WorldObject) -> np.ndarray:
    """:func:`texture` of a placed object, with the object's own aspect ratio."""
    return texture(obj.name, kind=obj.kind, aspect=obj.width_m / obj.height_m)


@functools.lru_cache(maxsize=128)
def _texture(name: str, kind: str, h: int, w: int) -> np.ndarray:
    seed = zlib.crc32(f"{kind}\0{name}".encode())
    rng = np.random.default_rng(seed)
    entry = CATALOGUE.get(kind, CATALOGUE["thing"])
    img = _gradient(rng, h, w, _jitter(rng, entry.palette[0], 40), _rand_colour(rng))
    _scatter_shapes(rng, img, 18, scale=0.12)
    _DRAWERS.get(kind, _draw_thing)(rng, img, entry.palette)
    _scatter_shapes(rng, img, 10, scale=0.06)
    _scatter_text(rng, img, 5)
    _bold_marks(rng, img, 4)
    # the name, for people looking at the pictures; font, size and place vary with the seed so
    # that two instances of a kind with similar names do not share a matchable label
    font = int(rng.choice(_FONTS))
    scale = float(rng.uniform(0.45, 0.7)) * w / 480 + 0.2
    org = (int(rng.uniform(0.03, 0.4) * w), int(rng.choice([0.1, 0.96]) * h))
    colour = _rand_colour(rng)
    text = name.upper()[:16]
    cv2.putText(img, text, org, font, scale, _contrast(colour), 4, cv2.LINE_AA)
    cv2.putText(img, text, org, font, scale, colour, 2, cv2.LINE_AA)
    noise = rng.normal(0.0, 5.0, img.shape)
    out = np.clip(img.astype(np.float64) + noise, 0, 255).astype(np.uint8)
    cv2.rectangle(out, (0, 0), (w - 1, h - 1), _rand_colour(rng), int(rng.integers(2, 3 + w // 100)))
    out.setflags(write=False)
    return out


# ---------------------------------------------------------------------------- drawing helpers
_FONTS = (
    cv2.FONT_HERSHEY_SIMPLEX,
    cv2.FONT_HERSHEY_DUPLEX,
    cv2.FONT_HERSHEY_COMPLEX,
    cv2.FONT_HERSHEY_TRIPLEX,
    cv2.FONT_ITALIC | cv2.FONT_HERSHEY_SIMPLEX,
)


def _rand_colour(rng: np.random.Generator) -> Colour:
    c = rng.integers(0, 256, 3)
    return (int(c[0]), int(c[1]), int(c[2]))


def _jitter(rng: np.random.Generator, c: Colour, amount: int) -> Colour:
    d = rng.integers(-amount, amount + 1, 3)
    return (
        int(np.clip(c[0] + d[0], 0, 255)),
        int(np.clip(c[1] + d[1], 0, 255)),
        int(np.clip(c[2] + d[2], 0, 255)),
    )


def _contrast(c: Colour) -> Colour:
    return (20, 20, 20) if sum(c) > 380 else (235, 235, 235)


def _gradient(rng: np.random.Generator, h: int, w: int, c0: Colour, c1: Colour) -> np.ndarray:
    ang = rng.uniform(0, 2 * math.pi)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    t = (xx / w) * math.cos(ang) + (yy / h) * math.sin(ang)
    t = (t - t.min()) / max(np.ptp(t), 1e-9)
    img = (1 - t)[..., None] * np.array(c0, float) + t[..., None] * np.array(c1, float)
    return np.ascontiguousarray(img.astype(np.uint8))


def _put_text(
    img: np.ndarray, text: str, org: tuple[int, int], scale: float, colour: Colour, thick: int
) -> None:
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, _contrast(colour), thick + 2, cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thick, cv2.LINE_AA)


def _random_word(rng: np.random.Generator, n: int) -> str:
    letters = string.ascii_uppercase + string.digits
    return "".join(letters[int(i)] for i in rng.integers(0, len(letters), n))


def _scatter_text(rng: np.random.Generator, img: np.ndarray, n: int) -> None:
    h, w = img.shape[:2]
    for _ in range(n):
        org = (int(rng.uniform(0, 0.8) * w), int(rng.uniform(0.1, 0.95) * h))
        font = int(rng.choice(_FONTS))
        scale = float(rng.uniform(0.4, 0.9)) * min(h, w) / 240
        colour = _rand_colour(rng)
        cv2.putText(img, _random_word(rng, int(rng.integers(2, 6))), org, font, scale, colour, 2, cv2.LINE_AA)


def _bold_marks(rng: np.random.Generator, img: np.ndarray, n: int) -> None:
    """Large, thick, high-contrast marks that survive being seen small (from far away)."""
    h, w = img.shape[:2]
    s = min(h, w)
    for _ in range(n):
        colour = _rand_colour(rng)
        cx, cy = int(rng.uniform(0.1, 0.9) * w), int(rng.uniform(0.1, 0.9) * h)
        if rng.random() < 0.5:
            word = _random_word(rng, int(rng.integers(1, 3)))
            scale = float(rng.uniform(1.2, 2.0)) * s / 240
            _put_text(img, word, (cx - int(0.1 * s), cy), scale, colour, max(3, s // 50))
        else:
            r = int(rng.uniform(0.06, 0.12) * s)
            pts = np.array(
                [[cx + r * math.cos(a), cy + r * math.sin(a)] for a in np.sort(rng.uniform(0, 6.28, 5))]
            )
            cv2.fillPoly(img, [pts.astype(np.int32)], colour, cv2.LINE_AA)
            cv2.polylines(img, [pts.astype(np.int32)], True, _contrast(colour), max(2, s // 80), cv2.LINE_AA)


def _scatter_shapes(rng: np.random.Generator, img: np.ndarray, n: int, *, scale: float) -> None:
    h, w = img.shape[:2]
    s = scale * min(h, w)
    for _ in range(n):
        cx, cy = int(rng.uniform(0, w)), int(rng.uniform(0, h))
        r = max(3, int(rng.uniform(0.3, 1.0) * s))
        colour = _rand_colour(rng)
        thick = -1 if rng.random() < 0.6 else int(rng.integers(2, 5))
        shape = int(rng.integers(0, 5))
        if shape == 0:
            cv2.circle(img, (cx, cy), r, colour, thick, cv2.LINE_AA)
        elif shape == 1:
            cv2.rectangle(img, (cx - r, cy - r // 2), (cx + r, cy + r // 2), colour, thick)
        elif shape == 2:
            pts = np.array([[cx + r * math.cos(a), cy + r * math.sin(a)] for a in rng.uniform(0, 6.28, 3)])
            cv2.fillConvexPoly(img, pts.astype(np.int32), colour, cv2.LINE_AA)
        elif shape == 3:
            axes = (r, max(2, r // 2))
            cv2.ellipse(img, (cx, cy), axes, float(rng.uniform(0, 180)), 0, 360, colour, thick, cv2.LINE_AA)
        else:
            p2 = (cx + int(rng.uniform(-2, 2) * r), cy + int(rng.uniform(-2, 2) * r))
            cv2.line(img, (cx, cy), p2, colour, int(rng.integers(2, 5)), cv2.LINE_AA)


def _pattern(
    rng: np.random.Generator, img: np.ndarray, x0: int, y0: int, x1: int, y1: int, base: Colour
) -> None:
    """Fill a rectangle with a seeded, deliberately irregular pattern: stripes, dots, checks or a
    zigzag. Irregular, because a periodic pattern lets a feature matcher map any lattice onto
    any other and confuse two objects that both have one."""
    h, w = img.shape[:2]
    x0, x1 = max(0, min(x0, x1)), min(w, max(x0, x1))
    y0, y1 = max(0, min(y0, y1)), min(h, max(y0, y1))
    pw, ph = x1 - x0, y1 - y0
    if pw < 4 or ph < 4:
        return
    patch = np.empty((ph, pw, 3), np.uint8)
    patch[:] = base
    other = _jitter(rng, _contrast(base), 60)
    kind = int(rng.integers(0, 4))
    step = max(6, int(rng.uniform(0.08, 0.2) * min(pw, ph)))
    if kind == 0:
        x = -ph // 2
        while x < pw:
            cv2.line(
                patch, (x, 0), (x + ph // 2, ph), other, int(rng.integers(2, max(3, step // 2))), cv2.LINE_AA
            )
            x += int(rng.uniform(0.8, 2.5) * step)
    elif kind == 1:
        n = int(pw * ph / step**2)
        for _ in range(n):
            c = (int(rng.uniform(0, pw)), int(rng.uniform(0, ph)))
            cv2.circle(patch, c, int(rng.integers(2, max(3, step // 2))), other, -1, cv2.LINE_AA)
    elif kind == 2:
        for y in range(0, ph, step):
            for x in range(0, pw, step):
                if rng.random() < 0.5:
                    cv2.rectangle(patch, (x, y), (x + step - 1, y + step - 1), other, -1)
    else:
        xs = np.cumsum(rng.uniform(0.6, 1.6, 2 + 2 * pw // step) * step) - step
        ys = ph / 2 + rng.uniform(0.3, 1.0, xs.size) * step * np.where(np.arange(xs.size) % 2, 1, -1)
        pts = np.stack([xs, ys], axis=1).astype(np.int32)
        cv2.polylines(patch, [pts], False, other, max(2, step // 4), cv2.LINE_AA)
    img[y0:y1, x0:x1] = patch
    cv2.rectangle(img, (x0, y0), (x1 - 1, y1 - 1), _jitter(rng, base, 60), 2)


# ------------------------------------------------------------------------------- kind drawers
Drawer = Callable[[np.random.Generator, np.ndarray, tuple[Colour, ...]], None]


def _draw_couch(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    body = _jitter(rng, pal[int(rng.integers(0, len(pal)))], 30)
    top, split = rng.uniform(0.1, 0.25), rng.uniform(0.45, 0.62)
    cv2.rectangle(img, (int(0.04 * w), int(top * h)), (int(0.96 * w), int(0.9 * h)), body, -1)
    n = int(rng.integers(2, 5))
    cw = 0.8 * w / n
    for i in range(n):
        x0 = int(0.1 * w + i * cw)
        _pattern(
            rng, img, x0 + 3, int((top + 0.05) * h), int(x0 + cw - 3), int(split * h), _jitter(rng, body, 40)
        )
    m = int(rng.integers(1, 4))
    for i in range(m):
        x0 = int(0.1 * w + i * 0.8 * w / m)
        _pattern(
            rng,
            img,
            x0 + 3,
            int((split + 0.03) * h),
            int(x0 + 0.8 * w / m - 3),
            int(0.82 * h),
            _jitter(rng, body, 40),
        )
    for x0 in (int(0.02 * w), int(0.9 * w)):
        cv2.rectangle(
            img, (x0, int(0.35 * h)), (x0 + int(0.08 * w), int(0.9 * h)), _jitter(rng, body, 20), -1
        )
    for _ in range(int(rng.integers(1, 4))):
        px = int(rng.uniform(0.15, 0.75) * w)
        _pattern(rng, img, px, int(0.25 * h), px + int(0.12 * w), int(0.5 * h), _rand_colour(rng))


def _draw_television(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    cv2.rectangle(img, (int(0.03 * w), int(0.03 * h)), (int(0.97 * w), int(0.85 * h)), (25, 25, 25), -1)
    x0, y0, x1, y1 = int(0.07 * w), int(0.08 * h), int(0.93 * w), int(0.78 * h)
    img[y0:y1, x0:x1] = _gradient(rng, y1 - y0, x1 - x0, _rand_colour(rng), _rand_colour(rng))
    ridge = [(x0, y1)] + [
        (int(x), int(rng.uniform(y0 + 0.3 * (y1 - y0), y1 - 5))) for x in np.linspace(x0, x1, 9)
    ]
    cv2.fillPoly(img, [np.array([*ridge, (x1, y1)], np.int32)], _jitter(rng, pal[1], 60))
    cv2.circle(img, (int(rng.uniform(x0 + 30, x1 - 30)), y0 + 30), 18, (80, 220, 255), -1, cv2.LINE_AA)
    _put_text(img, _random_word(rng, 3), (x0 + 10, y0 + 32), 0.9 * w / 480, (255, 255, 255), 2)
    cv2.rectangle(img, (int(0.42 * w), int(0.85 * h)), (int(0.58 * w), int(0.97 * h)), (40, 40, 40), -1)
    cv2.circle(img, (int(0.9 * w), int(0.815 * h)), 4, (0, 0, 255), -1)


def _draw_bookcase(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    wood = _jitter(rng, pal[0], 20)
    cv2.rectangle(img, (0, 0), (w - 1, h - 1), wood, -1)
    shelves = int(rng.integers(4, 6))
    sh = (h - 20) / shelves
    for s in range(shelves):
        top, bot = int(10 + s * sh), int(10 + (s + 1) * sh) - 8
        x = 12
        while x < w - 20:
            bw = int(rng.integers(10, 34))
            bh = int(rng.uniform(0.6, 0.95) * (bot - top))
            col = _rand_colour(rng)
            cv2.rectangle(img, (x, bot - bh), (min(x + bw, w - 12), bot), col, -1)
            if rng.random() < 0.6:
                cv2.rectangle(
                    img,
                    (x, bot - int(0.7 * bh)),
                    (min(x + bw, w - 12), bot - int(0.6 * bh)),
                    _contrast(col),
                    -1,
                )
            x += bw + int(rng.integers(1, 4))
        cv2.rectangle(img, (6, bot), (w - 6, bot + 8), _jitter(rng, pal[1], 20), -1)


def _draw_charging_station(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    cv2.rectangle(img, (int(0.08 * w), int(0.05 * h)), (int(0.92 * w), int(0.92 * h)), (45, 45, 45), -1)
    s = min(w, h)
    cx, cy = w // 2, int(0.42 * h)
    bolt = np.array([[0.1, -0.5], [-0.25, 0.05], [0.0, 0.05], [-0.1, 0.5], [0.25, -0.05], [0.0, -0.05]])
    cv2.fillPoly(img, [(bolt * s * 0.55 + [cx, cy]).astype(np.int32)], pal[1], cv2.LINE_AA)
    _put_text(img, "CHARGE", (int(0.18 * w), int(0.8 * h)), 0.9 * s / 300, (255, 255, 255), 2)
    for i in range(4):
        cv2.circle(
            img,
            (int(0.2 * w + i * 0.2 * w), int(0.12 * h)),
            6,
            pal[2] if rng.random() < 0.6 else (0, 0, 220),
            -1,
        )
    for i in range(2):
        x0 = int(0.25 * w + i * 0.35 * w)
        cv2.rectangle(img, (x0, int(0.86 * h)), (x0 + int(0.15 * w), int(0.9 * h)), (0, 170, 210), -1)


def _draw_fridge(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    cv2.rectangle(
        img, (int(0.05 * w), int(0.02 * h)), (int(0.95 * w), int(0.98 * h)), _jitter(rng, pal[0], 15), -1
    )
    split = int(rng.uniform(0.3, 0.4) * h)
    cv2.line(img, (int(0.05 * w), split), (int(0.95 * w), split), (120, 120, 120), 3)
    for y0, y1 in ((int(0.06 * h), split - 20), (split + 20, int(0.5 * h))):
        cv2.rectangle(img, (int(0.82 * w), y0), (int(0.88 * w), y1), (90, 90, 90), -1)
    for _ in range(int(rng.integers(5, 10))):
        mx, my = int(rng.uniform(0.12, 0.7) * w), int(rng.uniform(0.08, 0.9) * h)
        _pattern(
            rng,
            img,
            mx,
            my,
            mx + int(rng.integers(18, 50)),
            my + int(rng.integers(18, 50)),
            _rand_colour(rng),
        )
    nx, ny = int(0.15 * w), int(0.6 * h)
    cv2.rectangle(img, (nx, ny), (nx + int(0.5 * w), ny + int(0.2 * h)), (180, 240, 250), -1)
    for i in range(3):
        cv2.putText(
            img,
            _random_word(rng, 5),
            (nx + 6, ny + 20 + 22 * i),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.5,
            (40, 40, 140),
            1,
            cv2.LINE_AA,
        )


def _draw_coffee_machine(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    cv2.rectangle(
        img, (int(0.1 * w), int(0.03 * h)), (int(0.9 * w), int(0.95 * h)), _jitter(rng, pal[0], 15), -1
    )
    cv2.rectangle(img, (int(0.2 * w), int(0.1 * h)), (int(0.8 * w), int(0.3 * h)), (60, 120, 60), -1)
    _put_text(img, _random_word(rng, 4), (int(0.25 * w), int(0.25 * h)), 0.8 * w / 300, (180, 255, 180), 2)
    for i in range(3):
        cv2.circle(
            img,
            (int(0.3 * w + i * 0.2 * w), int(0.4 * h)),
            max(5, w // 20),
            _rand_colour(rng),
            -1,
            cv2.LINE_AA,
        )
    cv2.rectangle(img, (int(0.42 * w), int(0.45 * h)), (int(0.58 * w), int(0.55 * h)), pal[2], -1)
    cup = np.array([[0.33, 0.62], [0.67, 0.62], [0.62, 0.85], [0.38, 0.85]]) * [w, h]
    cv2.fillConvexPoly(img, cup.astype(np.int32), _rand_colour(rng), cv2.LINE_AA)
    cv2.ellipse(img, (int(0.7 * w), int(0.72 * h)), (w // 14, h // 14), 0, -90, 90, (200, 200, 200), 3)


def _draw_desk(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    top = _jitter(rng, pal[0], 25)
    cv2.rectangle(img, (int(0.02 * w), int(0.3 * h)), (int(0.98 * w), int(0.4 * h)), top, -1)
    cv2.rectangle(
        img, (int(0.65 * w), int(0.4 * h)), (int(0.95 * w), int(0.97 * h)), _jitter(rng, pal[1], 20), -1
    )
    for i in range(3):
        y0 = int(0.43 * h + i * 0.18 * h)
        cv2.rectangle(img, (int(0.67 * w), y0), (int(0.93 * w), y0 + int(0.15 * h)), top, -1)
        cv2.rectangle(img, (int(0.76 * w), y0 + 10), (int(0.84 * w), y0 + 16), (200, 200, 200), -1)
    cv2.rectangle(
        img, (int(0.05 * w), int(0.4 * h)), (int(0.09 * w), int(0.97 * h)), _jitter(rng, pal[1], 20), -1
    )
    for _ in range(int(rng.integers(2, 5))):
        x = int(rng.uniform(0.05, 0.85) * w)
        _pattern(
            rng, img, x, int(rng.uniform(0.05, 0.2) * h), x + int(0.1 * w), int(0.3 * h), _rand_colour(rng)
        )


def _draw_monitor(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    cv2.rectangle(img, (int(0.03 * w), int(0.03 * h)), (int(0.97 * w), int(0.82 * h)), (20, 20, 20), -1)
    x0, y0, x1, y1 = int(0.06 * w), int(0.07 * h), int(0.94 * w), int(0.76 * h)
    cv2.rectangle(img, (x0, y0), (x1, y1), _jitter(rng, pal[1], 50), -1)
    for _ in range(int(rng.integers(2, 4))):
        wx, wy = int(rng.uniform(x0, x1 - 120)), int(rng.uniform(y0, y1 - 80))
        ww, wh = int(rng.integers(90, 180)), int(rng.integers(60, 110))
        cv2.rectangle(img, (wx, wy), (min(wx + ww, x1), min(wy + wh, y1)), (235, 235, 235), -1)
        cv2.rectangle(img, (wx, wy), (min(wx + ww, x1), wy + 12), _rand_colour(rng), -1)
        for j in range(2):
            cv2.putText(
                img,
                _random_word(rng, 4),
                (wx + 5, wy + 36 + 26 * j),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.8,
                (40, 40, 40),
                2,
            )
    cv2.rectangle(img, (int(0.45 * w), int(0.82 * h)), (int(0.55 * w), int(0.97 * h)), (50, 50, 50), -1)


def _draw_bucket(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    col = _jitter(rng, pal[int(rng.integers(0, len(pal)))], 30)
    body = np.array([[0.12, 0.25], [0.88, 0.25], [0.75, 0.97], [0.25, 0.97]]) * [w, h]
    cv2.fillConvexPoly(img, body.astype(np.int32), col, cv2.LINE_AA)
    cv2.ellipse(
        img,
        (w // 2, int(0.25 * h)),
        (int(0.38 * w), int(0.22 * h)),
        0,
        180,
        360,
        (60, 60, 60),
        4,
        cv2.LINE_AA,
    )
    for f in (0.45, 0.7):
        cv2.line(
            img,
            (int((0.12 + 0.17 * f) * w), int(f * h)),
            (int((0.88 - 0.17 * f) * w), int(f * h)),
            _contrast(col),
            5,
        )
    _put_text(img, _random_word(rng, 3), (int(0.3 * w), int(0.62 * h)), 0.7 * w / 200, (255, 255, 255), 2)


def _draw_table(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    wood = _jitter(rng, pal[0], 25)
    cv2.rectangle(img, (int(0.02 * w), int(0.35 * h)), (int(0.98 * w), int(0.45 * h)), wood, -1)
    for x in (0.06, 0.9):
        cv2.rectangle(
            img,
            (int(x * w), int(0.45 * h)),
            (int((x + 0.04) * w), int(0.98 * h)),
            _jitter(rng, pal[1], 15),
            -1,
        )
    _pattern(rng, img, int(0.1 * w), int(0.45 * h), int(0.88 * w), int(0.55 * h), _jitter(rng, pal[2], 30))
    vx = int(rng.uniform(0.15, 0.7) * w)
    cv2.ellipse(
        img, (vx, int(0.25 * h)), (int(0.05 * w), int(0.1 * h)), 0, 0, 360, _rand_colour(rng), -1, cv2.LINE_AA
    )
    bx = int(rng.uniform(0.15, 0.7) * w)
    cv2.ellipse(
        img,
        (bx, int(0.33 * h)),
        (int(0.08 * w), int(0.05 * h)),
        0,
        0,
        180,
        _rand_colour(rng),
        -1,
        cv2.LINE_AA,
    )


def _draw_bed(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    cv2.rectangle(
        img, (int(0.02 * w), int(0.05 * h)), (int(0.1 * w), int(0.95 * h)), _jitter(rng, pal[1], 20), -1
    )
    _pattern(rng, img, int(0.1 * w), int(0.35 * h), int(0.97 * w), int(0.85 * h), _jitter(rng, pal[0], 40))
    for i in range(2):
        x0 = int(0.12 * w + i * 0.17 * w)
        cv2.rectangle(
            img, (x0, int(0.2 * h)), (x0 + int(0.15 * w), int(0.4 * h)), _jitter(rng, pal[2], 15), -1
        )


def _draw_plant(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    pot = np.array([[0.25, 0.7], [0.75, 0.7], [0.65, 0.98], [0.35, 0.98]]) * [w, h]
    cv2.fillConvexPoly(img, pot.astype(np.int32), _jitter(rng, pal[2], 30), cv2.LINE_AA)
    for _ in range(int(rng.integers(12, 20))):
        tip = (int(rng.uniform(0.1, 0.9) * w), int(rng.uniform(0.05, 0.6) * h))
        base = (w // 2 + int(rng.integers(-10, 10)), int(0.7 * h))
        cv2.line(img, base, tip, _jitter(rng, pal[1], 30), 3, cv2.LINE_AA)
        axes = (int(rng.integers(12, 30)), int(rng.integers(5, 12)))
        cv2.ellipse(
            img, tip, axes, float(rng.uniform(0, 180)), 0, 360, _jitter(rng, pal[0], 50), -1, cv2.LINE_AA
        )


def _draw_whiteboard(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    cv2.rectangle(img, (int(0.03 * w), int(0.04 * h)), (int(0.97 * w), int(0.9 * h)), pal[0], -1)
    for i in range(int(rng.integers(4, 7))):
        col = pal[1 + int(rng.integers(0, 2))]
        cv2.putText(
            img,
            _random_word(rng, int(rng.integers(3, 8))),
            (int(0.08 * w), int(0.15 * h + i * 0.12 * h)),
            cv2.FONT_HERSHEY_SCRIPT_SIMPLEX,
            1.0 * w / 600,
            col,
            2,
            cv2.LINE_AA,
        )
    pts = np.stack([np.linspace(0.6 * w, 0.92 * w, 8), rng.uniform(0.2 * h, 0.6 * h, 8)], 1)
    cv2.polylines(img, [pts.astype(np.int32)], False, pal[2], 3, cv2.LINE_AA)
    cv2.rectangle(img, (int(0.1 * w), int(0.9 * h)), (int(0.9 * w), int(0.94 * h)), (150, 150, 150), -1)


def _draw_thing(rng: np.random.Generator, img: np.ndarray, pal: tuple[Colour, ...]) -> None:
    h, w = img.shape[:2]
    for _ in range(3):
        x0, y0 = int(rng.uniform(0, 0.6) * w), int(rng.uniform(0, 0.6) * h)
        _pattern(rng, img, x0, y0, x0 + int(0.35 * w), y0 + int(0.35 * h), _rand_colour(rng))


_DRAWERS: dict[str, Drawer] = {
    "couch": _draw_couch,
    "television": _draw_television,
    "bookcase": _draw_bookcase,
    "charging_station": _draw_charging_station,
    "fridge": _draw_fridge,
    "coffee_machine": _draw_coffee_machine,
    "desk": _draw_desk,
    "monitor": _draw_monitor,
    "bucket": _draw_bucket,
    "table": _draw_table,
    "bed": _draw_bed,
    "plant": _draw_plant,
    "whiteboard": _draw_whiteboard,
}
