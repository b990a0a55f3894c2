"""The book's iAMN experiment (Sect. 4.8.3): Freiburg building 79 at a 0.2 m node grid, the left
half trained, the right half classified, against AdaBoost (+ relaxation) on the same nodes.

Map: ``DATA/ipa/segmentation/Freiburg79_scan.png`` (the drawn map of the building, 0.063 m per
pixel as measured against the real scans, docs/places.md) with the labels of
``DATA/logs/Freiburg79_labels_provisional.png`` (77 room, 115 corridor, 179 doorway; doorway
= 0.5 m either side of each door line, so *provisional*). The split is at the middle column of
the free cells' bounding box. Every method is scored on the same right-half nodes (one per
0.2 m block holding a labelled free cell, the class of the node's scan cell):

* iAMN: :func:`knowledge.places.iamn.train_iamn` (FDR → NN transform → AMN) and MAP;
* its parts: the learned node potentials alone (per-node argmax) and 1-NN on the selected
  features (argmin of eq. 4.10), no learning;
* AdaBoost: the decision list (``train_place_model``, T = 100, stride 3 cells ≈ the node
  spacing) on the left half's cells, applied to the nodes; then Sect. 4.5's relaxation (50
  iterations, compatibilities from the left half's node labels) on the 0.2 m node grid.

Run: ``python -m tools.iamn_experiment --out /tmp/iamn [--rounds 100]`` (about 15 s on
one core); writes ``iamn_fr079.json``, the iAMN model ``iamn_fr079.npz`` (for ``loci places
label --method iamn``) and a picture of truth / AdaBoost / iAMN on the right half.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from agent.datasets import data_dir
from knowledge import labels as lbl
from knowledge.places.dataset import IPA_BUILDINGS, LabelledMap, load_ipa_building, load_labelled_map
from knowledge.places.iamn import (
    IAMNConfig,
    check_classes,
    label_map_iamn,
    lattice,
    node_features,
    node_truth,
    train_iamn,
)

RESOLUTION = 0.063


def load_fr79(data: Path) -> LabelledMap:
    return load_labelled_map(
        data / "ipa" / "segmentation" / "Freiburg79_scan.png",
        data / "logs" / "Freiburg79_labels_provisional.png",
        resolution=RESOLUTION,
        codes="ipa",
        name="Freiburg79",
    )


def _acc(pred: np.ndarray, truth: np.ndarray) -> float:
    return float(np.mean(pred == truth))


def _per_class(pred: np.ndarray, truth: np.ndarray, classes: tuple[str, ...]) -> dict[str, float]:
    return {c: float(np.mean(pred[truth == k] == k)) for k, c in enumerate(classes) if np.any(truth == k)}


def compare(
    train: list[tuple[LabelledMap, np.ndarray | None]],
    test: LabelledMap,
    test_mask: np.ndarray | None,
    *,
    n_features: int,
    rounds: int,
    relax_iterations: int = 50,
    model_path: Path | None = None,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Train every method on ``train`` (maps with an optional mask of the cells to learn from),
    score all of them on the same nodes of ``test`` (inside ``test_mask``).

    Returns the report and what :func:`_picture` draws.
    """
    from knowledge.places.labeling import label_map
    from knowledge.places.relaxation import CompatibilityStats, relax
    from knowledge.places.training import TrainingConfig, train_place_model

    report: dict[str, Any] = {"train": [m.name for m, _ in train], "test": test.name}
    config = IAMNConfig(n_features=n_features)

    # ---- iAMN
    t0 = time.perf_counter()
    if len(train) == 1:
        model, train_t = train_iamn(train[0][0], config, mask=train[0][1])
    else:
        model, train_t = train_iamn([m for m, _ in train], config)
    t_train = time.perf_counter() - t0
    check_classes(model, test.class_counts())
    if model_path is not None:
        model.save(model_path)
    t0 = time.perf_counter()
    result, lat, nodes = label_map_iamn(test.grid, model, mask=test_mask)
    t_label = time.perf_counter() - t0
    cell_truth = test.labels[result.cells[:, 0], result.cells[:, 1]]
    cell_pred = result.labels[result.cells[:, 0], result.cells[:, 1]]
    labelled = cell_truth > 0
    truth = node_truth(test, lat, model.classes)
    k = truth >= 0
    X = node_features(test.grid, lat.cells, model.feature_names, model.scan)
    T = model.nn.transform(X)
    per_node = np.argmax(model.node_scores(X), axis=1)
    nn1 = np.argmin(T, axis=1)
    classes = model.classes
    report["nodes"] = {"train": int(sum(model.data.examples_per_class.values())), "test": int(k.sum())}
    report["iamn"] = {
        "accuracy": _acc(nodes[k], truth[k]),
        "per_class": _per_class(nodes[k], truth[k], classes),
        "features": list(model.feature_names),
        "fdr": [round(float(v), 4) for v in model.fdr],
        "w_node": model.amn.w_node_.round(4).tolist(),
        "w_edge": model.amn.w_edge_.round(4).tolist(),
        "train_s": round(t_train, 2),
        "train_timings_s": {a: round(b, 2) for a, b in train_t.items()},
        "label_s": round(t_label, 2),
        "free_cell_accuracy": _acc(cell_pred[labelled], cell_truth[labelled]),
    }
    report["node_potentials_only"] = {
        "accuracy": _acc(per_node[k], truth[k]),
        "per_class": _per_class(per_node[k], truth[k], classes),
    }
    report["nn1"] = {"accuracy": _acc(nn1[k], truth[k]), "per_class": _per_class(nn1[k], truth[k], classes)}

    # ---- AdaBoost (+ relaxation) on the same nodes
    ada_maps = [
        m if mask is None else LabelledMap(m.grid, np.where(mask, m.labels, 0).astype(np.uint8), m.names)
        for m, mask in train
    ]
    t0 = time.perf_counter()
    ada, _ = train_place_model(
        ada_maps, TrainingConfig(stride=lat.step, rounds=rounds, classes=tuple(classes), order="best")
    )
    t_ada_train = time.perf_counter() - t0
    t0 = time.perf_counter()
    ada_labels = label_map(test.grid, ada, cells=lat.cells)
    t_ada_label = time.perf_counter() - t0
    order = [ada.classes.index(c) for c in classes]
    proba = ada_labels.proba[:, order]
    ada_pred = np.argmax(proba, axis=1)
    report["adaboost"] = {
        "accuracy": _acc(ada_pred[k], truth[k]),
        "per_class": _per_class(ada_pred[k], truth[k], classes),
        "order": list(ada.decision_list.order_),
        "rounds": rounds,
        "train_s": round(t_ada_train, 2),
        "label_s": round(t_ada_label, 2),
    }
    # relaxation on the 0.2 m node grid: compatibilities from the training maps' node labels
    codes = [lbl.CLASS_CODES[c] for c in classes]
    samples = []
    for m, mask in train:
        tl = lattice(m.grid, config.spacing, mask)
        tt = node_truth(m, tl, classes)
        img = np.zeros(tuple(int(v) + 1 for v in tl.blocks.max(axis=0)), np.int64)
        sel = tt >= 0
        img[tl.blocks[sel, 0], tl.blocks[sel, 1]] = np.array(codes)[tt[sel]]
        occupied = np.ones(img.shape, bool)
        occupied[tl.blocks[:, 0], tl.blocks[:, 1]] = False
        samples.append((img, occupied))
    stats = CompatibilityStats.from_label_images(samples, codes)
    shape = tuple(int(v) + 1 for v in lat.blocks.max(axis=0))
    free = np.zeros(shape, bool)
    free[lat.blocks[:, 0], lat.blocks[:, 1]] = True
    P0 = np.zeros((*shape, len(classes)), np.float32)
    P0[lat.blocks[:, 0], lat.blocks[:, 1]] = proba
    t0 = time.perf_counter()
    relaxed = relax(P0, stats, free_mask=free, iterations=relax_iterations)
    t_relax = time.perf_counter() - t0
    rel_pred = np.argmax(relaxed[lat.blocks[:, 0], lat.blocks[:, 1], : len(classes)], axis=1)
    report["adaboost_relaxation"] = {
        "accuracy": _acc(rel_pred[k], truth[k]),
        "per_class": _per_class(rel_pred[k], truth[k], classes),
        "iterations": relax_iterations,
        "relax_s": round(t_relax, 3),
    }
    return report, {"lat": lat, "truth": truth, "ada": ada_pred, "iamn": nodes, "classes": classes}


