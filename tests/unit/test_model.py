"""Place models on disk: one versioned .npz with a JSON header, loaded without pickle."""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from knowledge.errors import ModelError
from knowledge.learning.boosting import GeneralizedAdaBoost
from knowledge.learning.decision_list import DecisionList
from knowledge.places.model import FORMAT, DataSummary, PlaceModel, ScanParams

features = pytest.importorskip(
    "knowledge.places.features", reason="the scan features (knowledge.places.features) are not there yet"
)
synthetic = pytest.importorskip("knowledge.places.features.synthetic", reason="no synthetic scans yet")

MAX_RANGE = 30.0
BEAMS = 360


@pytest.fixture(scope="module")
def trained() -> dict[str, Any]:
    rng = np.random.default_rng(21)
    ranges, kind = synthetic.random_scans(360, rng=rng, num_beams=BEAMS, max_range=MAX_RANGE)
    names = features.default_feature_names()
    X = features.FeatureExtractor(names, max_range=MAX_RANGE)(ranges)
    y = np.asarray(synthetic.KINDS)[kind]
    dl = DecisionList(partial(GeneralizedAdaBoost, n_rounds=8)).fit(X, y)
    counts = {str(c): int((y == c).sum()) for c in np.unique(y)}
    model = PlaceModel.from_decision_list(
        dl,
        names,
        scan=ScanParams(n_beams=BEAMS, max_range=MAX_RANGE),
        data=DataSummary(maps=("synthetic",), examples_per_class=counts, stride=3),
        extras={"compatibility": np.arange(16.0).reshape(4, 4)},
        extras_meta={"relaxation": {"iterations": 50}},
    )
    return {"ranges": ranges, "X": X, "names": names, "dl": dl, "model": model}


def test_model_keeps_only_the_used_features(trained: dict[str, Any]) -> None:
    model, dl, X, names = trained["model"], trained["dl"], trained["X"], trained["names"]
    used = dl.all_used_features()
    assert model.feature_names == tuple(names[i] for i in used)
    assert len(model.feature_names) < len(names)
    np.testing.assert_array_equal(model.predict_proba_features(X[:, used]), dl.predict_proba(X))
    # prediction computes only the consulted boosters' columns
    consulted = {names[i] for i in dl.used_features()}
    assert set(model.extractor().names) == consulted
    assert set(model.extractor(all_features=True).names) == set(model.feature_names)
    assert model.training["n_rounds"] == 8 and model.training["order"] == "best"
    assert model.training["booster"] == "generalized"


def test_predict_from_scans_computes_the_same_features(trained: dict[str, Any]) -> None:
    model, dl, X, ranges = trained["model"], trained["dl"], trained["X"], trained["ranges"]
    P = model.predict_proba_scans(ranges[:50])
    np.testing.assert_allclose(P, dl.predict_proba(X[:50]), atol=1e-9)
    assert (model.predict_scans(ranges[:50]) == dl.predict(X[:50])).all()
    assert model.predict_proba_scans(ranges[0]).shape == (1, len(model.classes))
    with pytest.raises(ValueError, match="360 beams"):
        model.predict_proba_scans(ranges[:2, :180])


def test_round_trip(trained: dict[str, Any], tmp_path: Path) -> None:
    model, ranges = trained["model"], trained["ranges"]
    path = model.save(tmp_path / "places.npz")
    assert [p.name for p in tmp_path.iterdir()] == ["places.npz"]  # no temp file left
    loaded = PlaceModel.load(path)
    np.testing.assert_array_equal(loaded.predict_proba_scans(ranges), model.predict_proba_scans(ranges))
    assert loaded.feature_names == model.feature_names
    assert loaded.classes == model.classes
    assert loaded.decision_list.order_ == model.decision_list.order_
    # every class's booster is saved, so other orders can be scored on test data
    X = loaded.features(ranges, all_features=True)
    table = loaded.decision_list.order_accuracies(X, trained["dl"].predict(trained["X"]))
    assert len(table) == 6 and table[0][1] == 1.0
    assert loaded.decision_list.order_scores_ == model.decision_list.order_scores_
    assert loaded.scan == model.scan
    assert loaded.training == model.training
    assert loaded.data == model.data
    assert loaded.data.version and loaded.data.date and loaded.data.stride == 3
    np.testing.assert_array_equal(loaded.extras["compatibility"], model.extras["compatibility"])
    assert loaded.extras_meta == {"relaxation": {"iterations": 50}}
    with np.load(path, allow_pickle=False) as npz:
        header = json.loads(npz["header_json"].tobytes())
    assert header["format"] == FORMAT
    for key in ("feature_names", "scan", "decision_list", "training", "data", "extras"):
        assert key in header
    assert header["decision_list"]["order_name"] == "-".join(model.decision_list.order_[:-1])


# -- broken files -----------------------------------------------------------------------


