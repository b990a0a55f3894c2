"""Speaking the robot's lines through espeak-ng, without blocking the dialogue.

:class:`Speech` owns a queue and one asyncio task that runs the synthesiser for one line
at a time (lines never overlap; the event loop never waits on them). The text goes to the
program's standard input (``espeak-ng --stdin``), never on its command line. When the
program is not installed, :attr:`Speech.available` is False and lines are only counted:
the dialogue process prints every line anyway.

Install espeak-ng with ``sudo apt-get install espeak-ng``; ``espeak-ng --voices`` lists voices.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
import shutil
from collections import deque

log = logging.getLogger(__name__)

#: The synthesiser looked up on PATH by default.
DEFAULT_PROGRAM = "espeak-ng"
_VOICE = re.compile(r"[A-Za-z0-9_.+/-]{1,64}")


class Speech:
    """A non-blocking queue of lines for a speech synthesiser.

    Args:
        voice: the synthesiser's voice (``-v VOICE``, e.g. ``"en"``, ``"en-us+f3"``); None:
            its default.
        program: the synthesiser's name on PATH or its path; it is called as ``PROGRAM
            [-v VOICE] [-s WPM] --stdin`` with the text on standard input.
        enabled: False: never speak (``--no-speech``).
        words_per_minute: speaking rate (``-s``), None for the default.
        max_queue: lines waiting beyond this are dropped, oldest first (counted).
        line_timeout: a line still being spoken after this many seconds is cut off.

    Raises:
        ValueError: a voice name with characters a voice name cannot have.
    """

    def __init__(
        self,
        *,
        voice: str | None = None,
        program: str = DEFAULT_PROGRAM,
        enabled: bool = True,
        words_per_minute: int | None = None,
        max_queue: int = 8,
        line_timeout: float = 30.0,
    ) -> None:
        if voice is not None and not _VOICE.fullmatch(voice):
            raise ValueError(f"voice {voice!r} is not a voice name; see 'espeak-ng --voices' (e.g. 'en-us')")
        if words_per_minute is not None and not 80 <= words_per_minute <= 500:
            raise ValueError(f"words_per_minute must be within 80..500, got {words_per_minute}")
        self.voice = voice
        self.words_per_minute = words_per_minute
        self.max_queue = max(1, max_queue)
        self.line_timeout = line_timeout
        self.executable = shutil.which(program) if enabled else None
        self.spoken = 0
        self.dropped = 0
        self.failed = 0
        self._lines: deque[str] = deque()
        self._wake: asyncio.Event | None = None
        self._task: asyncio.Task[None] | None = None

    @property
    def available(self) -> bool:
        """True when lines are really spoken (the program was found and speech is enabled)."""
        return self.executable is not None

    def argv(self) -> list[str]:
        """The synthesiser's command line (the text goes to its standard input)."""
        if self.executable is None:
            raise RuntimeError("no speech synthesiser: install espeak-ng or run with --no-speech")
        argv = [self.executable]
        if self.voice:
            argv += ["-v", self.voice]
        if self.words_per_minute:
            argv += ["-s", str(self.words_per_minute)]
        return [*argv, "--stdin"]

    def start(self) -> None:
        """Start the speaking task (call in the event loop; without a synthesiser it does nothing)."""
        if self.available and self._task is None:
            self._wake = asyncio.Event()
            self._task = asyncio.get_running_loop().create_task(self._run(), name="speech")

    def say(self, text: str) -> None:
        """Queue a line; returns at once."""
        text = " ".join(text.split())
        if not text or not self.available:
            return
        if len(self._lines) >= self.max_queue:
            self._lines.popleft()
            self.dropped += 1
        self._lines.append(text)
        if self._wake is not None:
            self._wake.set()

    async def drain(self, timeout: float = 10.0) -> bool:
        """Wait until every queued line was spoken (True) or ``timeout`` seconds pass (False)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while self._task is not None and (self._lines or self._busy):
            if loop.time() > deadline:
                return False
            await asyncio.sleep(0.02)
        return True

    _busy = False

    async def _run(self) -> None:
        assert self._wake is not None
        while True:
            if not self._lines:
                self._wake.clear()
                await self._wake.wait()
                continue
            text = self._lines.popleft()
            self._busy = True
            try:
                await self._speak(text)
            finally:
                self._busy = False

    async def _speak(self, text: str) -> None:
        try:
            proc = await asyncio.create_subprocess_exec(
                *self.argv(),
                stdin=asyncio.subprocess.PIPE,
                stdout=asyncio.subprocess.DEVNULL,
                stderr=asyncio.subprocess.PIPE,
            )
        except OSError as exc:
            self.failed += 1
            log.warning("cannot run %s: %s", self.executable, exc)
            return
        try:
            _, err = await asyncio.wait_for(proc.communicate(text.encode("utf-8")), self.line_timeout)
        except TimeoutError:
            self.failed += 1
            log.warning(
                "%s took longer than %.0f s for one line; stopped it", self.executable, self.line_timeout
            )
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()
            return
        except asyncio.CancelledError:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()
            raise
        if proc.returncode:
            self.failed += 1
            log.warning(
                "%s failed (exit %s): %s",
                self.executable,
                proc.returncode,
                err.decode(errors="replace")[:200],
            )
        else:
            self.spoken += 1

    async def close(self, timeout: float = 5.0) -> None:
        """Let queued lines finish for up to ``timeout`` seconds, then stop the task."""
        if self._task is None:
            return
        await self.drain(timeout)
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task
        self._task = None
