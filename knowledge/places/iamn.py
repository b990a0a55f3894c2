"""Instance-based associative Markov networks for whole maps (Sect. 4.6): train, save, label.

The network's nodes are the blocks of a coarser lattice laid over the occupancy grid, one
node per block of ``step × step`` cells that holds a free cell (``step`` = the node spacing,
0.2 m in the book's experiment, divided by the map's resolution and rounded; 1 on a 0.2 m
map). A node's scan is cast from the block's free cell nearest to the block's centre, at
the map's own resolution; edges join 8-neighbouring blocks. On labelling, every free cell
takes its block's label.

Pipeline: the 309 scan features of every node (App. A, B) → FDR selection of L* of them
(:mod:`.fdr`, on the training nodes) → the nearest-neighbour transform τ_M
(:mod:`.nn_transform`, the training nodes are the instances), each row divided by its mean
(:func:`relative`) → the AMN over the lattice (:mod:`.amn`: tied node weights started from
the nearest-neighbour rule, max-margin, α-expansion MAP). The AMN learns from the training
nodes' τ_M cross-fitted between stripes of the training region (:func:`cross_transform`).

File format ``loci.iamn-model/1``: one ``.npz`` (:mod:`knowledge.npzfile`: JSON header as
``header_json``, never pickles) beside the AdaBoost place models. The header lists the
classes, the selected features in the order FDR picked them with their FDR, the scan
parameters, the node spacing and the training parameters; the arrays are the NN instances
(``nn_X`` standardised, ``nn_y``, ``nn_mean``, ``nn_scale``) and the AMN weights
(``w_node``, ``w_edge``).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from knowledge.errors import MapError, ModelError
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.raycast import cast_cells
from knowledge.npzfile import read_npz, write_npz
from knowledge.places.amn import AMN, grid_edges
from knowledge.places.dataset import LabelledMap
from knowledge.places.fdr import select_features
from knowledge.places.labeling import MapLabels, class_codes
from knowledge.places.model import FORMAT as PLACE_FORMAT
from knowledge.places.model import DataSummary, ScanParams, genius_loci_version
from knowledge.places.nn_transform import NNTransform

FORMAT = "loci.iamn-model/1"
RETRAIN = "retrain it (tools/iamn_experiment.py or knowledge.places.iamn.train_iamn)"
ARRAYS = ("nn_X", "nn_y", "nn_mean", "nn_scale", "w_node", "w_edge")

ProgressFn = Callable[[str, int, int], None]


@dataclass(frozen=True)
class IAMNConfig:
    """Training parameters.

    Attributes:
        n_features: L*, features FDR keeps (the book: 30 of 203).
        n_neighbors: M of eq. 4.11.
        spacing: node spacing in metres (the book: 0.2).
        w1, w2: weights of FDR and correlation in Fig. 4.6.
        C, epochs, step: the AMN's max-margin learning (:class:`~knowledge.places.amn.AMN`).
        n_beams, max_range: the simulated 360° scans.
        features: candidate feature names (default: all of :func:`default_feature_names`).
        scales: start scales of the nearest-neighbour rule tried by the learner (see train_iamn).
        folds: the AMN learns from the training nodes' τ_M computed against the instances of
            the *other* folds (stripes across the training map's longer side; see
            :func:`cross_transform`); 1 means leave-one-out against all the others.
    """

    n_features: int = 30
    n_neighbors: int = 1
    spacing: float = 0.2
    w1: float = 1.0
    w2: float = 1.0
    C: float = 1e-3
    epochs: int = 150
    step: float = 0.5
    n_beams: int = 360
    max_range: float = 30.0
    features: tuple[str, ...] | None = None
    folds: int = 2
    scales: tuple[float, ...] = (1.0, 3.0, 10.0, 30.0, 100.0)


@dataclass(frozen=True, eq=False)
class Lattice:
    """The nodes of a map's network.

    Attributes:
        step: cells per block side.
        cells: ``(N, 2)`` (row, col) of each node's scan cell (a free cell).
        blocks: ``(N, 2)`` block (row, col) of each node; 8-neighbouring blocks are joined.
        free: ``(F, 2)`` every free cell considered, and ``node_of`` ``(F,)`` its node.
    """

    step: int
    cells: np.ndarray
    blocks: np.ndarray
    free: np.ndarray
    node_of: np.ndarray

    def edges(self) -> np.ndarray:
        return grid_edges(self.blocks)


def lattice(grid: OccupancyGrid, spacing: float, mask: np.ndarray | None = None) -> Lattice:
    """The nodes of ``grid``'s free cells (inside ``mask`` if given) at ``spacing`` metres."""
    step = max(1, round(spacing / grid.resolution))
    free_mask = grid.free if mask is None else grid.free & mask
    free = np.argwhere(free_mask)
    if len(free) == 0:
        raise MapError(
            f"{grid.name}: no free cells to label; is the map's free space white (or its YAML thresholds right)?"
        )
    block = free // step
    centre = block * step + (step - 1) / 2.0
    d2 = np.sum((free - centre) ** 2, axis=1)
    ncols = int(block[:, 1].max()) + 1
    bid = block[:, 0] * ncols + block[:, 1]
    order = np.lexsort((d2, bid))
    first = np.ones(len(order), dtype=bool)
    first[1:] = bid[order][1:] != bid[order][:-1]
    reps = order[first]
    uniq = bid[reps]
    node_of = np.searchsorted(uniq, bid)
    return Lattice(step=step, cells=free[reps], blocks=block[reps], free=free, node_of=node_of)


