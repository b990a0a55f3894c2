"""The place models measured building-disjoint: the real Freiburg 079 log, leave one building out
on the labelled IPA maps, the bundled models on their own buildings, room segmentation.

Every model is trained by :mod:`agent.training.default_models` (the recipe of ``loci places
train-default``) with the building it is scored on left out (``--without``); models are kept in
``--models`` and reused.

1. ``fr079`` (``places_fr079.{md,json}``): the labelled Freiburg 079 log through the agent's
   pipeline, front laser only (:mod:`agent.training.labelled_log`), per scan and per node, without
   and with the HMM, for the previous bundled model (``--old-model``, given an HMM fitted on
   the same drives) and the new agent model trained without Freiburg 079; people detection
   off, and on for the new model.
2. ``lobo`` (``places_lobo.{md,json}``): for each of the five labelled IPA buildings, the map
   model trained without it labels every free cell of it (360° casts in the drawn map).
3. ``fit`` (in ``places_lobo.md``): the bundled map model on each of the five buildings it was
   trained on, and the bundled agent model on the Freiburg 079 log it was trained on.
4. ``segmentation`` (``places_segmentation.{md,json}``): room segmentation with the bundled
   map model on the 16 IPA maps, with and without furniture (the chain and scores of
   :mod:`tools.evaluate_topology`).

Run: ``make eval`` or ``python -m tools.evaluate_places --out docs/results`` (hours on a
shared 2-core machine, most of it training the held-out models).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from agent.datasets import data_dir
from agent.progress import Progress
from knowledge.fileio import atomic_write_text
from knowledge.learning.metrics import Scores, score
from knowledge.places.dataset import IPA_BUILDINGS, LabelledMap, load_ipa_building
from knowledge.places.labeling import MapLabels, label_map
from knowledge.places.model import PlaceModel, default_map_model_path, default_model_path

CLASSES3 = ("room", "corridor", "doorway")
CLASSES2 = ("room", "corridor")


def score_labels(
    lmap: LabelledMap, result: MapLabels, merge: dict[str, str] | None = None
) -> dict[str, Scores]:
    """3-class and 2-class scores of a whole-map labeling against the map's labels."""
    cells = result.cells
    truth_codes = lmap.labels[cells[:, 0], cells[:, 1]]
    keep = truth_codes > 0
    truth = np.array([lmap.names[int(c)] for c in truth_codes[keep]])
    pred = result.predicted()[keep]
    if merge:
        pred = np.array([merge.get(c, c) for c in pred])
    return {"3": score(truth, pred, CLASSES3), "2": score(truth, pred, CLASSES2)}


def _row(name: str, s: dict[str, Scores], seconds: float) -> dict[str, Any]:
    return {
        "building": name,
        "cells": s["3"].n,
        "accuracy3": s["3"].accuracy,
        "balanced3": s["3"].balanced_accuracy,
        "accuracy2": s["2"].accuracy,
        "balanced2": s["2"].balanced_accuracy,
        "confusion3": s["3"].confusion.tolist(),
        "recall3": dict(
            zip(CLASSES3, [None if np.isnan(v) else float(v) for v in s["3"].recall], strict=True)
        ),
        "label_seconds": seconds,
    }


def _table(rows: list[dict[str, Any]]) -> list[str]:
    out = [
        "| building | cells | 3-class acc. | 3-class bal. | room/corridor acc. | room/corridor bal. | room / corridor / doorway recall |",
        "| --- | ---: | ---: | ---: | ---: | ---: | --- |",
    ]
    for r in rows:
        rec = " / ".join("–" if r["recall3"][c] is None else f"{100 * r['recall3'][c]:.1f}" for c in CLASSES3)
        out.append(
            f"| {r['building']} | {r['cells']:,} | {100 * r['accuracy3']:.2f} % | {100 * r['balanced3']:.2f} % | "
            f"{100 * r['accuracy2']:.2f} % | {100 * r['balanced2']:.2f} % | {rec} |"
        )
    mean = {
        k: float(np.mean([r[k] for r in rows])) for k in ("accuracy3", "balanced3", "accuracy2", "balanced2")
    }
    out.append(
        f"| **mean** | | **{100 * mean['accuracy3']:.2f} %** | {100 * mean['balanced3']:.2f} % | "
        f"**{100 * mean['accuracy2']:.2f} %** | {100 * mean['balanced2']:.2f} % | |"
    )
    return out


