"""The bundled place models: they load, say how they were made, and their documented command
reproduces their format."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from knowledge.places.dataset import IPA_BUILDINGS
from knowledge.places.features import default_feature_names
from knowledge.places.model import FORMAT, PlaceModel, default_map_model_path, default_model_path

#: The command documented in docs/places.md that made knowledge/places/models/default*.npz.
DOC_COMMAND = "loci places train-default --cache /tmp/loci-places-cache"


def _header(path: Path) -> dict[str, object]:
    with np.load(path, allow_pickle=False) as z:
        return dict(json.loads(z["header_json"].tobytes().decode()))


@pytest.mark.parametrize("which", ["agent", "map"])
def test_bundled_models_load_and_say_how_they_were_made(which: str) -> None:
    path = default_model_path() if which == "agent" else default_map_model_path()
    assert path.stat().st_size < 3_000_000  # small enough to commit
    model = PlaceModel.load(path)
    assert model.classes == ("room", "corridor", "doorway")
    assert model.scan.n_beams == 360 and model.scan.max_range == 30.0
    assert set(model.feature_names) <= set(default_feature_names())
    maps = set(model.data.maps)
    # the agent's model also learns from 10 generated floors, the map model from the IPA maps only
    assert set(IPA_BUILDINGS) <= maps
    assert sum(m.startswith("building_") for m in maps) == (10 if which == "agent" else 0)
    assert model.training["n_rounds"] == 100 and model.training["booster"] == "generalized"
    assert any(k.startswith("relaxation_") for k in model.extras)
    notes = model.data.notes
    assert notes["model"] == which and notes["command"] == "loci places train-default"
    kinds = notes["examples_per_kind"]
    if which == "agent":
        # the agent's model: the robot's view (drives, randomised casts, the real log, a little
        # of the clean casts), an HMM
        assert "fr079" in maps and set(kinds) == {"grid", "grid+rand", "drive", "real"}
        assert notes["weights"]["grid"] < 0.5 <= notes["weights"]["drive"]
        hmm = model.hmm
        assert hmm is not None and hmm.get_params()["observation"] == "histogram"
        assert list(hmm.classes_) == list(model.classes)
    else:
        # the map model: 360° casts in the maps as drawn and in randomised variants, and drives
        assert set(kinds) == {"grid", "grid+rand", "drive"} and model.hmm is None
    docs = (Path(__file__).resolve().parents[2] / "docs" / "places.md").read_text()
    assert DOC_COMMAND in docs


@pytest.mark.data
@pytest.mark.slow
def test_documented_command_reproduces_the_format(tmp_path: Path, shared_data: Path) -> None:
    # the same command, shrunk so that it runs in a minute: the smallest IPA building, one
    # generated one, 3 rounds
    args = [*DOC_COMMAND.split()[1:]]
    args[args.index("--cache") + 1] = str(tmp_path / "cache")
    for b in (*IPA_BUILDINGS, "fr079"):
        if b != "lab_ipa":
            args += ["--without", b]
    args += ["--generated", "1", "--rounds", "3", "--out-dir", str(tmp_path), "--data", str(shared_data)]
    proc = subprocess.run(
        [sys.executable, "-m", "agent.cli", "-q", *args], capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr
    for bundled_path, name in (
        (default_model_path(), "default.npz"),
        (default_map_model_path(), "default_map.npz"),
    ):
        out = tmp_path / name
        bundled, fresh = _header(bundled_path), _header(out)
        assert bundled["format"] == fresh["format"] == FORMAT
        assert set(bundled) == set(fresh)
        for key in ("scan", "decision_list", "extras", "training", "data"):
            assert set(bundled[key]) == set(fresh[key]), key  # type: ignore[arg-type]
        with np.load(bundled_path, allow_pickle=False) as a, np.load(out, allow_pickle=False) as b:
            assert {k.split(".")[-1] for k in a.files} == {k.split(".")[-1] for k in b.files}
        PlaceModel.load(out)
    # the cache holds the two buildings' scans
    assert len(list((tmp_path / "cache").glob("*.npz"))) == 2
