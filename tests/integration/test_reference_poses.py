"""``loci import --reference``: a corrected copy's poses on pose/truth, matched by ranges; and
the CSAIL log's 406 corrected scans (real data)."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import pytest
from test_import_cli import box_ranges, corridor_log, loci

from agent.recording.importer import import_log
from agent.recording.localize import read_truth
from agent.recording.reference import add_reference
from knowledge.errors import DataError


def corrected_copy(path: Path, keep: list[int]) -> Path:
    """A corrected log of some scans of :func:`corridor_log`: other poses (shifted 10 m, in a
    frame of its own), ranges printed with other digits, times too coarse to match on."""
    lines = ["# corrected"]
    for i in keep:
        x = 0.1 * i
        r = " ".join(f"{v:.6f}" for v in np.round(box_ranges(x, 0.0, 0.0), 2))
        pose = f"{x + 10.0:.3f} 5 0.1"
        lines.append(f"FLASER 181 {r} {pose} {pose} 1.13486e+09 pippo 1.13486e+09")
    with gzip.open(path, "wt") as f:
        f.write("\n".join(lines) + "\n")
    return path


def test_import_with_a_reference_as_a_user_types_it(tmp_path: Path) -> None:
    raw = corridor_log(tmp_path / "raw.log.gz", scans=30)
    ref = corrected_copy(tmp_path / "corrected.log.gz", [3, 10, 11, 25])
    out = tmp_path / "run.mcap"
    done = loci("import", raw, out, "--reference", ref, "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["reference"] == {"matched": 4, "scans": 4}
    stamps, poses = read_truth(out, "raw")
    assert np.allclose(stamps, [1000.0 + 0.2 * i for i in (3, 10, 11, 25)])  # the raw scans' stamps
    assert np.allclose(poses[:, 0], [10.3, 11.0, 11.1, 12.5]) and np.allclose(poses[:, 1:], [5.0, 0.1])
    plain = loci("import", raw, tmp_path / "plain.mcap")
    assert "reference" in done.stdout and plain.returncode == 0
    # the scans and odometry are those of the plain import
    assert read_truth(tmp_path / "plain.mcap", "raw")[0].size == 0


def test_a_reference_that_matches_nothing_is_an_error(tmp_path: Path) -> None:
    raw = corridor_log(tmp_path / "raw.log.gz", scans=10)
    rec = tmp_path / "raw.mcap"
    import_log(raw, rec, emit=lambda s: None)
    other = tmp_path / "other.log.gz"
    with gzip.open(other, "wt") as f:
        f.write("FLASER 3 1.0 2.0 3.0 0 0 0 0 0 0 1.0 x 1.0\n")
    with pytest.raises(DataError, match="none of its 1 scans"):
        add_reference(rec, other, tmp_path / "out.mcap")
    assert not (tmp_path / "out.mcap").exists() and not (tmp_path / "out.mcap.partial").exists()


@pytest.mark.data
def test_csail_corrected_poses_match_406_raw_scans(shared_data: Path, tmp_path: Path) -> None:
    logs = shared_data / "logs"
    rec = tmp_path / "csail.mcap"
    import_log(logs / "csail-oldcarmen.log.gz", tmp_path / "raw.mcap", emit=lambda s: None)
    res = add_reference(tmp_path / "raw.mcap", logs / "csail-corrected.log.gz", rec)
    assert (res.matched, res.reference_scans, res.raw_scans) == (406, 406, 1988)
    stamps, poses = read_truth(rec, "csail-oldcarmen")
    assert stamps.size == 406 and np.all(np.diff(stamps) > 0)
    # the corrected frame starts near the origin, the raw odometry near (576, 0)
    assert np.hypot(*poses[0, :2]) < 1.0


@pytest.mark.data
@pytest.mark.slow
def test_csail_replayed_with_tracking_follows_the_corrected_poses(shared_data: Path, tmp_path: Path) -> None:
    """``loci replay`` of the raw CSAIL log with ``[localization] tracking``: its first 560 scans
    (the first 3,000 lines) stay within 0.3 m RMS of the corrected poses; raw odometry does not."""
    from dataclasses import replace

    from agent.core.pipeline import PipelineParams
    from agent.recording.offline import read_recording_metadata, replay_recording
    from knowledge.localization.tracking import TrackingParams
    from knowledge.localization.trajectory import associate, ate

    logs = shared_data / "logs"
    import_log(
        prefix_log(logs / "csail-oldcarmen.log.gz", tmp_path / "head.log.gz", 3000), tmp_path / "raw.mcap"
    )
    rec = tmp_path / "csail.mcap"
    add_reference(tmp_path / "raw.mcap", logs / "csail-corrected.log.gz", rec)
    base = PipelineParams.from_table(json.loads(read_recording_metadata(rec)["pipeline"]))
    got: dict[str, list] = {"on": [], "off": []}
    for key, params in (("on", replace(base, localization=TrackingParams())), ("off", base)):
        out = replay_recording(rec, params=params, on_step=lambda r, k=key: got[k].append(r))
        assert out.accounting()["balanced"]
    stamps, truth = read_truth(rec, "head")
    for key in got:
        st = np.array([r.stamp for r in got[key]])
        est = np.array([[r.pose.x, r.pose.y, r.pose.theta] for r in got[key]])
        pairs = associate(st, stamps, 1e-3)
        assert len(pairs) > 50
        got[key] = [ate(truth[pairs[:, 1]], est[pairs[:, 0]])[0].rmse]  # type: ignore[list-item]
    assert got["on"][0] < 0.3 < got["off"][0]


def prefix_log(src: Path, dst: Path, lines: int) -> Path:
    with gzip.open(src, "rt") as f, gzip.open(dst, "wt") as g:
        for k, line in enumerate(f):
            if k >= lines:
                break
            g.write(line)
    return dst