def run(data: Path, out: Path, *, n_features: int, rounds: int) -> dict[str, Any]:
    """The book's experiment: building 79, left half trained, right half classified."""
    lmap = load_fr79(data)
    cols = np.flatnonzero(lmap.grid.free.any(axis=0))
    split = (int(cols.min()) + int(cols.max()) + 1) // 2
    left = np.zeros(lmap.grid.shape, bool)
    left[:, :split] = True
    report, drawn = compare(
        [(lmap, left)], lmap, ~left, n_features=n_features, rounds=rounds, model_path=out / "iamn_fr079.npz"
    )
    report.update({"map": lmap.name, "resolution_m": RESOLUTION, "split_column": split})
    _picture(out / "iamn_fr079.png", lmap, **drawn)
    (out / "iamn_fr079.json").write_text(json.dumps(report, indent=1) + "\n")
    return report


def run_lobo(data: Path, out: Path, building: str, *, n_features: int, rounds: int) -> dict[str, Any]:
    """Leave one labelled IPA building out: the other four trained, every node of it classified."""
    maps = {b: load_ipa_building(data, b) for b in IPA_BUILDINGS}
    if building not in maps:
        raise SystemExit(f"unknown IPA building {building!r}; choose from {', '.join(IPA_BUILDINGS)}")
    test = maps.pop(building)
    report, _ = compare([(m, None) for m in maps.values()], test, None, n_features=n_features, rounds=rounds)
    (out / f"iamn_lobo_{building}.json").write_text(json.dumps(report, indent=1) + "\n")
    return report


