"""Place classification on the labelled real Freiburg 079 log, through the agent's pipeline.

The 4,791 front-laser scans of
``logs/fr079_labels_provisional.npz`` (360 beams over 180°, beam i at −90° + i·0.5°,
SLAM-corrected poses) are fed as :class:`~drivers.messages.LaserScan` +
:class:`~drivers.messages.Pose2D` through :class:`agent.core.pipeline.Pipeline`, front laser only,
as the agent runs: sparse local map, rear beams simulated, 360° scan, model, navigation graph.
The real LMS writes 81.91 m for "no echo": it is the scans' ``range_max`` here, so those beams
are no-returns.

Scores (``../shared/data/README.md`` describes the labels; they are provisional, doorways coarse):

* per scan: room/corridor accuracy over scans labelled room or corridor (a doorway prediction
  counts as wrong), its balanced accuracy (mean of the two recalls), 3-class accuracy;
  for the label the pipeline publishes (``label``) and, when the pipeline filters, the raw one;
* per node: every place node of the final navigation graph with a label, against the label
  image at the node's position (through the log → map transform); nodes standing on a
  doorway band take the nearest room or corridor pixel's class, since place nodes are
  room/corridor.

Run: ``python -m tools.places_log --model M.npz [--people] [--json]``; the bundled agent
model is trained on these scans too (:mod:`agent.training.default_models`).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from knowledge.learning.metrics import score

CLASSES3 = ("room", "corridor", "doorway")
CLASSES2 = ("room", "corridor")
#: Grey values of the log's labels → class names (115 is the corridor, "hallway" in the file's legend).
LOG_CODES = {77: "room", 115: "corridor", 179: "doorway"}
#: What the real LMS writes when a beam has no echo.
NO_ECHO = 81.91
#: Model classes scored as another (a model with halls: halls count as corridor).
MERGE = {"hallway": "corridor"}


@dataclass(frozen=True, eq=False)
class LabelledLog:
    """The labelled scans of a real log.

    Attributes:
        stamps: ``(S,)`` seconds.
        poses: ``(S, 3)`` corrected laser poses ``(x [m], y [m], θ [rad])``.
        ranges: ``(S, B)`` float32 metres (``NO_ECHO`` = no echo).
        angle_min, angle_increment: radians of beam 0 and between beams.
        truth: ``(S,)`` class names.
        label_image: ``(rows, cols)`` uint8 grey values of the label picture (0 none).
        align: the log → picture similarity transform (README of the data).
    """

    stamps: np.ndarray
    poses: np.ndarray
    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    truth: np.ndarray
    label_image: np.ndarray
    align: dict[str, Any]

    def __len__(self) -> int:
        return int(self.stamps.shape[0])

    def to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """``(k, 2)`` float (column, row) in the label picture of log-frame points ``(k, 2)``."""
        a = self.align
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        x, y = p[:, 0], float(a["mirror"]) * p[:, 1]
        th, s = math.radians(float(a["rot_deg"])), float(a["m_per_px"])
        X = (math.cos(th) * x - math.sin(th) * y) / s
        Y = (math.sin(th) * x + math.cos(th) * y) / s
        return np.column_stack((X + float(a["tx_px"]), -Y + float(a["ty_px"])))


def map_poses(log: LabelledLog, rows: int) -> np.ndarray:
    """``(S, 3)`` the log's poses in the world frame of the aligned map (an
    :class:`~knowledge.metric.grid.OccupancyGrid` of ``rows`` rows at ``m_per_px`` metres per
    cell, origin at its lower-left corner): the similarity transform of the data's README."""
    a = log.align
    th, s = math.radians(float(a["rot_deg"])), float(a["m_per_px"])
    x, y, h = log.poses[:, 0], float(a["mirror"]) * log.poses[:, 1], log.poses[:, 2]
    mx = math.cos(th) * x - math.sin(th) * y + s * float(a["tx_px"])
    my = math.sin(th) * x + math.cos(th) * y + s * (rows - float(a["ty_px"]))
    heading = float(a["mirror"]) * h + th
    return np.column_stack((mx, my, np.arctan2(np.sin(heading), np.cos(heading))))