class Models:
    """Held-out models: trained on demand by the default recipe, kept in ``folder`` and reused
    as they are (after changing the recipe or the training code, empty the folder)."""

    def __init__(self, data: Path, folder: Path, cache: Path | None, generated: int, progress: Any) -> None:
        self.data, self.folder, self.cache, self.generated, self.progress = (
            data,
            folder,
            cache,
            generated,
            progress,
        )

    def get(self, without: str, kind: str) -> PlaceModel:
        from agent.training.default_models import FILES, train_default

        out = self.folder / f"without_{without}"
        path = out / FILES[kind]
        if not path.is_file():
            print(f"training the {kind} model without {without} ...", file=sys.stderr, flush=True)
            train_default(
                self.data,
                out,
                without=[without],
                generated=self.generated,
                cache=self.cache,
                which=(kind,),
                progress=self.progress,
            )
        return PlaceModel.load(path)


# ---------------------------------------------------------------------------- 1. Freiburg 079


def _log_row(name: str, hmm: str, vote: str, r: dict[str, Any]) -> dict[str, Any]:
    return {"model": name, "hmm": hmm, "vote": vote, **r}


def part_fr079(models: Models, old_model: Path | None) -> dict[str, Any]:
    from agent.core.pipeline import PipelineParams, PlaceFilterParams
    from agent.training.default_models import FR079, training_set
    from agent.training.labelled_log import evaluate, load_fr079
    from knowledge.learning.hmm import PlaceHMM
    from knowledge.places.training import fit_trajectory_hmm

    log = load_fr079(models.data)
    new = models.get(FR079, "agent")
    candidates: list[tuple[str, PlaceModel]] = []
    if old_model is not None:
        old = PlaceModel.load(old_model)
        ts = training_set(models.data, without=[FR079], generated=models.generated, cache=models.cache)
        drives = ts.scans.subset(ts.scans.kinds == "drive")
        # its hallway class has no labelled drives (the IPA maps call halls corridor): the
        # histogram observation model needs no class means, eq. 5.4 would
        old_hmm = fit_trajectory_hmm(old, drives, ts.maps, hmm=PlaceHMM(observation="histogram"), seed=0)
        candidates.append(("previous bundled model", old_hmm))
    candidates.append(("new agent model, trained without Freiburg 079", new))
    rows = []
    for name, model in candidates:
        hmm_book = model.hmm
        settings: list[tuple[str, Any, str]] = [("none", None, "raw")]
        if hmm_book is not None and int(hmm_book.n_observations_.min()) > 0:
            settings.append(("eq. 5.4 (book)", replace_hmm(model, "kl"), "filtered"))
        if hmm_book is not None:
            settings.append(("histogram, γ = 0.5", replace_hmm(model, "histogram"), "filtered"))
        for hmm_name, m, vote in settings:
            use = model if m is None else m
            params = PipelineParams(places=PlaceFilterParams(hmm=m is not None, vote=vote))
            print(f"[fr079] {name}, HMM {hmm_name} ...", file=sys.stderr, flush=True)
            rows.append(_log_row(name, hmm_name, vote, evaluate(log, use, params=params)))
        if m is not None:
            params = PipelineParams(places=PlaceFilterParams(hmm=True, vote="raw"))
            rows.append(
                _log_row(name, f"{hmm_name}, raw labels vote", "raw", evaluate(log, m, params=params))
            )
    # people detection on, for the new model with the HMM it ships with
    params = PipelineParams(places=PlaceFilterParams(hmm=True, vote="filtered"))
    r = evaluate(log, new, people=True, params=params)
    rows.append(_log_row("new agent model, people detection and masking on", "as shipped", "filtered", r))
    return {"rows": rows, "scans": len(log)}


def replace_hmm(model: PlaceModel, observation: str) -> PlaceModel:
    """``model`` with its HMM's observation model set to ``observation`` (same fitted arrays)."""
    hmm = model.hmm
    meta, arrays = hmm.to_arrays()
    meta = {**meta, "params": {**meta["params"], "observation": observation}}
    from knowledge.learning.hmm import PlaceHMM

    return model.with_hmm(PlaceHMM.from_arrays(meta, arrays))