def node_features(
    grid: OccupancyGrid,
    cells: np.ndarray,
    names: Sequence[str],
    scan: ScanParams,
    progress: ProgressFn | None = None,
) -> np.ndarray:
    """``(N, len(names))`` float32 features of 360° scans cast from ``cells`` of ``grid``."""
    from knowledge.places.features import FeatureExtractor

    extractor = FeatureExtractor(list(names), max_range=scan.max_range)
    X = np.empty((len(cells), len(names)), dtype=np.float32)
    chunk = 8192
    for s in range(0, len(cells), chunk):
        e = min(len(cells), s + chunk)
        ranges = cast_cells(grid, cells[s:e], n_beams=scan.n_beams, max_range=scan.max_range)
        X[s:e] = extractor(ranges)
        if progress is not None:
            progress("features", e, len(cells))
    return X


def relative(T: np.ndarray) -> np.ndarray:
    """Each row of τ_M divided by its mean: the AMN reads how much nearer one class is than the others.

    Plain distances grow on a map the training instances do not cover well (on building 79's
    right half they are 2.4 times those of the training nodes), which shifts every linear
    score by a different amount per class; the ratios do not.
    """
    m = T.mean(axis=1, keepdims=True)
    return np.asarray(T / np.where(m > 0, m, 1.0))