def load_fr079(data: Path) -> LabelledLog:
    """``logs/fr079_labels_provisional.npz`` and its label picture."""
    import cv2

    path = data / "logs" / "fr079_labels_provisional.npz"
    with np.load(path, allow_pickle=False) as z:
        align = json.loads(str(z["align"]))
        truth = np.array([LOG_CODES[int(v)] for v in z["label"]])
        log = LabelledLog(
            stamps=np.asarray(z["t"], dtype=np.float64),
            poses=np.asarray(z["pose"], dtype=np.float64),
            ranges=np.asarray(z["ranges"], dtype=np.float32),
            angle_min=float(z["angle_min"]),
            angle_increment=float(z["angle_inc"]),
            truth=truth,
            label_image=np.zeros((1, 1), np.uint8),
            align=align,
        )
    img = cv2.imread(str(data / "logs" / "Freiburg79_labels_provisional.png"), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise FileNotFoundError(f"{data}/logs/Freiburg79_labels_provisional.png is missing or unreadable")
    return replace(log, label_image=img)


def real_scans(log: LabelledLog, *, n_beams: int = 360, max_range: float = 30.0, name: str = "fr079") -> Any:
    """The log's scans as the agent assembles them (front laser, sparse local map, rear beams;
    people off), labelled: a :class:`~knowledge.places.dataset.ScanSet` of kind "real"."""
    from knowledge.metric.rear_beams import FullScanParams
    from knowledge.places.dataset import ScanSet
    from knowledge.places.drives import assemble_along

    angles = log.angle_min + np.arange(log.ranges.shape[1]) * log.angle_increment
    ranges, _ = assemble_along(
        log.ranges,
        angles,
        log.poses,
        range_max=NO_ECHO,
        stamps=log.stamps,
        out=FullScanParams(n_beams=n_beams, max_range=max_range),
    )
    cells = np.round(log.to_pixels(log.poses[:, :2])[:, ::-1]).astype(np.int64)
    return ScanSet(
        ranges,
        log.truth.astype(str),
        np.zeros(len(log), dtype=np.int32),
        cells,
        (name,),
        np.full(len(log), "real", dtype="<U16"),
    )


def node_truth(log: LabelledLog, xy: np.ndarray) -> np.ndarray:
    """``(k,)`` room/corridor truth of place-node positions ``(k, 2)`` (log frame): the label
    picture's class there, or of the nearest room/corridor pixel when it is a doorway or none."""
    img = log.label_image
    rc = np.argwhere((img == 77) | (img == 115))
    px = log.to_pixels(xy)
    out = []
    for col, row in px:
        r, c = round(row), round(col)
        v = int(img[r, c]) if 0 <= r < img.shape[0] and 0 <= c < img.shape[1] else 0
        if v not in (77, 115):
            j = int(np.argmin((rc[:, 0] - row) ** 2 + (rc[:, 1] - col) ** 2))
            v = int(img[rc[j, 0], rc[j, 1]])
        out.append(LOG_CODES[v])
    return np.array(out)


def run_pipeline(
    log: LabelledLog,
    model: Any,
    *,
    people: bool = False,
    params: Any = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> dict[str, Any]:
    """Feed every scan of ``log`` through a fresh :class:`agent.core.pipeline.Pipeline`.

    Returns ``labels`` (what the pipeline publishes), ``raw_labels`` (the model's argmax),
    ``proba`` ``(S, K)``, ``coverage`` ``(S,)``, ``ranges360`` ``(S, n)``, the final place
    nodes ``nodes_xy`` ``(k, 2)`` and ``nodes_label`` ``(k,)``, and ``seconds``.
    """
    from agent.core.pipeline import PeopleParams, Pipeline, PipelineParams
    from drivers.messages import LaserScan, Pose2D

    prm = params if params is not None else PipelineParams()
    prm = replace(prm, people=replace(prm.people, enabled=people) if people else PeopleParams(enabled=False))
    pipe = Pipeline(model, prm)
    n = len(log)
    labels, raw_labels = [], []
    proba = np.zeros((n, len(model.classes)), np.float32)
    coverage = np.zeros(n, np.float32)
    ranges360 = np.zeros((n, model.scan.n_beams), np.float32)
    masked = 0
    t0 = time.perf_counter()
    for i in range(n):
        scan = LaserScan(
            float(log.stamps[i]),
            i,
            "laser",
            log.angle_min,
            log.angle_increment,
            NO_ECHO,
            log.ranges[i],
        )
        x, y, th = log.poses[i]
        res = pipe.process(scan, Pose2D(float(x), float(y), float(th), stamp=float(log.stamps[i])))
        labels.append(res.label)
        raw = getattr(res, "raw_probabilities", None) or res.probabilities
        p = np.array([raw[c] for c in model.classes])
        proba[i] = p
        raw_labels.append(model.classes[int(np.argmax(p))])
        coverage[i] = res.coverage
        ranges360[i] = res.ranges
        masked += res.masked is not None
        if progress is not None and (i % 200 == 0 or i == n - 1):
            progress("log", i + 1, n)
    seconds = time.perf_counter() - t0
    nodes = [nd for nd in pipe.graph.place_nodes() if nd.label is not None]
    return {
        "labels": np.array(labels),
        "raw_labels": np.array(raw_labels),
        "proba": proba,
        "coverage": coverage,
        "ranges360": ranges360,
        "nodes_xy": np.array([nd.xy for nd in nodes]).reshape(-1, 2),
        "nodes_label": np.array([nd.label for nd in nodes]),
        "scans_masked": masked,
        "seconds": seconds,
    }


def merged(labels: np.ndarray) -> np.ndarray:
    return np.array([MERGE.get(str(c), str(c)) for c in labels])


def scan_scores(truth: np.ndarray, pred: np.ndarray) -> dict[str, float]:
    """Room/corridor accuracy and balanced accuracy, 3-class accuracy of per-scan labels."""
    p = merged(pred)
    s2, s3 = score(truth, p, CLASSES2), score(truth, p, CLASSES3)
    return {
        "rc_accuracy": s2.accuracy,
        "rc_balanced": s2.balanced_accuracy,
        "room_recall": float(s2.recall[0]),
        "corridor_recall": float(s2.recall[1]),
        "accuracy3": s3.accuracy,
        "n": s2.n,
    }


def evaluate(log: LabelledLog, model: Any, *, people: bool = False, params: Any = None) -> dict[str, Any]:
    """Per-scan and per-node scores of one run (see the module doc)."""
    run = run_pipeline(log, model, people=people, params=params)
    out: dict[str, Any] = {
        "scan": scan_scores(log.truth, run["labels"]),
        "scan_raw": scan_scores(log.truth, run["raw_labels"]),
        "scans_masked": run["scans_masked"],
        "seconds": run["seconds"],
    }
    if len(run["nodes_label"]):
        nt = node_truth(log, run["nodes_xy"])
        s = score(nt, merged(run["nodes_label"]), CLASSES2)
        out["node"] = {"rc_accuracy": s.accuracy, "rc_balanced": s.balanced_accuracy, "n": s.n}
    return out
