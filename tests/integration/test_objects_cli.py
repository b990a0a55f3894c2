"""``loci objects add/list/recognise/remove`` as a user types them, on real image files."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

import agent.cli as cli
from agent.commands.objects import default_db_dir
from drivers.messages import Pose2D
from knowledge.metric.grid import OccupancyGrid
from sim.camera_view import CameraMount, VirtualCamera
from sim.objects import WorldObject, object_texture
from sim.world import SimWorld

REPO = Path(__file__).resolve().parents[2]
MODULE = "agent.commands.objects"


@pytest.fixture(autouse=True)
def registered(monkeypatch: pytest.MonkeyPatch) -> None:
    """The command as the lead registers it in agent/cli.py (kept working before and after)."""
    if MODULE not in cli.COMMAND_MODULES:
        monkeypatch.setattr(cli, "COMMAND_MODULES", [*cli.COMMAND_MODULES, MODULE])


def loci(capsys: pytest.CaptureFixture[str], *args: str | Path) -> tuple[int, str, str]:
    code = cli.main(["-q", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Pictures of a television and a charging station, and a camera frame showing both."""
    d = tmp_path_factory.mktemp("objects_cli")
    occ = np.zeros((120, 120), bool)
    occ[:2], occ[-2:], occ[:, :2], occ[:, -2:] = True, True, True, True
    grid = OccupancyGrid.from_masks(occ, 0.05, origin=(-3.0, -3.0, 0.0))
    tv = WorldObject.place("television", 1.0, 0.6, math.pi, name="television")
    dock = WorldObject.place("charging_station", 0.5, -0.4, math.pi, name="charging_station")
    cam = VirtualCamera(SimWorld(grid, (tv, dock)), mount=CameraMount(z=1.0), noise_sigma=2.0, blur_sigma=0.6)
    out = {
        "tv": d / "tv.png",
        "dock": d / "dock.jpg",
        "frame": d / "frame.png",
        "empty": d / "empty.png",
        "junk": d / "junk.png",
    }
    cv2.imwrite(str(out["tv"]), np.ascontiguousarray(object_texture(tv)))
    cv2.imwrite(str(out["dock"]), np.ascontiguousarray(object_texture(dock)), [cv2.IMWRITE_JPEG_QUALITY, 95])
    cv2.imwrite(str(out["frame"]), cam.render(Pose2D(-2.0, 0.0, 0.0)))
    cv2.imwrite(str(out["empty"]), cam.render(Pose2D(-2.0, 0.0, math.pi)))
    out["junk"].write_bytes(b"not a picture at all")
    return out


def test_teach_list_recognise_remove(
    tmp_path: Path, files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "db"
    code, out, _ = loci(capsys, "objects", "add", "television", files["tv"], "--db", db)
    assert code == 0 and "taught 'television' (Television): 1 picture" in out
    code, out, _ = loci(
        capsys, "objects", "add", "dock", files["dock"], "--kind", "charging station", "--db", db
    )
    assert code == 0 and "(ChargingStation)" in out

    code, out, _ = loci(capsys, "objects", "list", "--db", db, "--json")
    listed = json.loads(out)
    assert [(o["name"], o["kind"]) for o in listed["objects"]] == [
        ("dock", "ChargingStation"),
        ("television", "Television"),
    ]
    code, out, _ = loci(capsys, "objects", "list", "--db", db)
    assert out.splitlines()[0].startswith("dock ")

    code, out, _ = loci(capsys, "objects", "recognise", files["frame"], files["empty"], "--db", db, "--json")
    assert code == 0
    frame, empty = json.loads(out)["images"]
    assert (frame["width"], frame["height"]) == (640, 480)
    found = {d["name"]: d for d in frame["detections"]}
    assert set(found) == {"television", "dock"}
    assert found["television"]["kind"] == "Television" and found["television"]["inliers"] >= 12
    assert found["television"]["centre"][0] < 320 < found["dock"]["centre"][0]  # tv left, dock right
    assert empty["detections"] == []
    code, out, _ = loci(capsys, "objects", "recognize", files["empty"], "--db", db)
    assert out.strip() == f"{files['empty']}: nothing recognised"

    code, out, _ = loci(capsys, "objects", "remove", "dock", "--db", db)
    assert code == 0 and "forgot 'dock'" in out
    code, out, _ = loci(capsys, "objects", "recognise", files["frame"], "--db", db, "--json")
    assert [d["name"] for d in json.loads(out)["images"][0]["detections"]] == ["television"]


def test_bad_input_is_a_one_line_error(
    tmp_path: Path, files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "db"
    code, _, err = loci(capsys, "objects", "recognise", files["frame"], "--db", db)
    assert code == 2 and err.startswith("loci: error:") and "no objects in" in err
    code, _, err = loci(capsys, "objects", "add", "tv", files["tv"], files["junk"], "--db", db)
    assert code == 2 and "junk.png: cannot read it as an image" in err
    assert not db.exists()  # nothing written when one picture is bad
    code, _, err = loci(capsys, "objects", "add", "tv", tmp_path / "nope.png", "--db", db)
    assert code == 2 and "no such image file" in err
    loci(capsys, "objects", "add", "tv", files["tv"], "--db", db)
    code, _, err = loci(capsys, "objects", "remove", "couch", "--db", db)
    assert code == 2 and "unknown object 'couch'" in err and "known: tv" in err
    code, _, err = loci(capsys, "objects", "add", "3d", files["tv"], "--db", db)
    assert code == 2 and "--kind" in err


def test_default_db_follows_the_state_dir_convention(tmp_path: Path) -> None:
    assert default_db_dir({"LOCI_OBJECTS_DB": "/x/db", "LOCI_STATE_DIR": "/s"}) == Path("/x/db")
    assert default_db_dir({"LOCI_STATE_DIR": "/s"}) == Path("/s/objects")
    env = {"XDG_STATE_HOME": str(tmp_path), "LOCI_ROBOT": "rosie"}
    assert default_db_dir(env) == tmp_path / "genius-loci" / "rosie" / "objects"


@pytest.mark.slow
def test_help_and_exit_code_in_a_real_process(tmp_path: Path, files: dict[str, Path]) -> None:
    code = (
        "import sys, agent.cli as c\n"
        f"c.COMMAND_MODULES.append({MODULE!r}) if {MODULE!r} not in c.COMMAND_MODULES else None\n"
        "sys.exit(c.main(sys.argv[1:]))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO), "LOCI_OBJECTS_DB": str(tmp_path / "envdb")}

    def run(*args: str | Path) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-c", code, *map(str, args)],
            env=env,
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=120,
        )

    h = run("objects", "--help")
    assert (
        h.returncode == 0 and "add" in h.stdout and "recognise" in h.stdout and "$LOCI_OBJECTS_DB" in h.stdout
    )
    h = run("objects", "add", "--help")
    assert h.returncode == 0 and "--kind" in h.stdout and "ChargingStation" in h.stdout
    ok = run("objects", "add", "television", files["tv"])
    assert ok.returncode == 0, ok.stderr
    assert (tmp_path / "envdb" / "index.json").is_file()  # $LOCI_OBJECTS_DB is the default --db
    bad = run("objects", "recognise", files["junk"])
    assert bad.returncode == 2 and bad.stderr.startswith("loci: error:") and "Traceback" not in bad.stderr
