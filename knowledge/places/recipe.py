"""What a place model is trained on: the mix of simulated scans drawn from each labelled map.

A :class:`Recipe` says, per labelled map, which kinds of training scans to make:

* ``grid`` — 360° scans cast at every ``grid_stride``-th labelled free cell of the map as
  drawn (the book's protocol, Sect. 3.6.1; what whole-map labeling classifies);
* ``grid+rand`` — the same in ``variants`` random variants of the map
  (:func:`~knowledge.places.randomize.randomize_map`: scale, clutter, shut doors) with
  real-looking ranges (:func:`~knowledge.places.randomize.perturb_scans`);
* ``drive`` — the agent's 360° scans assembled from a front laser's scans along a simulated
  drive through each variant (:mod:`knowledge.places.drives`).

:func:`recipe_scans` makes them for one map, deterministically from the recipe's seed and
the map's name (a map's scans do not change when other maps are added or left out, so the
folds of a leave-one-building-out evaluation share them). :func:`training_scans` makes
them for many maps and adds real labelled scans; :func:`example_weights` weighs the kinds.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from knowledge.metric.raycast import cast_cells
from knowledge.places.dataset import LabelledMap, ScanSet, sample_cells
from knowledge.places.drives import DriveParams, Sensor, drive_scans, plan_tour, tour_poses
from knowledge.places.randomize import ClutterParams, ScanNoiseParams, perturb_scans, randomize_map

ProgressFn = Callable[[str, int, int], None]

#: The sensors of drives: (field of view in degrees, beams, relative frequency). A SICK LMS
#: 2xx at 0.5° and 1°, and 270° lasers (Hokuyo UTM, SICK S300 / TiM) as on many robots.
SENSORS: tuple[tuple[float, int, float], ...] = ((180.0, 361, 0.5), (180.0, 181, 0.2), (270.0, 541, 0.3))


@dataclass(frozen=True)
class Recipe:
    """The training scans made from each labelled map (see the module doc).

    Attributes:
        grid_stride: cells between clean 360° casts (0: none).
        variants: random variants of each map.
        variant_stride: cells between 360° casts in each variant (0: none).
        drive_goals: goals of the simulated drive through each variant (0: no drive).
        keep_every: keep every k-th scan of a drive (all of them build the local map).
        scale: (min, max) factor on the map's metres per cell, drawn log-uniformly.
        clutter: furniture added to each variant (times a factor from ``clutter_scale``).
        clutter_scale: (min, max) of that factor.
        doors_closed: (min, max) share of the doors shut in a variant.
        noise: scan perturbation of variants' scans (None: exact casts).
        sensors: drive sensors ``(fov degrees, beams, weight)``; one drawn per drive.
        drive: how the simulated robot drives.
        classes: classes to keep (None: all); ``merge`` renames first.
        merge: class renames (e.g. hallway → corridor).
        n_beams, max_range: the 360° scans' beams and range (the model's).
        seed: base seed.
    """

    grid_stride: int = 4
    variants: int = 2
    variant_stride: int = 8
    drive_goals: int = 25
    keep_every: int = 2
    scale: tuple[float, float] = (0.8, 1.25)
    clutter: ClutterParams = field(default_factory=ClutterParams)
    clutter_scale: tuple[float, float] = (0.5, 1.5)
    doors_closed: tuple[float, float] = (0.0, 0.4)
    noise: ScanNoiseParams | None = field(default_factory=ScanNoiseParams)
    sensors: tuple[tuple[float, int, float], ...] = SENSORS
    drive: DriveParams = field(default_factory=DriveParams)
    classes: tuple[str, ...] | None = ("room", "corridor", "doorway")
    merge: Mapping[str, str] | None = field(default_factory=lambda: {"hallway": "corridor"})
    n_beams: int = 360
    max_range: float = 30.0
    seed: int = 0

    def as_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["merge"] = dict(self.merge or {})
        return d


def _scanset(lmap: LabelledMap, ranges: np.ndarray, cells: np.ndarray, kind: str, name: str) -> ScanSet:
    names = np.array([lmap.names[int(c)] for c in lmap.labels[cells[:, 0], cells[:, 1]]], dtype=str)
    return ScanSet(
        np.asarray(ranges, dtype=np.float32),
        names.reshape(len(cells)),
        np.zeros(len(cells), dtype=np.int32),
        np.asarray(cells).reshape(-1, 2),
        (name,),
        np.full(len(cells), kind, dtype="<U16"),
    )


def _grid(
    lmap: LabelledMap, stride: int, recipe: Recipe, kind: str, rng: np.random.Generator | None, name: str
) -> ScanSet:
    cells = sample_cells(lmap, stride, offset=0 if rng is None else int(rng.integers(stride)))
    ranges = cast_cells(lmap.grid, cells, n_beams=recipe.n_beams, max_range=recipe.max_range)
    if rng is not None and recipe.noise is not None:
        angles = np.arange(recipe.n_beams) * (2 * math.pi / recipe.n_beams)
        ranges = perturb_scans(ranges, angles, rng, max_range=recipe.max_range, params=recipe.noise)
    return _scanset(lmap, ranges, cells, kind, name)


def _keep(s: ScanSet, recipe: Recipe) -> ScanSet:
    merge = dict(recipe.merge or {})
    y = np.array([merge.get(c, c) for c in s.y.tolist()], dtype=str) if merge else s.y
    s = ScanSet(s.ranges, y.reshape(len(s)), s.source, s.cells, s.maps, s.kind)
    if recipe.classes is None:
        return s
    return s.subset(np.isin(s.y, list(recipe.classes)))


def map_seed(name: str) -> int:
    """A stable number of a map's name (CRC-32), which with the recipe's seed seeds its scans."""
    return zlib.crc32(name.encode("utf-8"))


def recipe_scans(lmap: LabelledMap, recipe: Recipe, *, progress: ProgressFn | None = None) -> ScanSet:
    """The training scans of one labelled map (see the module doc), seeded by ``recipe.seed``
    and the map's name."""
    rng = np.random.default_rng([recipe.seed, map_seed(lmap.name)])
    parts = []
    if recipe.grid_stride:
        parts.append(_grid(lmap, recipe.grid_stride, recipe, "grid", None, lmap.name))
    weights = np.array([w for _, _, w in recipe.sensors], dtype=np.float64)
    for v in range(recipe.variants):
        variant = randomize_map(
            lmap,
            rng,
            scale=recipe.scale,
            clutter=recipe.clutter,
            clutter_scale=recipe.clutter_scale,
            doors_closed=recipe.doors_closed,
        )
        if recipe.variant_stride:
            parts.append(_grid(variant, recipe.variant_stride, recipe, "grid+rand", rng, lmap.name))
        if recipe.drive_goals:
            fov, beams, _ = recipe.sensors[int(rng.choice(len(recipe.sensors), p=weights / weights.sum()))]
            sensor = Sensor(math.radians(fov), int(beams), max_range=recipe.max_range)
            poses = tour_poses(plan_tour(variant, rng, recipe.drive_goals, recipe.drive), rng, recipe.drive)
            d = drive_scans(
                variant, poses, rng, sensor=sensor, noise=recipe.noise, keep_every=recipe.keep_every
            )
            parts.append(
                ScanSet(
                    d.ranges,
                    d.y,
                    np.zeros(len(d), dtype=np.int32),
                    d.cells,
                    (lmap.name,),
                    np.full(len(d), "drive", dtype="<U16"),
                )
            )
        if progress is not None:
            progress(f"scans of {lmap.name}", v + 1, recipe.variants)
    if not parts:
        raise ValueError("the recipe makes no scans: set grid_stride, variant_stride or drive_goals")
    return _keep(ScanSet.concatenate(parts), recipe)


