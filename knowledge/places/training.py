"""Training a place model from labelled maps: scans, features, decision list, statistics.

The steps of the book's experiments (Sect. 3.6.1, 4.8): simulate a 360° scan in every
``stride``-th labelled free cell of the training maps, compute every feature of the family
(App. A, B), train one generalized-AdaBoost booster per class (one against all), choose
the decision-list order, and keep what later stages need: the features the boosters use,
the scan parameters, and the label statistics for relaxation labeling (eq. 4.8).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from knowledge import labels as lbl
from knowledge.learning.boosting import DiscreteAdaBoost, GeneralizedAdaBoost
from knowledge.learning.decision_list import DecisionList
from knowledge.places.dataset import LabelledMap, ScanSet, simulate_scans
from knowledge.places.features import FeatureExtractor, default_feature_names
from knowledge.places.model import DataSummary, PlaceModel, ScanParams
from knowledge.places.regions import CorrectionThresholds, thresholds_from_training
from knowledge.places.relaxation import CompatibilityStats

ProgressFn = Callable[[str, int, int], None]

#: Class merges commonly needed: the IPA maps call halls "corridor".
HALLWAY_AS_CORRIDOR: Mapping[str, str] = {"hallway": "corridor"}


@dataclass(frozen=True)
class TrainingConfig:
    """Everything that decides what a training run produces.

    Attributes:
        classes: class names to learn, in the order used for ties and tables; None = all
            classes found in the maps.
        merge: class renames applied to the labels first (e.g. hallway → corridor).
        stride: take a scan every ``stride`` cells in both directions.
        n_beams: beams of the simulated 360° scans.
        max_range: the simulated sensor's maximum range in metres.
        rounds: boosting rounds T per binary classifier (the book uses 100).
        booster: "generalized" (Fig. 4.2, with confidences) or "discrete" (Fig. 3.3).
        weak: weak learner kind ("threshold", "interval" or "both").
        order: "best" (every order tried), "heuristic" (training error) or explicit names.
        features: feature names to offer the boosters; None = the whole family.
        balanced: start boosting from class-balanced weights 1/(2l), 1/(2m) as the book's
            Fig. 3.3/4.2 do (True), or from uniform weights 1/N (False).
    """

    classes: tuple[str, ...] | None = None
    merge: Mapping[str, str] | None = None
    stride: int = 4
    n_beams: int = 360
    max_range: float = 30.0
    rounds: int = 100
    booster: str = "generalized"
    weak: str = "threshold"
    order: str | tuple[str, ...] = "best"
    features: tuple[str, ...] | None = None
    balanced: bool = True

    def __post_init__(self) -> None:
        if self.booster not in ("generalized", "discrete"):
            raise ValueError(f"booster must be 'generalized' or 'discrete', got {self.booster!r}")
        if self.rounds < 1:
            raise ValueError(f"rounds must be >= 1, got {self.rounds}")
        if self.n_beams < 8:
            raise ValueError(f"n_beams must be >= 8, got {self.n_beams}")
        if not self.max_range > 0:
            raise ValueError(f"max_range must be > 0 metres, got {self.max_range}")

    def as_json(self) -> dict[str, Any]:
        return {
            "classes": list(self.classes) if self.classes else None,
            "merge": dict(self.merge or {}),
            "stride": self.stride,
            "n_beams": self.n_beams,
            "max_range": self.max_range,
            "rounds": self.rounds,
            "booster": self.booster,
            "weak": self.weak,
            "order": self.order if isinstance(self.order, str) else list(self.order),
            "features": "all" if self.features is None else len(self.features),
            "balanced": self.balanced,
        }


def merge_classes(lmap: LabelledMap, merge: Mapping[str, str] | None) -> LabelledMap:
    """``lmap`` with classes renamed by ``merge`` (codes follow the standard table)."""
    if not merge:
        return lmap
    lut = np.arange(256, dtype=np.uint8)
    names = dict(lmap.names)
    for code, name in lmap.names.items():
        if name in merge:
            target = merge[name]
            if target not in lbl.CLASS_CODES:
                raise ValueError(f"merge target {target!r} must be a standard class name")
            lut[code] = lbl.CLASS_CODES[target]
            names.pop(code)
            names[lbl.CLASS_CODES[target]] = target
    return LabelledMap(lmap.grid, lut[lmap.labels], names)


def unlabel_classes(lmap: LabelledMap, names: Sequence[str]) -> LabelledMap:
    """``lmap`` with the cells of the classes ``names`` unlabelled (free, but not trained on)."""
    drop = [code for code, name in lmap.names.items() if name in set(names)]
    if not drop:
        return lmap
    labels = np.where(np.isin(lmap.labels, drop), 0, lmap.labels).astype(np.uint8)
    return LabelledMap(lmap.grid, labels, lmap.names)


def features_of(
    scans: ScanSet, names: Sequence[str], max_range: float, progress: ProgressFn | None
) -> np.ndarray:
    """``(N, F)`` float32 features of the scans, computed in chunks with progress."""
    extractor = FeatureExtractor(names, max_range=max_range)
    n = len(scans)
    X = np.empty((n, len(names)), dtype=np.float32)
    step = 8192
    for start in range(0, n, step):
        stop = min(n, start + step)
        X[start:stop] = extractor(scans.ranges[start:stop])
        if progress is not None:
            progress("features", stop, n)
    return X


def relaxation_stats(maps: Sequence[LabelledMap], classes: Sequence[str]) -> CompatibilityStats:
    """Eq. 4.8's label statistics of the training maps over the model's classes."""
    codes = [lbl.CLASS_CODES.get(c) for c in classes]
    if any(c is None for c in codes):
        raise ValueError(f"relaxation statistics need standard classes, got {list(classes)}")
    keep = np.zeros(256, dtype=bool)
    keep[[int(c) for c in codes if c is not None]] = True
    samples = [(np.where(keep[m.labels], m.labels, 0), m.grid.occupied | m.grid.unknown) for m in maps]
    return CompatibilityStats.from_label_images(samples, [int(c) for c in codes if c is not None])


def correction_thresholds(maps: Sequence[LabelledMap], classes: Sequence[str]) -> CorrectionThresholds:
    """Sect. 4.7's correction thresholds from the true regions of the training maps."""
    keep = np.zeros(256, dtype=bool)
    keep[[lbl.CLASS_CODES[c] for c in classes if c in lbl.CLASS_CODES]] = True
    return thresholds_from_training(
        [np.where(keep[m.labels], m.labels, 0) for m in maps], [m.grid.resolution for m in maps]
    )