@dataclass
class IAMNModel:
    """A trained iAMN (see the module doc)."""

    classes: tuple[str, ...]
    feature_names: tuple[str, ...]
    fdr: np.ndarray
    scan: ScanParams
    spacing: float
    nn: NNTransform
    amn: AMN
    training: dict[str, Any] = field(default_factory=dict)
    data: DataSummary = field(default_factory=DataSummary)

    def __post_init__(self) -> None:
        K = len(self.classes)
        if len(self.nn.classes_) != K or self.amn.w_edge_.shape != (K,):
            raise ValueError(
                f"{K} classes but the NN transform has {len(self.nn.classes_)} and the AMN {self.amn.w_edge_.shape}"
            )
        if self.nn.X_.shape[1] != len(self.feature_names):
            raise ValueError(
                f"{len(self.feature_names)} features but the NN instances have {self.nn.X_.shape[1]}"
            )

    def node_scores(self, X_selected: npt.ArrayLike) -> np.ndarray:
        """``(N, K)`` AMN node scores of nodes with the selected features ``(N, L*)``."""
        return self.amn.scores(relative(self.nn.transform(X_selected)))

    # -- files --------------------------------------------------------------------------

    def header(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "classes": list(self.classes),
            "feature_names": list(self.feature_names),
            "fdr": [float(v) for v in self.fdr],
            "scan": asdict(self.scan),
            "spacing_m": float(self.spacing),
            "n_neighbors": int(self.nn.n_neighbors),
            "training": dict(self.training),
            "data": self.data.to_json(),
        }

    def save(self, path: str | Path) -> Path:
        """Write the model atomically (npz + JSON header); returns the path."""
        arrays: dict[str, np.ndarray] = {
            "nn_X": self.nn.X_.astype(np.float32),
            "nn_y": self.nn.y_.astype(np.int16),
            "nn_mean": self.nn.mean_,
            "nn_scale": self.nn.scale_,
            "w_node": self.amn.w_node_,
            "w_edge": self.amn.w_edge_,
        }
        return write_npz(path, self.header(), arrays)

    @classmethod
    def load(cls, path: str | Path) -> IAMNModel:
        """Read a model written by :meth:`save`; :class:`ModelError` says what is wrong."""
        p = Path(path)
        if not p.is_file():
            raise ModelError(f"{p}: no such model file; check the path or train an iAMN first")
        header, arrays = read_npz(p, what=f"genius-loci iAMN model ({FORMAT} .npz)", retrain=RETRAIN)
        fmt = header.get("format")
        if fmt == PLACE_FORMAT:
            raise ModelError(
                f"{p}: an AdaBoost place model ({fmt}), not an iAMN; use it with --method adaboost "
                "or give an iAMN model"
            )
        if fmt != FORMAT:
            raise ModelError(
                f"{p}: format {fmt!r}, this genius-loci ({genius_loci_version()}) reads {FORMAT!r}"
            )
        missing = [a for a in ARRAYS if a not in arrays]
        if missing:
            raise ModelError(f"{p}: arrays {missing} are missing; the file is incomplete: {RETRAIN}")
        try:
            from knowledge.places.features import validate_feature_names

            names = tuple(str(n) for n in header["feature_names"])
            validate_feature_names(list(names))
            classes = tuple(str(c) for c in header["classes"])
            nn = NNTransform(int(header["n_neighbors"])).set_state(
                np.asarray(classes), arrays["nn_mean"], arrays["nn_scale"], arrays["nn_X"], arrays["nn_y"]
            )
            amn = AMN(**{k: v for k, v in dict(header["training"]).get("amn", {}).items()})
            amn.set_weights(arrays["w_node"], arrays["w_edge"])
            return cls(
                classes=classes,
                feature_names=names,
                fdr=np.asarray(header["fdr"], dtype=np.float64),
                scan=ScanParams(**dict(header["scan"])),
                spacing=float(header["spacing_m"]),
                nn=nn,
                amn=amn,
                training=dict(header["training"]),
                data=DataSummary.from_json(dict(header.get("data") or {})),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelError(f"{p}: the iAMN model is inconsistent ({exc}); {RETRAIN}") from exc


def node_truth(lmap: LabelledMap, lat: Lattice, classes: Sequence[str]) -> np.ndarray:
    """``(N,)`` class index of each node's scan cell, -1 where unlabelled or not in ``classes``."""
    codes = lmap.labels[lat.cells[:, 0], lat.cells[:, 1]]
    index = {c: i for i, c in enumerate(classes)}
    return np.array([index.get(lmap.names.get(int(c), ""), -1) if c else -1 for c in codes], dtype=np.intp)


def cross_transform(
    X: np.ndarray,
    y: np.ndarray,
    blocks: np.ndarray,
    folds: int,
    n_neighbors: int,
    classes: Sequence[str],
    *,
    groups: np.ndarray | None = None,
) -> np.ndarray:
    """``relative(τ_M)`` of the training nodes as the AMN will meet it on a new map.

    Neighbouring nodes see nearly the same scan, so a training node's nearest instance of its
    own class is almost always a neighbour at a tiny distance, even when the node itself is
    left out: on building 79 those distances are 2.4 times smaller than on the test half, and
    weights learned on them trust the own-class distance too much. So the nodes are cut into
    ``folds`` stripes across the longer side of the training region, and each stripe's
    τ_M is computed against an :class:`NNTransform` of the other stripes (cross-fitting).
    ``groups`` ``(N,)`` (e.g. the map of each node) replaces the stripes as the folds.
    """
    if groups is not None:
        fold = np.unique(np.asarray(groups), return_inverse=True)[1]
        folds = int(fold.max()) + 1
    elif folds <= 1:
        return relative(NNTransform(n_neighbors).fit(X, y).transform_training())
    else:
        axis = int(np.ptp(blocks[:, 1]) >= np.ptp(blocks[:, 0]))
        cuts = np.quantile(blocks[:, axis], np.linspace(0, 1, folds + 1)[1:-1])
        fold = np.searchsorted(cuts, blocks[:, axis], side="right")
    T = np.empty((len(X), len(classes) * n_neighbors))
    for f in range(folds):
        inside, rest = fold == f, fold != f
        missing = sorted(set(range(len(classes))) - set(np.unique(y[rest]).tolist()))
        if missing:
            raise ValueError(
                f"with {folds} folds, the nodes outside fold {f} hold no {[classes[m] for m in missing]}; "
                "use fewer folds (IAMNConfig.folds) or a training region with more of each class"
            )
        T[inside] = relative(NNTransform(n_neighbors).fit(X[rest], y[rest]).transform(X[inside]))
    return T


def train_iamn(
    lmap: LabelledMap | Sequence[LabelledMap],
    config: IAMNConfig = IAMNConfig(),
    *,
    mask: np.ndarray | None = None,
    classes: Sequence[str] | None = None,
    progress: ProgressFn | None = None,
) -> tuple[IAMNModel, dict[str, float]]:
    """Train an iAMN on the labelled free cells of ``lmap`` (inside ``mask``, e.g. the left half).

    Several maps make one network with no edge between maps; their nodes are then cross-fitted
    map against map (:func:`cross_transform`) instead of by stripes. ``mask`` is for one map.
    Returns the model and timings in seconds (``features``, ``select``, ``transform``, ``learn``).
    """
    from knowledge.places.features import default_feature_names

    t0 = time.perf_counter()
    maps = [lmap] if isinstance(lmap, LabelledMap) else list(lmap)
    if not maps or (mask is not None and len(maps) > 1):
        raise ValueError("give one map (with an optional mask) or several maps without a mask")
    scan = ScanParams(n_beams=config.n_beams, max_range=config.max_range)
    names = list(config.features or default_feature_names())
    present = sorted({c for m in maps for c in m.class_counts()})
    cls = tuple(classes) if classes else tuple(present)
    parts_X, parts_b, parts_y, parts_g = [], [], [], []
    offset = 0
    for g, m in enumerate(maps):
        lat = lattice(m.grid, config.spacing, mask)
        truth = node_truth(m, lat, cls)
        keep = truth >= 0
        parts_X.append(node_features(m.grid, lat.cells[keep], names, scan, progress))
        b = lat.blocks[keep]
        parts_b.append(
            b + np.array([offset, 0])
        )  # maps side by side, two empty block rows apart: no edges across
        offset += int(b[:, 0].max()) + 3 if len(b) else 0
        parts_y.append(truth[keep])
        parts_g.append(np.full(int(keep.sum()), g))
    X, blocks, y = np.vstack(parts_X), np.vstack(parts_b), np.concatenate(parts_y)
    groups = np.concatenate(parts_g)
    counts = np.bincount(y, minlength=len(cls))
    if np.any(counts < config.n_neighbors + 1):
        raise ValueError(
            f"every class needs more than {config.n_neighbors} labelled nodes; "
            f"got {dict(zip(cls, counts.tolist(), strict=True))}"
        )
    t1 = time.perf_counter()
    good = np.all(np.isfinite(X), axis=0)
    sel = select_features(X[:, good], y, min(config.n_features, int(good.sum())), w1=config.w1, w2=config.w2)
    cols = np.flatnonzero(good)[sel.indices]
    Xs = X[:, cols]
    t2 = time.perf_counter()
    nn = NNTransform(config.n_neighbors).fit(Xs, y)
    T = cross_transform(
        Xs, y, blocks, config.folds, config.n_neighbors, cls, groups=groups if len(maps) > 1 else None
    )
    t3 = time.perf_counter()
    # start from the nearest-neighbour rule θ_i(k) = -s·t_ik. Its scale s against the loss
    # decides how far the subgradient steps get, and they hardly move it: so fit from several
    # scales and keep the fit with the lowest training objective (the learner's own criterion)
    K, M = len(cls), config.n_neighbors
    edges = grid_edges(blocks)
    fits = []
    for scale in config.scales:
        init = np.concatenate([np.full(M, -scale / M), np.zeros(K)])
        fits.append(
            AMN(C=config.C, epochs=config.epochs, step=config.step, tied=True).fit(T, edges, y, K, init=init)
        )
    objectives = [min(a.history_) for a in fits]
    amn = fits[int(np.argmin(objectives))]
    t4 = time.perf_counter()
    model = IAMNModel(
        classes=cls,
        feature_names=tuple(names[i] for i in cols),
        fdr=sel.fdr,
        scan=scan,
        spacing=config.spacing,
        nn=nn,
        amn=amn,
        training={
            "method": "iamn",
            "n_features": len(cols),
            "candidates": len(names),
            "w1": config.w1,
            "w2": config.w2,
            "learning": "max-margin, projected subgradient with loss-augmented alpha-expansion",
            "amn": {"C": config.C, "epochs": config.epochs, "step": config.step, "tied": True},
            "folds": config.folds,
            "scales_tried": list(config.scales),
            "objectives": [round(v, 5) for v in objectives],
            "final_objective": float(amn.history_[-1]),
        },
        data=DataSummary(
            maps=tuple(m.name for m in maps),
            examples_per_class={c: int(n) for c, n in zip(cls, counts, strict=True)},
            notes={"spacing_m": config.spacing},
        ),
    )
    timings = {"features": t1 - t0, "select": t2 - t1, "transform": t3 - t2, "learn": t4 - t3}
    timings["total"] = time.perf_counter() - t0
    return model, timings


def label_map_iamn(
    grid: OccupancyGrid,
    model: IAMNModel,
    *,
    mask: np.ndarray | None = None,
    progress: ProgressFn | None = None,
) -> tuple[MapLabels, Lattice, np.ndarray]:
    """Label every free cell of ``grid`` (inside ``mask``) by MAP inference in the iAMN.

    Returns the :class:`~knowledge.places.labeling.MapLabels` of the free cells (``proba``
    one-hot: MAP gives a joint assignment, not marginals), the lattice and its ``(N,)`` node
    labels (class indices).
    """
    t0 = time.perf_counter()
    lat = lattice(grid, model.spacing, mask)
    X = node_features(grid, lat.cells, model.feature_names, model.scan, progress)
    if not np.all(np.isfinite(X)):
        bad = int(np.sum(~np.all(np.isfinite(X), axis=1)))
        warnings.warn(
            f"{bad} nodes have NaN or infinite features; they count as 0", RuntimeWarning, stacklevel=2
        )
        X = np.nan_to_num(X, nan=0.0, posinf=0.0, neginf=0.0)
    t1 = time.perf_counter()
    res = model.amn.predict(relative(model.nn.transform(X)), lat.edges()) if len(X) else None
    node_labels = res.labels if res is not None else np.zeros(0, np.intp)
    t2 = time.perf_counter()
    codes = class_codes(model.classes)
    code_of = np.array([codes[c] for c in model.classes], dtype=np.uint8)
    cell_labels = node_labels[lat.node_of]
    labels = np.zeros(grid.shape, dtype=np.uint8)
    labels[lat.free[:, 0], lat.free[:, 1]] = code_of[cell_labels]
    proba = np.eye(len(model.classes), dtype=np.float32)[cell_labels]
    out = MapLabels(
        labels=labels,
        cells=lat.free,
        proba=proba,
        classes=model.classes,
        codes=codes,
        timings={"cast+features": t1 - t0, "map": t2 - t1, "total": time.perf_counter() - t0},
    )
    return out, lat, node_labels


def check_classes(model: IAMNModel, wanted: Mapping[str, int] | Sequence[str]) -> None:
    """Refuse to score a model on classes it was not trained on (names them)."""
    unknown = sorted(set(wanted) - set(model.classes) - {"none"})
    if unknown:
        raise ModelError(
            f"the model was trained on {list(model.classes)} but the labels hold {unknown}; "
            "merge or drop those classes, or train the model on them"
        )
