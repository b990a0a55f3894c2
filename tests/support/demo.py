"""Play `loci demo` in subprocesses for the end-to-end tests: the output folder, the summary
the demo wrote, the finished process; optionally beside a busy core."""

from __future__ import annotations

import contextlib
import json
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any


@contextlib.contextmanager
def busy_core() -> Iterator[None]:
    """A busy loop on core 0 (``taskset -c 0`` where there is taskset) while the block runs:
    the machine has a core less, as on a CI machine someone else is using."""
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    proc = subprocess.Popen([*pin, "sh", "-c", "while :; do :; done"])
    try:
        yield
    finally:
        proc.kill()
        proc.wait()


def _command(out: Path, seed: int, args: tuple[str, ...]) -> list[str]:
    return [sys.executable, "-m", "agent.cli", "demo", "--out", str(out), "--seed", str(seed), *args]


def _summary(out: Path, proc: subprocess.CompletedProcess[str]) -> dict[str, Any]:
    summary_path = out / "summary.json"
    assert summary_path.is_file(), f"no summary; the demo said:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return dict(json.loads(summary_path.read_text()))


def play_demo(out: Path, seed: int, *args: str) -> tuple[dict[str, Any], subprocess.CompletedProcess[str]]:
    """``loci demo --out OUT --seed SEED ARGS...``; fails the test when no summary was written."""
    proc = subprocess.run(_command(out, seed, args), capture_output=True, text=True, timeout=600)
    return _summary(out, proc), proc


def play_demos(
    runs: list[tuple[Path, int]], *args: str, busy: bool = True, at_once: bool = True
) -> list[tuple[dict[str, Any], subprocess.CompletedProcess[str]]]:
    """Several tours (``(out, seed)`` each), at once or one after the other, beside a busy core
    unless ``busy`` is False."""
    done = []
    with busy_core() if busy else contextlib.nullcontext():
        if not at_once:
            for out, seed in runs:
                proc = subprocess.run(_command(out, seed, args), capture_output=True, text=True, timeout=900)
                done.append((out, proc))
            return [(_summary(out, proc), proc) for out, proc in done]
        procs = [
            (
                out,
                subprocess.Popen(
                    _command(out, seed, args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
                ),
            )
            for out, seed in runs
        ]
        for out, p in procs:
            stdout, stderr = p.communicate(timeout=900)
            done.append((out, subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr)))
    return [(_summary(out, proc), proc) for out, proc in done]