def training_scans(
    maps: Sequence[LabelledMap],
    recipe: Recipe,
    *,
    real: ScanSet | None = None,
    progress: ProgressFn | None = None,
    cache: Callable[[LabelledMap, Recipe], ScanSet] | None = None,
) -> ScanSet:
    """The recipe's scans of every map, plus ``real`` labelled scans (kind ``"real"``).

    ``cache(lmap, recipe)``, when given, is called instead of :func:`recipe_scans` (a caller
    keeping scans on disk between runs; it must return what ``recipe_scans`` would).
    """
    make = cache or (lambda m, r: recipe_scans(m, r))
    parts = []
    for i, m in enumerate(maps):
        parts.append(make(m, recipe))
        if progress is not None:
            progress("training maps", i + 1, len(maps))
    if real is not None and len(real):
        kinds = np.full(len(real), "real", dtype="<U16")
        parts.append(_keep(ScanSet(real.ranges, real.y, real.source, real.cells, real.maps, kinds), recipe))
    return ScanSet.concatenate(parts)


def example_weights(scans: ScanSet, weights: Mapping[str, float]) -> np.ndarray:
    """``(N,)`` example weights by kind (kinds not named weigh 1)."""
    table = {str(k): float(v) for k, v in weights.items()}
    bad = [k for k, v in table.items() if not (math.isfinite(v) and v >= 0)]
    if bad:
        raise ValueError(f"weights must be finite and >= 0, got {bad}")
    return np.array([table.get(str(k), 1.0) for k in scans.kinds.tolist()], dtype=np.float64)
