"""``loci`` run as a user runs it: a fresh interpreter, from the repository's root."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def loci(
    *args: str | Path,
    check: bool = False,
    env: Mapping[str, str] | None = None,
    timeout: float = 600.0,
) -> subprocess.CompletedProcess[str]:
    """``loci ARGS``; its exit code, stdout and stderr. ``check``: a non-zero exit is an
    AssertionError that shows stderr. ``env`` adds to the environment; ``timeout`` only ends
    a hung command."""
    proc = subprocess.run(
        [sys.executable, "-m", "agent.cli", *map(str, args)],
        cwd=REPO,
        env={**os.environ, **(env or {})},
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )
    if check and proc.returncode != 0:
        raise AssertionError(f"loci {' '.join(map(str, args))} failed ({proc.returncode}):\n{proc.stderr}")
    return proc
