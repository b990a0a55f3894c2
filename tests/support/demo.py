"""Play `loci demo` in a subprocess for the end-to-end tests: the output folder, the summary
the demo wrote, the finished process."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any


def play_demo(out: Path, seed: int, *args: str) -> tuple[dict[str, Any], subprocess.CompletedProcess[str]]:
    """``loci demo --out OUT --seed SEED ARGS...``; fails the test when no summary was written."""
    proc = subprocess.run(
        [sys.executable, "-m", "agent.cli", "demo", "--out", str(out), "--seed", str(seed), *args],
        capture_output=True,
        text=True,
        timeout=400,
    )
    summary_path = out / "summary.json"
    assert summary_path.is_file(), f"no summary; the demo said:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return json.loads(summary_path.read_text()), proc