def _picture(
    path: Path,
    lmap: LabelledMap,
    *,
    lat: Any,
    truth: np.ndarray,
    ada: np.ndarray,
    iamn: np.ndarray,
    classes: tuple[str, ...],
) -> None:
    from knowledge.fileio import write_image

    codes = np.array([lbl.CLASS_CODES[c] for c in classes], np.uint8)
    base = lmap.grid.to_image()
    panels = []
    for labels in (np.where(truth >= 0, truth, 0), ada, iamn):
        img = np.zeros(lmap.grid.shape, np.uint8)
        vals = codes[labels[lat.node_of]]
        if labels is not ada and labels is not iamn:
            vals = np.where(truth[lat.node_of] >= 0, vals, 0)
        img[lat.free[:, 0], lat.free[:, 1]] = vals
        (r0, c0), (r1, c1) = lat.free.min(axis=0), lat.free.max(axis=0)
        panels.append(lbl.overlay(base, img)[max(r0 - 4, 0) : r1 + 5, max(c0 - 4, 0) : c1 + 5])
    write_image(path, np.vstack(panels))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m tools.iamn_experiment", description=__doc__.splitlines()[0] if __doc__ else None
    )
    p.add_argument("--data", type=Path, default=None, help="the data folder (default: ../shared/data)")
    p.add_argument("--out", type=Path, required=True, help="folder for the JSON, the model and the picture")
    p.add_argument("--features", type=int, default=30, help="FDR-selected features (30, as the book)")
    p.add_argument("--rounds", type=int, default=100, help="AdaBoost rounds per classifier (100)")
    p.add_argument(
        "--lobo",
        metavar="BUILDING",
        default=None,
        help="instead: leave this IPA building out (trained on the other four, all its nodes classified)",
    )
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    data = args.data or data_dir()
    if args.lobo:
        report = run_lobo(data, args.out, args.lobo, n_features=args.features, rounds=args.rounds)
    else:
        report = run(data, args.out, n_features=args.features, rounds=args.rounds)
    for key in ("iamn", "node_potentials_only", "nn1", "adaboost", "adaboost_relaxation"):
        r = report[key]
        per = ", ".join(f"{c} {v:.3f}" for c, v in r["per_class"].items())
        print(f"{key:<22} {r['accuracy']:.4f}  ({per})")
    print(
        json.dumps(report["nodes"]), "iamn free-cell accuracy", round(report["iamn"]["free_cell_accuracy"], 4)
    )
    print("iamn times", report["iamn"]["train_timings_s"], "label", report["iamn"]["label_s"])
    print("adaboost times", report["adaboost"]["train_s"], report["adaboost"]["label_s"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
