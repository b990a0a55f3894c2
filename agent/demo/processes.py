"""The demo's child processes: started with their output in log files, stopped in order.

Each child is ``python -m agent.cli ...`` (the same interpreter, so the same environment) in
its own session, so a Ctrl-C in the terminal reaches only the demo, which then stops the
children itself, last started first: SIGINT, a grace period, SIGKILL. :class:`Children` is
a context manager; leaving it (normally, by an exception or by Ctrl-C) stops every child.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import TracebackType
from typing import Any

__all__ = ["Child", "Children", "free_port", "stop_process"]


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free now (the system picks it)."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Child:
    """One running ``loci`` command, its output in ``log``."""

    def __init__(self, name: str, args: list[str], log: Path) -> None:
        self.name = name
        self.args = args
        self.log = log
        self._out = log.open("wb")  # closed in stop()
        env = dict(os.environ)
        env.setdefault("PYTHONUNBUFFERED", "1")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "agent.cli", *args],
            stdin=subprocess.DEVNULL,
            stdout=self._out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            env=env,
        )

    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def tail(self, lines: int = 12) -> str:
        """The last lines of the child's output (for error messages)."""
        try:
            text = self.log.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return ""
        return "\n".join(text.splitlines()[-lines:])

    def stop(self, grace: float = 10.0) -> int | None:
        """SIGINT, wait ``grace`` seconds, then SIGKILL; returns the exit status."""
        try:
            return stop_process(self.proc, signal.SIGINT, grace)
        finally:
            self._out.close()


def stop_process(proc: subprocess.Popen[Any], sig: int = signal.SIGINT, grace: float = 10.0) -> int | None:
    """Ask a child to stop with ``sig``, wait ``grace`` seconds, then SIGKILL it; its exit
    status (a child that already ended is left as it is). The child's output must not be a
    pipe nobody reads (it could block on it while we wait)."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(sig)
        try:
            proc.wait(grace)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            proc.wait(5.0)
    return proc.returncode


class Children:
    """The demo's children (see the module docstring)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.children: list[Child] = []

    def start(self, name: str, args: list[str]) -> Child:
        child = Child(name, args, self.folder / f"{name}.log")
        self.children.append(child)
        return child

    def dead(self) -> Child | None:
        """A child that exited (None: all run)."""
        return next((c for c in self.children if not c.alive()), None)

    def stop(self, name: str, grace: float = 10.0) -> int | None:
        for c in self.children:
            if c.name == name:
                return c.stop(grace)
        return None

    def stop_all(self, grace: float = 10.0) -> dict[str, int | None]:
        codes: dict[str, int | None] = {}
        # Ctrl-C while stopping must not leave children behind
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            for c in reversed(self.children):
                codes[c.name] = c.stop(grace)
        finally:
            signal.signal(signal.SIGINT, previous)
        return codes

    def __enter__(self) -> Children:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop_all()


def wait_for_path(path: Path, timeout: float, children: Children) -> bool:
    """Wait until ``path`` exists (False after ``timeout`` s or when a child died)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.exists():
            return True
        if children.dead() is not None:
            return False
        time.sleep(0.05)
    return False