def train_place_model(
    maps: Sequence[LabelledMap],
    config: TrainingConfig,
    *,
    progress: ProgressFn | None = None,
    notes: Mapping[str, Any] | None = None,
) -> tuple[PlaceModel, dict[str, float]]:
    """Train a place model on labelled maps. Returns the model and timings (seconds)."""
    t0 = time.perf_counter()
    maps = [merge_classes(m, config.merge) for m in maps]
    classes = _classes(maps, config)
    scans = simulate_scans(
        maps,
        stride=config.stride,
        n_beams=config.n_beams,
        max_range=config.max_range,
        classes=classes,
        progress=progress,
    )
    t1 = time.perf_counter()
    model, timings = train_on_scans(scans, config, maps=maps, classes=classes, progress=progress, notes=notes)
    return model, {
        "scans": t1 - t0,
        **{k: v for k, v in timings.items() if k != "total"},
        "total": time.perf_counter() - t0,
    }


def _classes(maps: Sequence[LabelledMap], config: TrainingConfig) -> list[str]:
    present: list[str] = []
    for m in maps:
        for name in m.class_counts():
            if name not in present:
                present.append(name)
    order_pref = [c for c in lbl.CLASS_NAMES.values()]
    classes = (
        list(config.classes)
        if config.classes
        else sorted(
            present, key=lambda c: (c not in order_pref, order_pref.index(c) if c in order_pref else 0, c)
        )
    )
    missing = [c for c in classes if c not in present]
    if missing:
        raise ValueError(f"classes {missing} have no labelled cells in the training maps")
    return classes


