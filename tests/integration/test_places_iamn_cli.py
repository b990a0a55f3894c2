"""`loci places label --method iamn` as a user types it: the same outputs as the AdaBoost
labeling, and clear errors for an AdaBoost model, no model and a map with no free cells."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
from support import cli
from support.drawn_office import drawn_office

from knowledge import labels as lbl
from knowledge.places.iamn import IAMNConfig, train_iamn


def loci(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    return cli.loci("-q", *args, check=check)


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("iamn")
    office = drawn_office()
    model, _ = train_iamn(office, IAMNConfig(n_features=10, epochs=40))
    model_path = model.save(d / "iamn.npz")
    map_png = d / "office.png"
    cv2.imwrite(str(map_png), office.grid.to_image())
    return map_png, model_path


def test_label_with_iamn_writes_codes_yaml_and_overlay(tmp_path: Path, files: tuple[Path, Path]) -> None:
    map_png, model_path = files
    out = tmp_path / "labels.png"
    summary = json.loads(
        loci(
            "places", "label", str(map_png), "--resolution", "0.1", "--method", "iamn",
            "--model", str(model_path), "--out", str(out), "--json",
        ).stdout
    )  # fmt: skip
    office = drawn_office()
    labels = lbl.read_label_image(out)
    assert labels.shape == office.grid.shape
    assert (labels[~office.grid.free] == 0).all()
    assert set(np.unique(labels[office.grid.free]).tolist()) <= {1, 2, 3}
    assert summary["method"] == "iamn" and summary["cells"] == int(office.grid.free.sum())
    assert Path(summary["overlay"]).is_file() and Path(summary["labels_yaml"]).is_file()
    truth = office.labels[office.grid.free]
    got = labels[office.grid.free]
    rc = np.isin(truth, (lbl.ROOM, lbl.CORRIDOR))
    assert np.mean(got[rc] == truth[rc]) > 0.9


def test_label_with_iamn_refuses_bad_input(tmp_path: Path, files: tuple[Path, Path]) -> None:
    map_png, model_path = files
    out = tmp_path / "l.png"
    r = loci(
        "places",
        "label",
        str(map_png),
        "--resolution",
        "0.1",
        "--method",
        "iamn",
        "--out",
        str(out),
        check=False,
    )
    assert r.returncode != 0 and "needs --model" in r.stderr
    from knowledge.places.model import default_map_model_path

    r = loci(
        "places", "label", str(map_png), "--resolution", "0.1", "--method", "iamn",
        "--model", str(default_map_model_path()), "--out", str(out), check=False,
    )  # fmt: skip
    assert r.returncode != 0 and "AdaBoost place model" in r.stderr
    walls = tmp_path / "walls.png"
    cv2.imwrite(str(walls), np.zeros((30, 30), np.uint8))
    r = loci(
        "places", "label", str(walls), "--resolution", "0.1", "--method", "iamn",
        "--model", str(model_path), "--out", str(out), check=False,
    )  # fmt: skip
    assert r.returncode != 0 and "no free cells" in r.stderr
    assert not out.exists(), "nothing is written when labeling fails"


def test_adaboost_labeling_refuses_a_map_without_free_cells(tmp_path: Path) -> None:
    walls = tmp_path / "walls.png"
    cv2.imwrite(str(walls), np.zeros((30, 30), np.uint8))
    out = tmp_path / "l.png"
    r = loci("places", "label", str(walls), "--resolution", "0.1", "--out", str(out), check=False)
    assert r.returncode != 0 and "no free cells" in r.stderr
    assert not out.exists()