def fr079_markdown(res: dict[str, Any], command: str) -> list[str]:
    md = [
        "# Place classification on the real Freiburg 079 log, through the agent",
        "",
        f'Made by `{command}` (see docs/places.md, "Measured").',
        "",
        f"The {res['scans']:,} labelled front-laser scans of `logs/fr079_labels_provisional.npz` (180°, 360 beams, "
        "SLAM-corrected poses; 81.91 m = no echo) go through `agent.core.pipeline.Pipeline` as the agent runs: sparse local "
        "map, rear half simulated, 360° scan, model, HMM, navigation graph (`agent/training/labelled_log.py`). Per scan: "
        "the published label of every scan labelled room or corridor (a doorway answer counts as wrong), its "
        "balanced accuracy (mean of the room and corridor recalls), and the 3-class accuracy; per node: the final "
        "navigation graph's place nodes against the label picture at their positions. People detection is off "
        "except in the last row. No model here was trained on anything from Freiburg 079. Labels are provisional.",
        "",
        "| model | HMM | per scan room/corridor | balanced | room / corridor recall | 3-class | raw histogram's label | per node (nodes) |",
        "| --- | --- | ---: | ---: | --- | ---: | ---: | ---: |",
    ]
    for r in res["rows"]:
        s, raw, node = r["scan"], r["scan_raw"], r.get("node", {})
        md.append(
            f"| {r['model']} | {r['hmm']} | **{100 * s['rc_accuracy']:.2f} %** | {100 * s['rc_balanced']:.2f} % | "
            f"{100 * s['room_recall']:.1f} / {100 * s['corridor_recall']:.1f} | {100 * s['accuracy3']:.2f} % | "
            f"{100 * raw['rc_accuracy']:.2f} % | {100 * node.get('rc_accuracy', float('nan')):.2f} % ({node.get('n', 0)}) |"
        )
    md += [
        "",
        "The previous bundled model has hallway as a class; hallway answers count as corridor. Its HMM is fitted "
        "on the same simulated drives and moves as the new model's; those have no hallway labels, so eq. 5.4, "
        "which needs each class's mean histogram, has no row for it.",
        "",
    ]
    return md


# ---------------------------------------------------------------------------- 2, 3. IPA maps


def part_lobo(models: Models, only: list[str]) -> list[dict[str, Any]]:
    rows = []
    for b in only or list(IPA_BUILDINGS):
        model = models.get(b, "map")
        lmap = load_ipa_building(models.data, b)
        result = label_map(lmap.grid, model, progress=models.progress)
        row = _row(b, score_labels(lmap, result, {"hallway": "corridor"}), result.timings["total"])
        row["order"] = list(model.decision_list.order_)
        rows.append(row)
        print(
            f"[lobo {b}] room/corridor {100 * row['accuracy2']:.2f} %, 3-class {100 * row['accuracy3']:.2f} %",
            file=sys.stderr,
            flush=True,
        )
    return rows


def part_fit(data: Path, progress: Any) -> dict[str, Any]:
    from agent.core.pipeline import PipelineParams
    from agent.training.labelled_log import evaluate, load_fr079

    model = PlaceModel.load(default_map_model_path())
    rows = []
    for b in IPA_BUILDINGS:
        lmap = load_ipa_building(data, b)
        result = label_map(lmap.grid, model, progress=progress)
        rows.append(_row(b, score_labels(lmap, result, {"hallway": "corridor"}), result.timings["total"]))
    agent = PlaceModel.load(default_model_path())
    fr = evaluate(load_fr079(data), agent, params=PipelineParams())
    return {"map_model": rows, "agent_model_fr079": fr}


def lobo_markdown(rows: list[dict[str, Any]], fit: dict[str, Any] | None, command: str) -> list[str]:
    md = [
        "# Place classification on the labelled IPA maps",
        "",
        f'Made by `{command}` (see docs/places.md, "Measured"). Every free cell is labelled from its own 360° '
        "scan cast in the drawn map (360 beams, 30 m); 3-class accuracy over room/corridor/doorway cells, "
        "room/corridor accuracy over room and corridor cells (doorway cells ignored; a doorway answer there counts "
        "as wrong).",
        "",
    ]
    if rows:
        md += [
            "## Leave one building out: the map model trained without the building it labels",
            "",
            "Trained by the map model's recipe of `loci places train-default` (the other four IPA buildings: "
            "clean casts, randomised variants, drives; docs/places.md) with `--without BUILDING`.",
            "",
            *_table(rows),
            "",
            "Before this work (the book's protocol: clean casts in the other four buildings only, stride 4, T = 100): "
            "mean 3-class 85.12 %, room/corridor 86.25 % (Fr52 96.53, lab_d_furnitures 73.38, lab_intel 86.94, "
            "lab_ipa 82.01, office_e 92.36 % room/corridor).",
            "",
        ]
    if fit:
        md += [
            "## The bundled map model on the buildings it was trained on (does it fit?)",
            "",
            *_table(fit["map_model"]),
            "",
        ]
        s, node = fit["agent_model_fr079"]["scan"], fit["agent_model_fr079"].get("node", {})
        md += [
            "The bundled agent model (trained with the Freiburg 079 scans) on that log, as shipped (HMM on): "
            f"per scan room/corridor {100 * s['rc_accuracy']:.2f} % (balanced {100 * s['rc_balanced']:.2f} %), "
            f"per node {100 * node.get('rc_accuracy', float('nan')):.2f} % of {node.get('n', 0)} nodes.",
            "",
        ]
    return md