def rewrite(src: Path, dst: Path, edit_header: Any = None, edit_arrays: Any = None) -> Path:
    """Copy a model file with its header and/or arrays edited."""
    with np.load(src, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = json.loads(arrays.pop("header_json").tobytes())
    if edit_header:
        edit_header(header)
    if edit_arrays:
        edit_arrays(arrays)
    arrays["header_json"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    np.savez_compressed(dst, **arrays)
    return dst


@pytest.fixture
def saved(trained: dict[str, Any], tmp_path: Path) -> Path:
    return trained["model"].save(tmp_path / "good.npz")


def test_other_format_version(saved: Path, tmp_path: Path) -> None:
    bad = rewrite(saved, tmp_path / "v2.npz", lambda h: h.update(format="loci.place-model/2"))
    with pytest.raises(ModelError, match=r"loci.place-model/2.*retrain"):
        PlaceModel.load(bad)
    other = rewrite(saved, tmp_path / "other.npz", lambda h: h.update(format="someone.else/1"))
    with pytest.raises(ModelError, match="not a genius-loci place model"):
        PlaceModel.load(other)


def test_unknown_feature_names(saved: Path, tmp_path: Path) -> None:
    def rename(h: dict[str, Any]) -> None:
        h["feature_names"][0] = "Z.99[warp=9]"

    bad = rewrite(saved, tmp_path / "unknown.npz", rename)
    with pytest.raises(ModelError, match=r"Z\.99.*retrain"):
        PlaceModel.load(bad)


def test_truncated_file(saved: Path, tmp_path: Path) -> None:
    data = saved.read_bytes()
    for cut in (len(data) // 2, len(data) - 10, 30):
        bad = tmp_path / f"cut{cut}.npz"
        bad.write_bytes(data[:cut])
        with pytest.raises(ModelError, match=r"truncated|not a genius-loci"):
            PlaceModel.load(bad)


def test_object_array_is_refused(saved: Path, tmp_path: Path) -> None:
    with np.load(saved, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["dl.b0.alpha"] = np.array([{"evil": 1}], dtype=object)
    bad = tmp_path / "pickled.npz"
    np.savez(bad, **arrays)  # numpy pickles the object array
    with pytest.raises(ModelError, match="pickled object array"):
        PlaceModel.load(bad)


def test_not_a_model(tmp_path: Path) -> None:
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"\x00 definitely not a zip archive " * 20)
    with pytest.raises(ModelError, match="not a genius-loci place model"):
        PlaceModel.load(junk)
    single = tmp_path / "single.npy"
    np.save(single, np.zeros(3))
    with pytest.raises(ModelError, match="single array"):
        PlaceModel.load(single)
    headless = tmp_path / "headless.npz"
    np.savez(headless, alpha=np.zeros(3))
    with pytest.raises(ModelError, match="header_json"):
        PlaceModel.load(headless)
    with pytest.raises(ModelError, match="no such model file"):
        PlaceModel.load(tmp_path / "absent.npz")


def test_missing_and_inconsistent_arrays(saved: Path, tmp_path: Path) -> None:
    missing = rewrite(saved, tmp_path / "missing.npz", edit_arrays=lambda a: a.pop("dl.b0.alpha"))
    with pytest.raises(ModelError, match=r"missing.*alpha"):
        PlaceModel.load(missing)

    def shorten(a: dict[str, np.ndarray]) -> None:
        a["dl.b1.weak_threshold"] = a["dl.b1.weak_threshold"][:-1]

    short = rewrite(saved, tmp_path / "short.npz", edit_arrays=shorten)
    with pytest.raises(ModelError, match="shape"):
        PlaceModel.load(short)

    def drop_name(h: dict[str, Any]) -> None:
        h["feature_names"] = h["feature_names"][:-1]

    fewer = rewrite(saved, tmp_path / "fewer.npz", drop_name)
    with pytest.raises(ModelError, match="features"):
        PlaceModel.load(fewer)
    no_extra = rewrite(saved, tmp_path / "noextra.npz", edit_arrays=lambda a: a.pop("extra.compatibility"))
    with pytest.raises(ModelError, match=r"extra\.compatibility"):
        PlaceModel.load(no_extra)


def test_bad_model_contents_are_refused_before_writing(trained: dict[str, Any], tmp_path: Path) -> None:
    model = trained["model"]
    with pytest.raises(ValueError, match="object array"):
        PlaceModel(
            model.feature_names, model.decision_list, model.scan, extras={"x": np.array([None], dtype=object)}
        )
    with pytest.raises(ValueError, match="names"):
        PlaceModel(model.feature_names[:-1], model.decision_list, model.scan)
    with pytest.raises(ValueError, match="n_beams"):
        ScanParams(n_beams=0, max_range=30.0)
    odd = PlaceModel(model.feature_names, model.decision_list, model.scan, extras_meta={"when": object()})
    with pytest.raises(ValueError, match="JSON"):
        odd.save(tmp_path / "odd.npz")
    assert not any(tmp_path.iterdir())
