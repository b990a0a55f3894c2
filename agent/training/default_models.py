"""The bundled place models, trained by one reproducible command (``loci places train-default``).

Two models are made from the same training scans, because the agent and whole-map labeling
classify different things (``docs/places.md``, "The bundled models"):

* ``default.npz``, the **agent's** model (``loci run``, ``loci replay``): the 360° scans the
  agent assembles from a front laser and its local map, in randomised, cluttered variants of
  the maps (``grid+rand``, ``drive``), the real labelled Freiburg 079 scans (``real``), and a
  little of the clean casts (weight 0.1, so that an empty room is still a room), with the
  trajectory HMM (Sect. 5.4);
* ``default_map.npz``, the **map** model (``loci places label``, ``loci places topology``):
  360° casts in the maps as drawn (``grid``) and in the randomised variants, and the drives.

Clean casts pull a model towards the drawings: the more of them, the worse it labels real
scans; without any, an empty room looks like nothing the agent's model knows (it calls it a
corridor). The map model needs the drawn maps and gains from the drives too (docs/places.md).

Training data: the five labelled IPA buildings (``DATA/ipa/labeled``), ``--generated``
procedurally generated office floors (seeds 1000, 1001, ...; their open halls unlabelled), and the labelled Freiburg 079
log (``DATA/logs/fr079_labels_provisional.npz``), through the recipes of
:mod:`knowledge.places.recipe`. Everything is seeded: the same data and version give the same
models (the header's training date aside); the scan cache is keyed by the map, the recipe
and the source of the code that makes the scans. ``--without`` leaves buildings out (``fr079`` or an IPA building), which is how the
evaluations train models that never saw the building they score.

Run: ``loci places train-default`` (or ``make default-models``); about 20 minutes on one core.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from knowledge.learning.hmm import PlaceHMM
from knowledge.places.dataset import IPA_BUILDINGS, LabelledMap, ScanSet, load_ipa_building
from knowledge.places.recipe import Recipe, example_weights, recipe_scans, training_scans
from knowledge.places.training import (
    HALLWAY_AS_CORRIDOR,
    TrainingConfig,
    fit_trajectory_hmm,
    merge_classes,
    train_on_scans,
    unlabel_classes,
)

ProgressFn = Callable[[str, int, int], None]

CLASSES = ("room", "corridor", "doorway")
#: The real labelled log's name in ``--without`` and in the model's data summary.
FR079 = "fr079"
#: Generated buildings' map names start with this (sim.buildings).
GENERATED_PREFIX = "building_"
#: Seeds of the generated buildings (the first ``--generated`` of them).
GENERATED_SEED = 1000
GENERATED = 10
#: The recipe for the labelled IPA maps: clean casts every 4th cell, two randomised variants.
IPA_RECIPE = Recipe()
#: Generated floors are large and many: fewer scans from each.
GENERATED_RECIPE = replace(Recipe(), grid_stride=8, variant_stride=12, drive_goals=15)
#: Example weights by kind for each model (0: not used).
WEIGHTS: Mapping[str, Mapping[str, float]] = {
    "agent": {"grid": 0.1, "grid+rand": 1.0, "drive": 1.0, "real": 2.0},
    "map": {"grid": 1.0, "grid+rand": 1.0, "drive": 1.0, "real": 0.0},
}
#: The agent model's HMM: the book's moves, the histogram as observation (docs/results/places_fr079.md).
HMM_PARAMS: Mapping[str, Any] = {"observation": "histogram", "temper": 0.5}
#: The maps whose scans each model is trained on: the map model only on the labelled IPA
#: buildings (with the generated floors it labelled lab_d_furnitures, left out, no better:
#: 80.1 % against 80.7 %, docs/places.md), the agent's on every map (they help on real scans).
GENERATED_FOR = {"agent": True, "map": False}
#: File names of the two models.
FILES = {"agent": "default.npz", "map": "default_map.npz"}
CONFIG = TrainingConfig(classes=CLASSES, merge=dict(HALLWAY_AS_CORRIDOR), rounds=100)


@dataclass(frozen=True)
class TrainingSet:
    """Everything a default model is trained on."""

    maps: tuple[LabelledMap, ...]
    scans: ScanSet

    def names(self) -> list[str]:
        return [m.name for m in self.maps]


def _code_digest() -> bytes:
    """The source of the modules that make the training scans: a change there is a new cache
    entry, not a silently reused old scan."""
    import knowledge.metric.local_map
    import knowledge.metric.raycast
    import knowledge.metric.rear_beams
    import knowledge.places.dataset
    import knowledge.places.drives
    import knowledge.places.randomize
    import knowledge.places.recipe

    h = hashlib.sha1()
    for mod in (
        knowledge.metric.local_map,
        knowledge.metric.raycast,
        knowledge.metric.rear_beams,
        knowledge.places.dataset,
        knowledge.places.drives,
        knowledge.places.randomize,
        knowledge.places.recipe,
    ):
        h.update(Path(str(mod.__file__)).read_bytes())
    return h.digest()


def _key(lmap: LabelledMap, recipe: Recipe) -> str:
    """The recipe's and the map's contents and the scan-making code, hashed (a changed map,
    recipe or code is a new entry)."""
    h = hashlib.sha1(json.dumps(recipe.as_json(), sort_keys=True, default=str).encode())
    h.update(_code_digest())
    h.update(np.ascontiguousarray(lmap.grid.state).tobytes())
    h.update(np.ascontiguousarray(lmap.labels).tobytes())
    h.update(repr(lmap.grid.resolution).encode())
    return h.hexdigest()[:12]


def cached_recipe_scans(cache: Path | None) -> Callable[[LabelledMap, Recipe], ScanSet]:
    """:func:`recipe_scans`, kept in ``cache`` (``<map>__<recipe hash>.npz``) when given."""

    def make(lmap: LabelledMap, recipe: Recipe) -> ScanSet:
        if cache is None:
            return recipe_scans(lmap, recipe)
        path = cache / f"{lmap.name}__{_key(lmap, recipe)}.npz"
        if path.is_file():
            with np.load(path, allow_pickle=False) as z:
                return ScanSet(z["ranges"], z["y"], z["source"], z["cells"], (lmap.name,), z["kind"])
        s = recipe_scans(lmap, recipe)
        cache.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, ranges=s.ranges, y=s.y, source=s.source, cells=s.cells, kind=s.kinds)
        tmp.replace(path)
        return s

    return make


def training_set(
    data: Path,
    *,
    without: Sequence[str] = (),
    generated: int = GENERATED,
    cache: Path | None = None,
    progress: ProgressFn | None = None,
) -> TrainingSet:
    """The maps and scans of the default models, leaving out the buildings in ``without``."""
    from agent.training.labelled_log import load_fr079, real_scans
    from sim.buildings import generate_building

    unknown = sorted(set(without) - set(IPA_BUILDINGS) - {FR079})
    if unknown:
        raise ValueError(f"--without names {unknown}; choose from {', '.join((*IPA_BUILDINGS, FR079))}")
    make = cached_recipe_scans(cache)
    ipa = [
        merge_classes(load_ipa_building(data, b), HALLWAY_AS_CORRIDOR)
        for b in IPA_BUILDINGS
        if b not in without
    ]
    gen = []
    for i in range(generated):
        b = generate_building(GENERATED_SEED + i)
        # their open halls are left unlabelled: the IPA maps call such a space a room in one
        # building (lab_d_furnitures' central hall) and a corridor in another
        gen.append(unlabel_classes(LabelledMap(b.grid, b.labels), ["hallway"]))
        if progress is not None:
            progress("generating buildings", i + 1, generated)
    real = None
    if FR079 not in without:
        real = real_scans(load_fr079(data), n_beams=CONFIG.n_beams, max_range=CONFIG.max_range, name=FR079)
    parts = []
    if ipa or real is not None:
        parts.append(training_scans(ipa, IPA_RECIPE, real=real, progress=progress, cache=make))
    if gen:
        parts.append(training_scans(gen, GENERATED_RECIPE, progress=progress, cache=make))
    if not parts:
        raise ValueError("nothing to train on: every building is left out and no generated one is asked for")
    return TrainingSet(tuple(ipa + gen), ScanSet.concatenate(parts))


def train_models(
    ts: TrainingSet,
    *,
    which: Sequence[str] = ("agent", "map"),
    rounds: int | None = None,
    progress: ProgressFn | None = None,
    notes: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The default models (``"agent"``, ``"map"``) trained on a training set; the agent's
    carries the HMM, fitted on its drive and real scans and moves in the maps. ``rounds``
    overrides T (for quick tests only)."""
    config = CONFIG if rounds is None else replace(CONFIG, rounds=rounds)
    from knowledge.places.features import FeatureExtractor, default_feature_names

    names = default_feature_names()
    fx = FeatureExtractor(names, max_range=CONFIG.max_range)
    X = np.empty((len(ts.scans), len(names)), dtype=np.float32)
    for start in range(0, len(ts.scans), 8192):
        X[start : start + 8192] = fx(ts.scans.ranges[start : start + 8192])
        if progress is not None:
            progress("features", min(start + 8192, len(ts.scans)), len(ts.scans))
    out: dict[str, Any] = {}
    generated_scan = np.array([m.startswith(GENERATED_PREFIX) for m in ts.scans.maps])[ts.scans.source]
    for kind in which:
        w = example_weights(ts.scans, WEIGHTS[kind])
        use = w > 0
        maps = ts.maps
        if not GENERATED_FOR[kind]:
            use &= ~generated_scan
            maps = tuple(m for m in ts.maps if not m.name.startswith(GENERATED_PREFIX))
        if not use.any() or not maps:
            raise ValueError(f"the {kind} model has nothing to train on: keep at least one IPA building")
        model, _timings = train_on_scans(
            ts.scans.subset(use),
            config,
            maps=maps,
            classes=CLASSES,
            X=X[use],
            sample_weight=w[use],
            progress=progress,
            notes={
                "model": kind,
                "weights": dict(WEIGHTS[kind]),
                "examples_per_kind": {
                    str(k): int(n)
                    for k, n in zip(*np.unique(ts.scans.kinds[use], return_counts=True), strict=True)
                },
                "recipes": {"ipa": IPA_RECIPE.as_json(), "generated": GENERATED_RECIPE.as_json()},
                "command": "loci places train-default",
                **dict(notes or {}),
            },
        )
        if kind == "agent":
            robot_view = np.isin(ts.scans.kinds, ["drive", "real"]) & use
            model = fit_trajectory_hmm(
                model, ts.scans.subset(robot_view), maps, hmm=PlaceHMM(**HMM_PARAMS), seed=0
            )
        out[kind] = model
    return out


def train_default(
    data: Path,
    out_dir: Path,
    *,
    without: Sequence[str] = (),
    generated: int = GENERATED,
    cache: Path | None = None,
    which: Sequence[str] = ("agent", "map"),
    rounds: int | None = None,
    progress: ProgressFn | None = None,
) -> dict[str, Any]:
    """Train and write the default models; returns a summary (files, examples, seconds)."""
    t0 = time.perf_counter()
    ts = training_set(data, without=without, generated=generated, cache=cache, progress=progress)
    t1 = time.perf_counter()
    models = train_models(
        ts,
        which=which,
        rounds=rounds,
        progress=progress,
        notes={"without": list(without), "generated": generated},
    )
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {}
    for kind, model in models.items():
        files[kind] = str(model.save(out_dir / FILES[kind]))
    kinds, counts = np.unique(ts.scans.kinds, return_counts=True)
    return {
        "files": files,
        "maps": ts.names() + ([] if FR079 in without else [FR079]),
        "examples_per_kind": {str(k): int(n) for k, n in zip(kinds, counts, strict=True)},
        "examples_per_class": ts.scans.class_counts(),
        "seconds": {"scans": round(t1 - t0, 1), "total": round(time.perf_counter() - t0, 1)},
    }
