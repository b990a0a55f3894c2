"""Place classification on the labelled real Freiburg 079 log, through the agent's pipeline.

Per-scan and per-node room/corridor scores of one or more place models
(:mod:`agent.training.labelled_log` says what is scored). The bundled agent model saw these
scans in training: score a model trained ``--without fr079`` for a building-disjoint number
(``docs/results/places_fr079.md``).

Run: ``python -m tools.places_log --model M.npz [--people] [--no-hmm] [--json]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from agent.commands.options import add_json_file_option, add_json_option, emit_result


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.places_log", description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--model", type=Path, action="append", default=[], help="place model(s) (default: bundled)"
    )
    ap.add_argument(
        "--data", type=Path, default=None, help="data folder (default $LOCI_DATA or ../shared/data)"
    )
    ap.add_argument("--people", action="store_true", help="people detection and masking on (default off)")
    ap.add_argument("--no-hmm", action="store_true", help="do not filter with the model's HMM")
    ap.add_argument(
        "--vote", choices=("filtered", "raw"), default="filtered", help="the label that votes for nodes"
    )
    add_json_option(ap)
    add_json_file_option(ap)
    return ap


def _text(results: dict[str, Any]) -> str:
    lines = []
    for path, r in results.items():
        s, raw = r["scan"], r["scan_raw"]
        node = r.get("node", {})
        lines.append(
            f"{path}: per scan room/corridor {100 * s['rc_accuracy']:.2f} % (balanced {100 * s['rc_balanced']:.2f} %, "
            f"room {100 * s['room_recall']:.1f} / corridor {100 * s['corridor_recall']:.1f}), 3-class "
            f"{100 * s['accuracy3']:.2f} %; raw {100 * raw['rc_accuracy']:.2f} % (bal. {100 * raw['rc_balanced']:.2f} %); "
            f"per node {100 * node.get('rc_accuracy', float('nan')):.2f} % of {node.get('n', 0)}; "
            f"{r['scans_masked']} scans masked; {r['seconds']:.1f} s"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    from agent.core.pipeline import PipelineParams, PlaceFilterParams
    from agent.datasets import data_dir
    from agent.training.labelled_log import evaluate, load_fr079
    from knowledge.places.model import PlaceModel, default_model_path

    args = build_parser().parse_args(argv)
    log = load_fr079(args.data or data_dir())
    params = PipelineParams(places=PlaceFilterParams(hmm=not args.no_hmm, vote=args.vote))
    results = {
        str(path): evaluate(log, PlaceModel.load(path), people=args.people, params=params)
        for path in args.model or [default_model_path()]
    }
    emit_result(args, results, _text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
