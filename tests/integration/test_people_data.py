"""The legs data, its protocol, and `loci people train/evaluate` end to end (skipped without the data)."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest
from support import cli

from knowledge.people import dataset as ds

REPO = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.data


def loci(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return cli.loci("people", *args, env=env)


@pytest.fixture(scope="module")
def legs_dir(shared_data: Path) -> Path:
    return ds.find_legs_dir(shared_data)


def test_protocol_split(legs_dir: Path) -> None:
    train = ds.protocol_parts("train", legs_dir)
    test = ds.protocol_parts("test", legs_dir)
    names = lambda parts: {p.file for p in parts}  # noqa: E731
    assert {f"positive_{n}_extracted.training_scan.npz" for n in (1, 2, 3, 4)} < names(train)
    assert {f"positive_{n}_extracted.training_scan.npz" for n in (6, 7)} < names(test)
    assert not any(f.startswith("positive") for f in names(train) & names(test))
    for laser in ("left", "rear", "right"):
        f = f"negative_2.{laser}_scan.npz"
        (a,) = [p for p in train if p.file == f]
        (b,) = [p for p in test if p.file == f]
        n = ds.load_recording(legs_dir / f).n_scans
        assert a.first == 0 and a.stop == b.first and b.stop == n
        assert a.stop == int(0.7 * n)
    short = ds.protocol_parts("train", legs_dir, max_scans=5)
    assert all(p.stop is not None and p.stop - p.first == 5 for p in short)
    with pytest.raises(ValueError):
        ds.protocol_parts("validation", legs_dir)


def test_recordings_and_labels(legs_dir: Path) -> None:
    pos = ds.load_recording(legs_dir / "positive_1_extracted.training_scan.npz")
    assert pos.positive and pos.ranges.shape[1] == 768 and pos.range_max == 11.0
    assert pos.period == ds.NOMINAL_PERIOD  # its stamps are write times, ~1 ms apart
    neg = ds.load_recording(legs_dir / "negative_2.left_scan.npz")
    assert not neg.positive and 0.1 < neg.period < 0.2
    assert ds.load_recording(legs_dir / "positive_4_extracted.training_scan.npz").arc == (-15.0, 10.0, 5.0)
    ex = ds.build_examples(legs_dir, [ds.Part(pos_file := "positive_1_extracted.training_scan.npz", 0, 40)])
    d = ex.diagnostics
    assert d["scans"] == 40 and d["legs"] > 40
    assert d["legs_matched"] >= 0.8 * d["legs"]  # the 15 cm segments reproduce most labelled clusters
    assert ex.n_positive == pytest.approx(d["legs_matched"], abs=3)
    assert ex.X.shape == (ex.y.size, 14) and np.isfinite(ex.X).all()
    assert (ex.X[:, 0] >= 2).all()
    assert ex.parts[0].file == pos_file
    negs = ds.build_examples(legs_dir, [ds.Part("negative_2.rear_scan.npz", 0, 5)])
    assert negs.n_positive == 0 and negs.n_negative > 50


def test_error_codes_are_no_returns_as_for_the_labels(legs_dir: Path) -> None:
    """The laser reports errors as ranges of 6-15 mm. leg_tracker, which made the labels,
    dropped them (below the scans' range_min): no label lies at the laser, and with
    LEGS_RANGE_MIN our segments reproduce more of the labelled legs than with the codes as points."""
    from dataclasses import replace

    rec = ds.load_recording(legs_dir / "positive_6_extracted.training_scan.npz")
    assert rec.range_min == ds.LEGS_RANGE_MIN
    r = rec.ranges[:40]
    codes = (r > 0) & (r < ds.LEGS_RANGE_MIN)
    assert codes.sum() > 40 * 10  # dozens per scan
    assert rec.legs is not None and np.hypot(rec.legs[:, 1], rec.legs[:, 2]).min() > 0.1

    def matched(recording: ds.LegsRecording) -> tuple[int, int, np.ndarray]:
        legs = hits = 0
        sizes = []
        for k, seg, _ in ds.iter_scan_features(recording, 0, 40):
            _, counts = ds.label_segments(recording, k, seg.centroids(), seg.sizes)
            legs += counts["legs"]
            hits += counts["legs_matched"]
            sizes.append(np.hypot(*seg.centroids().T))
        return legs, hits, np.concatenate(sizes)

    legs, with_min, dist = matched(rec)
    _, without, dist0 = matched(replace(rec, range_min=0.0))
    assert with_min >= 0.9 * legs and with_min > without
    assert (dist0 < 0.02).sum() > 40 and (dist < 0.02).sum() == 0  # no segments at the laser


def test_examples_carry_the_distance_for_max_range(legs_dir: Path) -> None:
    ex = ds.build_examples(legs_dir, [ds.Part("negative_2.left_scan.npz", 0, 5)])
    assert ex.distance.shape == ex.y.shape and (ex.distance > 0).all() and ex.distance.max() > 5.0


def test_missing_data_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(ds.DataError, match="--data"):
        ds.find_legs_dir(tmp_path)


@pytest.mark.slow
def test_cli_train_and_evaluate_end_to_end(shared_data: Path, tmp_path: Path) -> None:
    model = tmp_path / "small.npz"
    out = loci(
        "train",
        "--data",
        str(shared_data),
        "--max-scans",
        "30",
        "--rounds",
        "20",
        "--threshold",
        "train-cv",
        "--out",
        str(model),
        "--json",
    )
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    assert summary["rounds"] <= 20 and summary["people_segments"] > 0
    assert model.is_file()
    # the threshold came from the training split's cross-validation and is stored in the model
    assert math.isfinite(summary["threshold"]) and summary["threshold"] != 0.0
    out = loci(
        "evaluate", "--model", str(model), "--max-scans", "30", "--json", env={"LOCI_DATA": str(shared_data)}
    )
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    c = result["confusion"]
    assert c["people"]["total"] == c["people"]["people"] + c["people"]["non_people"] > 0
    assert c["non_people"]["total"] == c["non_people"]["people"] + c["non_people"]["non_people"] > 0
    assert c["people"]["people_pct"] + c["people"]["non_people_pct"] == pytest.approx(100.0)
    fn = 100.0 * c["people"]["non_people"] / c["people"]["total"]
    assert result["false_negative_rate_pct"] == pytest.approx(fn)
    assert len(result["top_features"]) == 5
    assert result["detector"]["threshold"] == summary["threshold"]
    assert {"false_positive_rate_pct", "targets", "beams", "per_file", "diagnostics"} <= set(result)


@pytest.mark.slow
def test_cli_evaluates_the_bundled_model(shared_data: Path) -> None:
    out = loci("evaluate", "--data", str(shared_data / "legs"), "--max-scans", "40", "--json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["model"] == "bundled"
    assert result["detector"]["n_rounds"] == 100
    assert 0.0 <= result["false_negative_rate_pct"] <= 100.0
    # readable form
    text = loci("evaluate", "--data", str(shared_data), "--max-scans", "10")
    assert text.returncode == 0, text.stderr
    assert "Detected label" in text.stdout and "No person" in text.stdout and "C." in text.stdout


def test_cli_says_where_the_data_should_be(tmp_path: Path) -> None:
    out = loci("evaluate", "--data", str(tmp_path), "--json")
    assert out.returncode == 2
    assert "--data" in out.stderr and "LOCI_DATA" in out.stderr
