"""`loci places train|evaluate|label` as a user types them (`loci places demo` is the old
whole-map labeling demo; `loci demo` is the guided tour: tests/e2e/test_demo_tour.py)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from support import cli

from knowledge import labels as lbl
from knowledge.metric.grid import OccupancyGrid
from sim.buildings import generate_building


def loci(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    return cli.loci("-q", *args, check=check)


@pytest.fixture(scope="module")
def model_file(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, object]]:
    out = tmp_path_factory.mktemp("model") / "m.npz"
    proc = loci(
        "places", "train", "--generated", "2", "--seed", "3", "--stride", "12", "--rounds", "8",
        "--beams", "90", "--merge", "hallway=corridor", "--out", str(out), "--json",
    )  # fmt: skip
    return out, json.loads(proc.stdout)


@pytest.mark.slow
def test_train_writes_a_model_and_reports_it(model_file: tuple[Path, dict[str, object]]) -> None:
    path, summary = model_file
    assert path.is_file()
    assert summary["classes"] == ["room", "corridor", "doorway"]
    assert len(summary["order_scores"]) == 6  # every order of three classes was tried
    assert summary["features_for_prediction"] <= summary["features_used"]


@pytest.mark.slow
def test_evaluate_prints_scores_and_every_order(model_file: tuple[Path, dict[str, object]]) -> None:
    path, _ = model_file
    proc = loci(
        "places", "evaluate", "--model", str(path), "--generated", "1", "--seed", "11",
        "--stride", "8", "--merge", "hallway=corridor", "--json",
    )  # fmt: skip
    result = json.loads(proc.stdout)
    assert 0.5 < result["accuracy"] <= 1.0
    assert 0.0 < result["balanced_accuracy"] <= 1.0
    assert result["two_class_accuracy"] is not None
    conf = np.array(result["confusion"])
    assert conf.shape == (3, 3) and conf.sum() == result["examples"]  # every truth class is scored
    # the readable form has the book's table of decision-list orders
    text = loci(
        "places", "evaluate", "--model", str(path), "--generated", "1", "--seed", "11", "--stride", "16"
    ).stdout
    assert "decision list" in text and "<- model" in text and "recall" in text
    # all six orders are listed by the book's names (the first two classifiers)
    names = (
        "room-corridor",
        "corridor-room",
        "room-doorway",
        "doorway-room",
        "corridor-doorway",
        "doorway-corridor",
    )
    assert all(n in text for n in names)


@pytest.mark.slow
def test_label_writes_codes_and_an_overlay(
    model_file: tuple[Path, dict[str, object]], tmp_path: Path
) -> None:
    path, _ = model_file
    b = generate_building(21, layout="straight", furniture=False)
    map_yaml = b.grid.save(tmp_path / "office.yaml")
    out = tmp_path / "labels.png"
    summary = json.loads(
        loci("places", "label", str(map_yaml), "--model", str(path), "--out", str(out), "--json").stdout
    )
    labels = lbl.read_label_image(out)
    assert labels.shape == b.grid.shape
    assert set(np.unique(labels[b.grid.free])) <= {1, 2, 3}
    assert (labels[~b.grid.free] == 0).all()
    assert Path(summary["overlay"]).is_file()
    assert sum(summary["cells_per_class"].values()) == int(b.grid.free.sum())
    # the labels load as a map_server map in raw mode: the codes, in the input map's place
    assert summary["labels_yaml"] == str(tmp_path / "labels.yaml")
    described = OccupancyGrid.from_yaml(tmp_path / "labels.yaml")
    assert described.resolution == b.grid.resolution and described.origin == b.grid.origin
    meta = yaml.safe_load((tmp_path / "labels.yaml").read_text())
    assert meta["mode"] == "raw" and meta["image"] == "labels.png"
    # the overlay has a legend strip under the map
    overlay = cv2.imread(summary["overlay"], cv2.IMREAD_COLOR)
    assert overlay.shape[0] > b.grid.shape[0]
    strip = overlay[b.grid.shape[0] :]
    for code in {int(c) for c in np.unique(labels)} - {0}:
        bgr = np.asarray(lbl.CLASS_COLORS_BGR[code], np.uint8)
        assert np.all(strip == bgr, axis=2).any(), f"no legend swatch for class {code}"


def test_label_refuses_to_replace_the_input_map_with_its_yaml(tmp_path: Path) -> None:
    b = generate_building(21, layout="straight", furniture=False)
    map_yaml = b.grid.save(tmp_path / "office.yaml")
    before = map_yaml.read_text()
    r = loci("places", "label", str(map_yaml), "--out", str(tmp_path / "office.png"), check=False)
    assert r.returncode != 0 and "would replace the input map" in r.stderr
    assert map_yaml.read_text() == before


@pytest.mark.slow
def test_errors_are_clear(tmp_path: Path) -> None:
    img = tmp_path / "m.png"
    generate_building(1).grid.save(tmp_path / "m.yaml")
    (tmp_path / "m.pgm").rename(img)
    proc = loci("places", "label", str(img), "--out", str(tmp_path / "l.png"), check=False)
    assert proc.returncode == 2
    assert "needs its resolution" in proc.stderr
    proc = loci("places", "evaluate", "--model", str(tmp_path / "nope.npz"), "--generated", "1", check=False)
    assert proc.returncode == 2 and "no such model file" in proc.stderr
    proc = loci("places", "train", "--out", str(tmp_path / "x.npz"), check=False)
    assert proc.returncode != 0 and "no maps given" in proc.stderr


@pytest.mark.slow
def test_evaluate_ignores_classes_the_model_lacks_consistently(
    model_file: tuple[Path, dict[str, object]],
) -> None:
    path, _ = model_file  # a 3-class model (halls merged into corridors at training)
    result = json.loads(
        loci(
            "places",
            "evaluate",
            "--model",
            str(path),
            "--generated",
            "1",
            "--seed",
            "1",
            "--stride",
            "8",
            "--json",
        ).stdout
    )
    if "hallway" not in result["ignored"]:
        pytest.skip("this generated building has no hall")
    assert np.array(result["confusion"]).sum() == result["examples"]
    model_row = next(r for r in result["orders"] if r["order"] == result["order"])
    assert model_row["accuracy"] == pytest.approx(result["accuracy"], abs=1e-6)


@pytest.mark.slow
def test_bad_option_values_are_errors_not_tracebacks(tmp_path: Path) -> None:
    for args in (
        ("places", "train", "--generated", "1", "--stride", "0", "--out", str(tmp_path / "a.npz")),
        ("places", "train", "--generated", "1", "--rounds", "0", "--out", str(tmp_path / "a.npz")),
        (
            "places",
            "train",
            "--generated",
            "1",
            "--classes",
            "room,kitchen",
            "--out",
            str(tmp_path / "a.npz"),
        ),
        ("places", "train", "--generated", "1", "--order", "room,corridor", "--out", str(tmp_path / "a.npz")),
    ):
        proc = loci(*args, check=False)
        assert proc.returncode == 2, (args, proc.stderr)
        assert "Traceback" not in proc.stderr and "loci: error:" in proc.stderr, proc.stderr
