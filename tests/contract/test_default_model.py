"""The bundled place model: it loads, and its documented command reproduces its format."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from knowledge.places.features import default_feature_names
from knowledge.places.model import FORMAT, PlaceModel, default_model_path

#: The command documented in docs/places.md that made knowledge/places/models/default.npz.
DOC_COMMAND = (
    "loci places train --generated 40 --seed 1000 --stride 8 --out knowledge/places/models/default.npz"
)


def _header(path: Path) -> dict[str, object]:
    with np.load(path, allow_pickle=False) as z:
        return dict(json.loads(z["header_json"].tobytes().decode()))


def test_bundled_model_loads_and_says_how_it_was_made() -> None:
    path = default_model_path()
    model = PlaceModel.load(path)
    assert model.classes == ("room", "corridor", "doorway", "hallway")
    assert model.scan.n_beams == 360 and model.scan.max_range == 30.0
    assert set(model.feature_names) <= set(default_feature_names())
    assert model.data.stride == 8 and len(model.data.maps) == 40
    assert all(m.startswith("building_") for m in model.data.maps)  # generated buildings only
    assert model.training["n_rounds"] == 100 and model.training["booster"] == "generalized"
    assert any(k.startswith("relaxation_") for k in model.extras)
    docs = (Path(__file__).resolve().parents[2] / "docs" / "places.md").read_text()
    assert DOC_COMMAND in docs


@pytest.mark.slow
def test_documented_command_reproduces_the_format(tmp_path: Path) -> None:
    # the same command, shrunk (2 buildings, 3 rounds) so that it runs in seconds
    out = tmp_path / "small.npz"
    args = DOC_COMMAND.split()[1:]
    args[args.index("--generated") + 1] = "2"
    args[args.index("--out") + 1] = str(out)
    proc = subprocess.run(
        [sys.executable, "-m", "agent.cli", "-q", *args, "--rounds", "3", "--stride", "16"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    bundled, fresh = _header(default_model_path()), _header(out)
    assert bundled["format"] == fresh["format"] == FORMAT
    assert set(bundled) == set(fresh)
    for key in ("scan", "decision_list", "extras", "training", "data"):
        assert set(bundled[key]) == set(fresh[key]), key  # type: ignore[arg-type]
    with np.load(default_model_path(), allow_pickle=False) as a, np.load(out, allow_pickle=False) as b:
        assert {k.split(".")[-1] for k in a.files} == {k.split(".")[-1] for k in b.files}
    PlaceModel.load(out)
