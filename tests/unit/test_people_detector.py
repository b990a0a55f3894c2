"""The boosted leg detector: training, per-segment and per-beam labels, model files, the bundled model."""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path

import numpy as np
import pytest

from knowledge.errors import ModelError, NotFittedError
from knowledge.metric.grid import OccupancyGrid
from knowledge.people.detector import DEFAULT_MODEL, FORMAT, LegDetector
from knowledge.people.features import DEFAULT_COLUMNS, FEATURE_CODES, N_FEATURES, segment_features
from knowledge.people.segmentation import segment_scan
from sim.lms_world import Leg, LmsWorld

N_BEAMS = 768
INC = 0.006135923322290182
ANGLE_MIN = -2.356194496154785
FOV = INC * (N_BEAMS - 1)
RMAX = 11.0


def room() -> OccupancyGrid:
    """A 10 m × 10 m room at 5 cm with a table-sized block and a thin shelf."""
    occ = np.zeros((200, 200), dtype=bool)
    occ[:3] = occ[-3:] = True
    occ[:, :3] = occ[:, -3:] = True
    occ[40:60, 130:160] = True
    occ[150:152, 30:90] = True
    return OccupancyGrid.from_masks(occ, 0.05)


def synthetic_examples(n_scans: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Segments of simulated scans with one or two legs at random places: features and labels."""
    rng = np.random.default_rng(seed)
    grid = room()
    Xs, ys = [], []
    for _ in range(n_scans):
        pose = (rng.uniform(3.0, 7.0), rng.uniform(3.0, 7.0), rng.uniform(-math.pi, math.pi))
        centres = []
        for _k in range(2):
            d, b = rng.uniform(0.8, 3.5), rng.uniform(-2.0, 2.0)
            centres.append((pose[0] + d * math.cos(pose[2] + b), pose[1] + d * math.sin(pose[2] + b)))
        legs = [Leg(c, rng.uniform(0.05, 0.07)) for c in centres]
        world = LmsWorld(grid, pose, legs, noise_std=0.005, seed=int(rng.integers(1 << 30)))
        r = world.ranges(0.0, n_beams=N_BEAMS, fov=FOV, max_range=RMAX, angle_min=ANGLE_MIN)
        seg = segment_scan(r, ANGLE_MIN, INC, range_max=RMAX)
        X = segment_features(seg, range_max=RMAX)
        c = seg.centroids()
        th = pose[2]
        world_c = np.column_stack(
            [
                pose[0] + c[:, 0] * math.cos(th) - c[:, 1] * math.sin(th),
                pose[1] + c[:, 0] * math.sin(th) + c[:, 1] * math.cos(th),
            ]
        )
        near = np.min([np.hypot(*(world_c - np.array(q)).T) for q in centres], axis=0)
        keep = seg.sizes >= 2
        Xs.append(X[keep])
        ys.append(near[keep] < 0.1)
    return np.concatenate(Xs), np.concatenate(ys)


@pytest.fixture(scope="module")
def trained() -> LegDetector:
    X, y = synthetic_examples(30, seed=1)
    assert y.sum() >= 20 and (~y).sum() >= 100
    return LegDetector(n_rounds=30).fit(X, y, training={"source": "synthetic"})


def test_learns_legs_and_labels_their_beams(trained: LegDetector) -> None:
    X, y = synthetic_examples(10, seed=2)
    pred = trained.predict(X)
    assert (pred[y]).mean() >= 0.9
    assert (pred[~y]).mean() <= 0.1
    # one scan: the leg's beams are the person beams
    grid = room()
    pose = (5.0, 5.0, 0.0)
    world = LmsWorld(grid, pose, [Leg((7.0, 5.5), 0.06)], noise_std=0.0)
    r = world.ranges(0.0, n_beams=N_BEAMS, fov=FOV, max_range=RMAX, angle_min=ANGLE_MIN)
    det = trained.detect(r, ANGLE_MIN, INC, range_max=RMAX)
    assert det.legs.shape == (1, 2)
    np.testing.assert_allclose(det.legs[0], [2.0, 0.5], atol=0.08)
    beams = det.beam_labels
    bearing = math.atan2(0.5, 2.0)
    half = math.asin(0.06 / math.hypot(2.0, 0.5))
    angles = ANGLE_MIN + np.arange(N_BEAMS) * INC
    on_leg = np.abs(angles - bearing) < half - INC
    assert beams[on_leg].all()
    assert beams.sum() <= on_leg.sum() + 2
    assert det.score.shape == (det.segmentation.n_segments,)


def test_save_load_round_trip(trained: LegDetector, tmp_path: Path) -> None:
    path = trained.save(tmp_path / "legs.npz")
    with np.load(path, allow_pickle=False) as z:
        header = json.loads(z["header_json"].tobytes().decode())
    assert header["format"] == FORMAT
    assert header["features"] == [FEATURE_CODES[i] for i in DEFAULT_COLUMNS]
    assert (
        "C.4" not in header["features"]
        and "C.5" not in header["features"]
        and "C.14" not in header["features"]
    )
    assert header["detector"]["jump"] == 0.15
    assert header["detector"]["max_range"] is None
    assert header["training"]["source"] == "synthetic"
    back = LegDetector.load(path)
    X, _ = synthetic_examples(3, seed=3)
    np.testing.assert_array_equal(back.decision_function(X), trained.decision_function(X))
    assert back.columns == trained.columns and back.threshold == trained.threshold
    assert back.top_learners(3) == trained.top_learners(3)


def test_broken_model_files_raise_model_error(trained: LegDetector, tmp_path: Path) -> None:
    with pytest.raises(ModelError, match="no such"):
        LegDetector.load(tmp_path / "missing.npz")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip at all")
    with pytest.raises(ModelError):
        LegDetector.load(junk)
    good = trained.save(tmp_path / "good.npz")
    with np.load(good, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(arrays["header_json"].tobytes().decode())

    def write(name: str, h: dict[str, object], extra: dict[str, np.ndarray] | None = None) -> Path:
        a = dict(arrays)
        a["header_json"] = np.frombuffer(json.dumps(h).encode(), dtype=np.uint8)
        a.update(extra or {})
        p = tmp_path / name
        np.savez(p, **a)
        return p

    with pytest.raises(ModelError, match="retrain"):  # /1 measured C.4/C.5 across no-return beams
        LegDetector.load(write("v1.npz", {**header, "format": "loci.people-model/1"}))
    with pytest.raises(ModelError, match="format"):
        LegDetector.load(write("v3.npz", {**header, "format": "loci.people-model/3"}))
    with pytest.raises(ModelError, match="not a genius-loci people model"):
        LegDetector.load(write("place.npz", {**header, "format": "loci.place-model/1"}))
    with pytest.raises(ModelError, match="unknown features"):
        LegDetector.load(write("feat.npz", {**header, "features": ["C.1", "C.99"]}))
    with pytest.raises(ModelError, match="inconsistent"):
        LegDetector.load(write("short.npz", {**header, "features": ["C.1", "C.2"]}))
    with pytest.raises(ModelError, match="pickled"):
        LegDetector.load(write("pickle.npz", header, {"evil": np.array([{"a": 1}], dtype=object)}))
    with zipfile.ZipFile(good) as zf:
        names = zf.namelist()
    assert all(n.endswith(".npy") for n in names)


def test_unfitted_and_bad_parameters() -> None:
    with pytest.raises(NotFittedError):
        LegDetector().predict(np.zeros((1, N_FEATURES)))
    with pytest.raises(ValueError, match="columns"):
        LegDetector(columns=[0, 14]).fit(np.zeros((4, N_FEATURES)), [True, False, True, False])
    with pytest.raises(ValueError, match=r"\(n, 14\)"):
        LegDetector(n_rounds=2).fit(np.zeros((4, 3)), [True, False, True, False])


def test_bundled_model() -> None:
    assert DEFAULT_MODEL.is_file()
    assert DEFAULT_MODEL.stat().st_size < 50_000
    det = LegDetector.load()
    assert det.booster_.n_rounds_ == 100
    assert det.booster_.booster_type == "generalized"
    assert set(det.booster_.weak_kind_.tolist()) == {0}  # threshold learners only
    assert det.columns == DEFAULT_COLUMNS
    assert det.jump == 0.15
    assert det.max_range == 5.0
    assert det.training_["protocol"] == "train"
    assert det.training_["command"].startswith("loci people train")
    top = det.top_features(5)
    assert len(top) == 5
    assert [f["importance"] for f in top] == sorted((f["importance"] for f in top), reverse=True)
    learners = det.top_learners(5)
    assert [f["alpha"] for f in learners] == sorted((f["alpha"] for f in learners), reverse=True)


def test_max_range_makes_far_segments_non_persons(trained: LegDetector, tmp_path: Path) -> None:
    grid = room()
    pose = (5.0, 5.0, 0.0)
    near, far = Leg((7.0, 5.5), 0.06), Leg((8.0, 3.0), 0.06)  # 2.06 m and 3.61 m from the laser
    world = LmsWorld(grid, pose, [near, far], noise_std=0.0)
    r = world.ranges(0.0, n_beams=N_BEAMS, fov=FOV, max_range=RMAX, angle_min=ANGLE_MIN)
    unlimited = trained.detect(r, ANGLE_MIN, INC, range_max=RMAX)
    np.testing.assert_allclose(sorted(np.hypot(*unlimited.legs.T)), [2.06, 3.61], atol=0.08)  # near surface
    limited = LegDetector.load(trained.save(tmp_path / "short.npz"))
    limited.max_range = 3.0
    det = limited.detect(r, ANGLE_MIN, INC, range_max=RMAX)
    assert det.legs.shape == (1, 2)
    np.testing.assert_allclose(det.legs[0], [2.0, 0.5], atol=0.08)
    far_segment = int(np.argmin(np.hypot(*(det.segmentation.centroids() - [3.0, -2.0]).T)))
    assert (
        det.score[far_segment] == -np.inf
        and not det.beam_labels[det.segmentation.segment_beams(far_segment)].any()
    )
    # predict() applies the same limit when it is given the distances, and C.1 < min_points
    X = det.features
    dist = np.hypot(*det.segmentation.centroids().T)
    np.testing.assert_array_equal(limited.predict(X, dist), det.is_person)
    assert limited.predict(X).sum() == 2  # without distances only the size rule applies
    assert not limited.classifies([1, 5], [1.0, 3.5]).any() and limited.classifies([2], [2.9]).all()
    with pytest.raises(ValueError, match="max_range"):
        LegDetector(max_range=0.0).fit(X, np.arange(len(X)) % 2 == 0)
    # the limit is part of the model file
    limited.max_range = 3.0
    assert LegDetector.load(limited.save(tmp_path / "limited.npz")).max_range == 3.0


def test_error_codes_below_range_min_are_no_returns(trained: LegDetector) -> None:
    """A Hokuyo reports errors as ranges of a few millimetres; with the sensor's range_min the
    detector skips them, without it they are points at the laser that cut the leg."""
    grid = room()
    world = LmsWorld(grid, (5.0, 5.0, 0.0), [Leg((7.0, 5.5), 0.06)], noise_std=0.0)
    r = world.ranges(0.0, n_beams=N_BEAMS, fov=FOV, max_range=RMAX, angle_min=ANGLE_MIN)
    clean = trained.detect(r, ANGLE_MIN, INC, range_max=RMAX)
    (leg,) = np.flatnonzero(clean.is_person)
    beams = clean.segmentation.segment_beams(int(leg))
    dirty = r.copy()
    dirty[beams[len(beams) // 2]] = 0.009  # an error code in the middle of the leg
    dirty[beams[0] - 1] = 0.006  # and one at its edge
    ok = trained.detect(dirty, ANGLE_MIN, INC, range_max=RMAX, range_min=0.02)
    np.testing.assert_allclose(ok.legs, clean.legs, atol=0.01)
    cut = trained.detect(dirty, ANGLE_MIN, INC, range_max=RMAX)  # range_min = 0: the codes are points
    assert cut.segmentation.n_segments > clean.segmentation.n_segments