def train_on_scans(
    scans: ScanSet,
    config: TrainingConfig,
    *,
    maps: Sequence[LabelledMap],
    classes: Sequence[str] | None = None,
    X: np.ndarray | None = None,
    sample_weight: np.ndarray | None = None,
    progress: ProgressFn | None = None,
    notes: Mapping[str, Any] | None = None,
) -> tuple[PlaceModel, dict[str, float]]:
    """Train a place model on given 360° scans (simulated, assembled along drives, or real).

    Args:
        scans: the examples; ``scans.ranges`` ``(N, config.n_beams)`` metres, ``scans.y`` names
            (renamed by ``config.merge``; examples of classes outside ``classes`` are dropped).
        config: boosting rounds, booster, order, features, scan parameters (``stride`` is only
            recorded).
        maps: labelled maps for the relaxation statistics and the correction thresholds (the
            maps the scans came from, or any representative ones), already merged.
        classes: the classes to learn (default: ``config.classes`` or those of ``scans.y``).
        X: the ``(N, F)`` features of ``scans`` for ``config.features`` (or every default
            feature) if already computed.
        sample_weight: ``(N,)`` example weights (default: equal).

    Returns the model and timings (seconds).
    """
    t1 = time.perf_counter()
    merge = dict(config.merge or {})
    y = np.array([merge.get(c, c) for c in scans.y.tolist()], dtype=str) if merge else scans.y
    cls = list(classes or config.classes or sorted(set(y.tolist())))
    keep = np.isin(y, cls)
    names = list(config.features) if config.features is not None else default_feature_names()
    if X is None:
        X = features_of(scans, names, config.max_range, progress)
    if X.shape != (len(scans), len(names)):
        raise ValueError(f"X must be ({len(scans)}, {len(names)}) features of the scans, got {X.shape}")
    w = None if sample_weight is None else np.asarray(sample_weight, dtype=np.float64)[keep]
    X, y = X[keep], y[keep]
    t2 = time.perf_counter()
    booster_cls = GeneralizedAdaBoost if config.booster == "generalized" else DiscreteAdaBoost
    factory = functools.partial(
        booster_cls, n_rounds=config.rounds, weak=config.weak, balanced=config.balanced
    )
    dl = DecisionList(factory, order=config.order)
    dl.fit(X, y, classes=cls, sample_weight=w, progress=progress)
    t3 = time.perf_counter()
    stats = relaxation_stats(maps, cls)
    thresholds = correction_thresholds(maps, cls)
    counts = {str(c): int(n) for c, n in zip(*np.unique(y, return_counts=True), strict=True)}
    model = PlaceModel.from_decision_list(
        dl,
        names,
        scan=ScanParams(n_beams=config.n_beams, max_range=config.max_range),
        data=DataSummary(
            maps=tuple(
                dict.fromkeys(
                    [*(scans.maps[int(i)] for i in np.unique(scans.source)), *(m.name for m in maps)]
                )
            ),
            examples_per_class=counts,
            stride=config.stride,
            notes={"config": config.as_json(), **dict(notes or {})},
        ),
        extras=stats.to_arrays(),
        extras_meta={
            "relaxation": {"classes": list(cls), "resolution": [m.grid.resolution for m in maps]},
            "correction": {
                "thresholds": thresholds.to_dict(),
                "from": "thresholds_from_training (area-weighted quantile of the true regions)",
            },
        },
    )
    t4 = time.perf_counter()
    return model, {"features": t2 - t1, "boosting": t3 - t2, "finish": t4 - t3, "total": t4 - t1}


def fit_trajectory_hmm(
    model: PlaceModel,
    observations: ScanSet,
    maps: Sequence[LabelledMap],
    *,
    hmm: Any = None,
    seed: int = 0,
) -> PlaceModel:
    """``model`` with a fitted trajectory HMM (Sect. 5.4) in it.

    Args:
        model: the place model.
        observations: labelled 360° scans as the robot sees them (e.g. the ``drive`` scans of
            a recipe); the model's histograms of them give each class's mean histogram.
        maps: labelled maps (classes renamed as the model's) for the simulated Move transitions.
        hmm: an unfitted :class:`~knowledge.learning.hmm.PlaceHMM` with its parameters (default
            the book's: m = 50, 1,000 moves of 20–50 cm).
        seed: seeds the moves and the choice of the m observations.
    """
    from knowledge.learning.hmm import PlaceHMM, move_transitions

    est = hmm if hmm is not None else PlaceHMM()
    classes = model.classes
    codes = [lbl.CLASS_CODES[c] for c in classes]
    rng = np.random.default_rng(seed)
    counts = move_transitions(
        [m.labels for m in maps],
        [m.grid.resolution for m in maps],
        [m.grid.free for m in maps],
        codes,
        rng,
        n_moves=est.n_moves,
        distance=est.distance,
    )
    keep = np.isin(observations.y, list(classes))
    proba = np.empty((int(keep.sum()), len(classes)))
    R = observations.ranges[keep]
    for start in range(0, len(R), 8192):
        proba[start : start + 8192] = model.predict_proba_scans(R[start : start + 8192])
    est.fit(proba, observations.y[keep], classes=classes, move_counts=counts, rng=rng)
    return model.with_hmm(est)
