"""Place models on disk: a trained decision list with everything needed to use it on scans.

A :class:`PlaceModel` bundles

* the names of the features its boosters actually use, with the boosters re-indexed to
  read only those columns; prediction computes only the columns of the boosters the list
  consults (the default class's booster is kept so other orders can be scored on test
  data, the book's Tables 3.1–3.3);
* the scan parameters the features assume (beams, maximum range, field of view);
* the (probabilistic) decision list: classes, order, all K boosters' arrays;
* the training parameters (T, weak learner kind, order mode) and a summary of the training
  data (maps, examples per class, stride, date, genius-loci version);
* ``extras``: named numpy arrays plus JSON-able metadata that later stages fill in
  (e.g. relaxation compatibility statistics).

File format ``loci.place-model/1``: ONE ``.npz`` (``np.savez_compressed``) holding a JSON
header as a uint8 array ``header_json``, the boosters' arrays as ``dl.b<i>.<name>`` and the
extras as ``extra.<name>``. It is written atomically and read with ``allow_pickle=False``;
every problem on loading is a :class:`~knowledge.errors.ModelError` saying what is wrong
and what to do.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from knowledge.errors import ModelError
from knowledge.learning.boosting import STATE_ARRAYS
from knowledge.learning.decision_list import DecisionList
from knowledge.learning.weak import FloatArray
from knowledge.npzfile import read_npz, write_npz

FORMAT = "loci.place-model/1"
#: Extras holding the trajectory HMM (Sect. 5.4): arrays ``extra.hmm_<name>``, metadata ``extras_meta["hmm"]``.
HMM_PREFIX = "hmm_"
FORMAT_FAMILY = "loci.place-model/"
RETRAIN = "retrain it with 'loci places train'"
DL_PREFIX = "dl."
EXTRA_PREFIX = "extra."


def genius_loci_version() -> str:
    """The installed genius-loci version, or "unknown"."""
    try:
        return metadata.version("genius-loci")
    except metadata.PackageNotFoundError:
        return "unknown"


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


@dataclass(frozen=True)
class ScanParams:
    """The scans a model expects: ``n_beams`` beams over ``fov`` radians (2π: a full turn,
    beam i at angle i·fov/n_beams), ``max_range`` in metres (a beam that hit nothing)."""

    n_beams: int
    max_range: float
    fov: float = 2.0 * math.pi

    def __post_init__(self) -> None:
        if int(self.n_beams) != self.n_beams or self.n_beams < 3:
            raise ValueError(f"n_beams must be an integer ≥ 3, got {self.n_beams!r}")
        if not (math.isfinite(self.max_range) and self.max_range > 0):
            raise ValueError(f"max_range must be a positive number of metres, got {self.max_range!r}")
        if not (0 < self.fov <= 2.0 * math.pi + 1e-9):
            raise ValueError(f"fov must be in (0, 2π] radians, got {self.fov!r}")


@dataclass(frozen=True)
class DataSummary:
    """Where the training examples came from: map names, examples per class, the stride
    (cells between sampled map cells, if sampled on a grid), when, and by which version;
    ``notes`` holds anything else JSON-able."""

    maps: tuple[str, ...] = ()
    examples_per_class: Mapping[str, int] = field(default_factory=dict)
    stride: int | None = None
    date: str = field(default_factory=_now)
    version: str = field(default_factory=genius_loci_version)
    notes: Mapping[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["maps"] = list(self.maps)
        d["examples_per_class"] = {str(k): int(v) for k, v in self.examples_per_class.items()}
        d["notes"] = dict(self.notes)
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> DataSummary:
        known = {f.name for f in fields(cls)}
        notes = dict(d.get("notes") or {})
        notes.update({k: v for k, v in d.items() if k not in known})
        return cls(
            maps=tuple(str(m) for m in d.get("maps", ())),
            examples_per_class={str(k): int(v) for k, v in dict(d.get("examples_per_class") or {}).items()},
            stride=None if d.get("stride") is None else int(d["stride"]),
            date=str(d.get("date", "")),
            version=str(d.get("version", "unknown")),
            notes=notes,
        )


def training_params(dl: DecisionList) -> dict[str, Any]:
    """T, weak kind, booster type and order mode of a fitted decision list."""
    first = dl.boosters_[dl.order_[0]]
    params = first.get_params()
    return {
        "booster": first.booster_type,
        "n_rounds": params["n_rounds"],
        "weak": params["weak"] if isinstance(params["weak"], str) else "per-feature",
        "balanced": params["balanced"],
        "order": dl.order_mode,
        "probabilistic": bool(dl.probabilistic),
    }


@dataclass
class PlaceModel:
    """A trained place classifier and what it needs (see the module doc).

    ``decision_list`` reads exactly the columns ``feature_names`` (build one from a list
    trained on a wider matrix with :meth:`from_decision_list`).
    """

    feature_names: tuple[str, ...]
    decision_list: DecisionList
    scan: ScanParams
    training: dict[str, Any] = field(default_factory=dict)
    data: DataSummary = field(default_factory=DataSummary)
    extras: dict[str, npt.NDArray[Any]] = field(default_factory=dict)
    extras_meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.feature_names = tuple(str(n) for n in self.feature_names)
        width = self.decision_list.n_features_in_
        if width != len(self.feature_names):
            raise ValueError(
                f"the decision list reads {width} features but {len(self.feature_names)} names are given; "
                "use PlaceModel.from_decision_list to keep only the used features"
            )
        for name, arr in self.extras.items():
            if not name or "/" in name:
                raise ValueError(f"extras names must be non-empty and without '/', got {name!r}")
            if np.asarray(arr).dtype.hasobject:
                raise ValueError(
                    f"extras[{name!r}] is an object array; models hold numeric/string arrays only"
                )

    @classmethod
    def from_decision_list(
        cls,
        dl: DecisionList,
        feature_names: Sequence[str],
        *,
        scan: ScanParams,
        data: DataSummary | None = None,
        training: Mapping[str, Any] | None = None,
        extras: Mapping[str, npt.ArrayLike] | None = None,
        extras_meta: Mapping[str, Any] | None = None,
    ) -> PlaceModel:
        """A model from a list fitted on columns named ``feature_names``; keeps only the used ones.

        ``training`` adds to (or overrides) :func:`training_params` of ``dl``.
        """
        names = list(feature_names)
        if len(names) != dl.n_features_in_:
            raise ValueError(
                f"{len(names)} feature names for a decision list fitted on {dl.n_features_in_} features"
            )
        used = dl.all_used_features()
        return cls(
            feature_names=tuple(names[i] for i in used),
            decision_list=dl.reindexed(used),
            scan=scan,
            training={**training_params(dl), **dict(training or {})},
            data=data or DataSummary(),
            extras={k: np.asarray(v) for k, v in (extras or {}).items()},
            extras_meta=dict(extras_meta or {}),
        )

    @property
    def classes(self) -> tuple[str, ...]:
        """Class names in the column order of the probabilities."""
        return tuple(self.decision_list.classes_.tolist())

    # -- the trajectory HMM (Sect. 5.4) ---------------------------------------------------

    @property
    def hmm(self) -> Any:
        """The model's :class:`~knowledge.learning.hmm.PlaceHMM`, or None if it has none.

        Raises:
            ModelError: the stored HMM is damaged or does not match the classes.
        """
        from knowledge.learning.hmm import PlaceHMM

        meta = self.extras_meta.get("hmm")
        if not meta:
            return None
        arrays = {k[len(HMM_PREFIX) :]: v for k, v in self.extras.items() if k.startswith(HMM_PREFIX)}
        try:
            hmm = PlaceHMM.from_arrays(meta, arrays)
        except (ValueError, TypeError, KeyError) as exc:
            raise ModelError(
                f"the model's HMM is damaged ({exc}): retrain the model (loci places train-default, or loci places train)"
            ) from exc
        if tuple(hmm.classes_.tolist()) != self.classes:
            raise ModelError(
                f"the model's HMM is over the classes {hmm.classes_.tolist()}, the model's are {list(self.classes)}: refit it"
            )
        return hmm

    def with_hmm(self, hmm: Any) -> PlaceModel:
        """A copy of this model carrying the fitted ``hmm`` (over the same classes), replacing any."""
        meta, arrays = hmm.to_arrays()
        if tuple(meta["classes"]) != self.classes:
            raise ValueError(
                f"the HMM is over {meta['classes']}, the model's classes are {list(self.classes)}"
            )
        extras = {k: v for k, v in self.extras.items() if not k.startswith(HMM_PREFIX)}
        extras.update({HMM_PREFIX + k: np.asarray(v) for k, v in arrays.items()})
        return replace(self, extras=extras, extras_meta={**self.extras_meta, "hmm": meta})

    # -- prediction ---------------------------------------------------------------------

    def predict_proba_features(self, X_used: npt.ArrayLike) -> FloatArray:
        """Eq. 4.5 histograms ``(S, K)`` (``classes`` order) from features ``(S, len(feature_names))``."""
        return self.decision_list.predict_proba(X_used)

    def prediction_columns(self) -> npt.NDArray[np.intp]:
        """Columns of ``feature_names`` that prediction reads (the consulted boosters' features)."""
        return self.decision_list.used_features()

    def extractor(self, *, all_features: bool = False) -> Any:
        """The :class:`~knowledge.places.features.FeatureExtractor` of the prediction columns
        (or of every column with ``all_features``); cached."""
        from knowledge.places.features import FeatureExtractor

        key = "all" if all_features else "predict"
        cache = self.__dict__.setdefault("_extractors", {})
        if key not in cache:
            cols = range(len(self.feature_names)) if all_features else self.prediction_columns()
            cache[key] = FeatureExtractor(
                [self.feature_names[i] for i in cols], max_range=self.scan.max_range
            )
        return cache[key]

    def features(self, ranges: npt.ArrayLike, *, all_features: bool = False) -> npt.NDArray[np.float32]:
        """The model's feature matrix ``(S, len(feature_names))`` float32 of scans ``(S, n_beams)``.

        Only the columns prediction reads are computed (the others, read only by the default
        class's booster when scoring other orders, are 0) unless ``all_features``.
        """
        R = np.asarray(ranges)
        if R.ndim == 1:
            R = R[None, :]
        if R.ndim != 2 or R.shape[1] != self.scan.n_beams:
            raise ValueError(
                f"this model expects scans of {self.scan.n_beams} beams, got shape {np.shape(ranges)}; "
                "resample the scans or use a model trained for them"
            )
        values = np.asarray(self.extractor(all_features=all_features)(R))
        if all_features or values.shape[1] == len(self.feature_names):
            return values
        X = np.zeros((R.shape[0], len(self.feature_names)), dtype=np.float32)
        X[:, self.prediction_columns()] = values
        return X

    def predict_proba_scans(self, ranges: npt.ArrayLike) -> FloatArray:
        """Eq. 4.5 histograms ``(S, K)`` of scans ``(S, n_beams)`` (or one scan ``(n_beams,)``) in metres."""
        return self.predict_proba_features(self.features(ranges))

    def predict_scans(self, ranges: npt.ArrayLike) -> npt.NDArray[np.str_]:
        """Class names ``(S,)`` of scans, by the decision list's rule (:meth:`DecisionList.predict`)."""
        return self.decision_list.predict(self.features(ranges))

    # -- files --------------------------------------------------------------------------

    def header(self) -> dict[str, Any]:
        """The JSON header written to the file."""
        dl_meta, _ = self.decision_list.get_state()
        return {
            "format": FORMAT,
            "feature_names": list(self.feature_names),
            "scan": asdict(self.scan),
            "training": dict(self.training),
            "data": self.data.to_json(),
            "decision_list": dl_meta,
            "extras": {"arrays": sorted(self.extras), "meta": dict(self.extras_meta)},
        }

    def save(self, path: str | Path) -> Path:
        """Write the model to ``path`` (a ``.npz``) atomically; returns the path."""
        _, dl_arrays = self.decision_list.get_state()
        arrays: dict[str, npt.ArrayLike] = {DL_PREFIX + k: v for k, v in dl_arrays.items()}
        arrays.update({EXTRA_PREFIX + name: arr for name, arr in self.extras.items()})
        return write_npz(path, self.header(), arrays)

    @classmethod
    def load(cls, path: str | Path) -> PlaceModel:
        """Read a model written by :meth:`save`; :class:`ModelError` says what is wrong and what to do."""
        p = Path(path)
        if not p.is_file():
            raise ModelError(f"{p}: no such model file; check the path or train a model first")
        header, arrays = read_npz(p, what=f"genius-loci place model ({FORMAT} .npz)", retrain=RETRAIN)
        return _from_header(p, header, arrays)


def _from_header(p: Path, header: Mapping[str, Any], arrays: Mapping[str, npt.NDArray[Any]]) -> PlaceModel:
    fmt = header.get("format")
    if not isinstance(fmt, str) or not fmt.startswith(FORMAT_FAMILY):
        raise ModelError(f"{p}: not a genius-loci place model (format {fmt!r}, expected {FORMAT!r})")
    if fmt != FORMAT:
        raise ModelError(
            f"{p}: model format {fmt!r}, but this genius-loci ({genius_loci_version()}) reads {FORMAT!r}; "
            "use the genius-loci version that wrote it, or retrain the model with this one"
        )
    for key in ("feature_names", "scan", "decision_list"):
        if key not in header:
            raise ModelError(
                f"{p}: the header lacks {key!r}; the file is incomplete: retrain or save it again"
            )
    names = header["feature_names"]
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise ModelError(f"{p}: feature_names must be a non-empty list of names")
    try:
        data = DataSummary.from_json(dict(header.get("data") or {}))
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{p}: the training-data summary in the header is damaged ({exc}): retrain") from exc
    from knowledge.places.features import validate_feature_names

    try:
        validate_feature_names(names)
    except ValueError as exc:
        raise ModelError(
            f"{p}: the model uses features this genius-loci ({genius_loci_version()}) does not know: {exc}. "
            f"It was trained with genius-loci {data.version}: use that version or retrain the model"
        ) from exc
    extras_info = dict(header.get("extras") or {})
    extra_names = [str(n) for n in extras_info.get("arrays", [])]
    missing = [EXTRA_PREFIX + n for n in extra_names if EXTRA_PREFIX + n not in arrays]
    if missing:
        raise ModelError(f"{p}: arrays {missing} are missing; the file is incomplete: save it again")
    boosters = list(dict(header["decision_list"]).get("boosters") or [])
    missing = [f"{DL_PREFIX}b{i}.{n}" for i in range(len(boosters)) for n in STATE_ARRAYS]
    missing = [k for k in missing if k not in arrays]
    if missing:
        raise ModelError(
            f"{p}: arrays {missing} are missing; the file is incomplete: save it again or retrain"
        )
    dl_arrays = {k[len(DL_PREFIX) :]: v for k, v in arrays.items() if k.startswith(DL_PREFIX)}
    try:
        scan = ScanParams(**dict(header["scan"]))
        dl = DecisionList.from_state(dict(header["decision_list"]), dl_arrays)
        model = PlaceModel(
            feature_names=tuple(names),
            decision_list=dl,
            scan=scan,
            training=dict(header.get("training") or {}),
            data=data,
            extras={n: arrays[EXTRA_PREFIX + n] for n in extra_names},
            extras_meta=dict(extras_info.get("meta") or {}),
        )
    except (ValueError, TypeError, KeyError) as exc:
        raise ModelError(
            f"{p}: the model is inconsistent ({exc}); it is damaged or was edited: retrain it"
        ) from exc
    try:
        model.hmm  # noqa: B018 - checks the stored HMM now rather than at first use
    except ModelError as exc:
        raise ModelError(f"{p}: {exc}") from exc
    return model


def default_model_path() -> Path:
    """The bundled place model of the agent: the 360° scans it assembles from its laser and
    its local map, with the trajectory HMM (``loci run``, ``loci replay``; docs/places.md)."""
    return Path(__file__).resolve().parent / "models" / "default.npz"


def default_map_model_path() -> Path:
    """The bundled place model for whole-map labeling (``loci places label``, ``loci places
    topology``): 360° casts in occupancy maps, drawn or cluttered (docs/places.md)."""
    return Path(__file__).resolve().parent / "models" / "default_map.npz"