# ---------------------------------------------------------------------------- 4. segmentation


def part_segmentation(data: Path, out: Path, progress: Any) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    from tools.evaluate_topology import SEG_MAPS, run_segmentation, segmentation_summary

    model = PlaceModel.load(default_map_model_path())
    rows = run_segmentation(
        data,
        {"bundled map model": lambda name: ("default_map.npz", model)},
        SEG_MAPS,
        out,
        None,
        (),
        progress,
    )
    return rows, segmentation_summary(rows)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m tools.evaluate_places", description=(__doc__ or "").split("\n\n")[0]
    )
    ap.add_argument(
        "--data", type=Path, default=None, help="data folder (default $LOCI_DATA or ../shared/data)"
    )
    ap.add_argument("--out", type=Path, default=Path("docs/results"), help="folder for the tables")
    ap.add_argument(
        "--models",
        type=Path,
        default=Path("out/places-eval"),
        help="held-out models (trained when missing, else reused: empty it after changing the recipe)",
    )
    ap.add_argument(
        "--cache", type=Path, default=Path("/tmp/loci-places-cache"), help="simulated training scans, reused"
    )
    ap.add_argument(
        "--generated", type=int, default=None, help="generated buildings in training (default 10)"
    )
    ap.add_argument(
        "--old-model", type=Path, default=None, help="the previous bundled model, for the Freiburg 079 table"
    )
    ap.add_argument(
        "--part",
        action="append",
        choices=("fr079", "lobo", "fit", "segmentation"),
        default=[],
        help="what to measure (repeatable; default all)",
    )
    ap.add_argument("--only", action="append", default=[], help="leave-one-out: only these buildings")
    ap.add_argument("--quiet", action="store_true")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from agent.training.default_models import GENERATED

    data = args.data or data_dir()
    if not (data / "ipa" / "labeled").is_dir():
        print(f"no labelled maps under {data}/ipa/labeled: pass --data or set LOCI_DATA", file=sys.stderr)
        return 2
    parts = args.part or ["fr079", "lobo", "fit", "segmentation"]
    args.out.mkdir(parents=True, exist_ok=True)
    cmd = ("python -m tools.evaluate_places " + " ".join(argv if argv is not None else sys.argv[1:])).strip()
    t0 = time.perf_counter()
    with Progress(enabled=not args.quiet) as progress:
        models = Models(
            data, args.models, args.cache, GENERATED if args.generated is None else args.generated, progress
        )
        if "fr079" in parts:
            res = part_fr079(models, args.old_model)
            atomic_write_text(
                args.out / "places_fr079.json", json.dumps({"command": cmd, **res}, indent=2) + "\n"
            )
            atomic_write_text(args.out / "places_fr079.md", "\n".join(fr079_markdown(res, cmd)))
        lobo_rows: list[dict[str, Any]] = []
        fit = None
        if "lobo" in parts:
            lobo_rows = part_lobo(models, args.only)
        if "fit" in parts:
            fit = part_fit(data, progress)
        if lobo_rows or fit:
            doc = {"command": cmd, "leave_one_building_out": lobo_rows, "fit": fit}
            atomic_write_text(args.out / "places_lobo.json", json.dumps(doc, indent=2, default=float) + "\n")
            atomic_write_text(args.out / "places_lobo.md", "\n".join(lobo_markdown(lobo_rows, fit, cmd)))
        if "segmentation" in parts:
            from tools.evaluate_topology import segmentation_markdown

            rows, summary = part_segmentation(data, args.out, progress)
            atomic_write_text(
                args.out / "places_segmentation.json",
                json.dumps({"command": cmd, "summary": summary, "maps": rows}, indent=2) + "\n",
            )
            md = [
                "# Room segmentation with the bundled map model",
                "",
                f"Made by `{cmd}`. The chain and the scores of `tools/evaluate_topology.py` (relaxation, region "
                "correction, doorway cells grown into their neighbours; scored against `_gt_segmentation.png`) "
                "with `knowledge/places/models/default_map.npz` on the 16 IPA segmentation maps. The model was "
                "trained on the five labelled IPA buildings, which include five of these maps (Freiburg52_scan, "
                "lab_d_scan, lab_intel, lab_ipa, office_e), so on those five this checks the fit, not "
                "generalisation; it does not use the real Freiburg 079 scans (Freiburg79_scan's building). "
                "Building-disjoint segmentation: docs/results/topology_segmentation.md.",
                "",
                *segmentation_markdown(rows, summary),
            ]
            atomic_write_text(args.out / "places_segmentation.md", "\n".join(md))
    print(f"done in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
