"""The conceptual map survives a killed process: what was saved comes back, nothing is torn."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

from knowledge.conceptual import ConceptualMap

REPO = Path(__file__).resolve().parents[2]

CHILD = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from knowledge.conceptual import ConceptualMap
    m = ConceptualMap(Path(sys.argv[1]))
    m.set_area(1, "room")
    m.set_area(2, "corridor")
    m.add_object("couch", "couch", 1, node=3)
    m.assert_type(2, "corridor", "anna")
    m.assert_name(1, "the den", "bob")
    m.reason()
    m.save()
    print("saved", m.version, flush=True)
    m.add_object("tv", "television", 2, node=9)   # not saved: must not come back
    print("changed", flush=True)
    time.sleep(120)
    """
)


def test_saved_map_survives_sigkill(tmp_path: Path) -> None:
    db = tmp_path / "concepts.sqlite3"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(db)], stdout=subprocess.PIPE, text=True, cwd=REPO, env=env
    )
    try:
        assert child.stdout is not None
        saved = child.stdout.readline().split()
        assert saved[:1] == ["saved"], saved
        assert child.stdout.readline().strip() == "changed"
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    assert child.returncode == -signal.SIGKILL
    with ConceptualMap(db) as m:
        snap = m.snapshot()
        assert snap["version"] == int(saved[1]) and snap["reasoned"] == snap["version"]
        assert snap["areas"]["1"]["types"] == ["LivingRoom", "Room"], "the inferred layer is persisted"
        assert snap["areas"]["1"]["names"] == ["the den"]
        assert snap["areas"]["2"]["asserted"] == [
            {"kind": "type", "word": "corridor", "class": "Corridor", "speaker": "anna"}
        ]
        assert set(snap["objects"]) == {"couch"}, "an unsaved change must not come back"
        # the reopened map keeps working and saving
        m.add_object("tv", "television", 2, node=9)
        version = m.version
    with ConceptualMap(db) as m:
        assert m.version == version and m.snapshot()["objects"]["tv"]["area"] == 2
