"""Speech through a real subprocess: a stand-in synthesiser script that records what it was asked to say."""

from __future__ import annotations

import asyncio
import stat
from pathlib import Path

import pytest

from agent.dialogue.speech import Speech


def _synthesiser(
    tmp_path: Path, body: str = 'printf "%s|" "$*" >> "$0.args"; cat >> "$0.said"; echo >> "$0.said"'
) -> Path:
    program = tmp_path / "say-it"
    program.write_text("#!/bin/sh\n" + body + "\n", encoding="utf-8")
    program.chmod(program.stat().st_mode | stat.S_IXUSR)
    return program


def test_lines_are_spoken_in_order_with_the_text_on_stdin(tmp_path: Path) -> None:
    program = _synthesiser(tmp_path)

    async def main() -> Speech:
        speech = Speech(program=str(program), voice="en-us+f3", words_per_minute=150)
        assert speech.available
        speech.start()
        speech.say("I am in the living room.")
        speech.say("  ")  # nothing to say
        speech.say("-v de; rm -rf / `whoami`")  # text is never an argument
        assert await speech.drain(5.0)
        await speech.close()
        return speech

    speech = asyncio.run(main())
    said = (tmp_path / "say-it.said").read_text().splitlines()
    assert said == ["I am in the living room.", "-v de; rm -rf / `whoami`"]
    args = (tmp_path / "say-it.args").read_text().split("|")[:-1]
    assert args == ["-v en-us+f3 -s 150 --stdin"] * 2
    assert (speech.spoken, speech.failed, speech.dropped) == (2, 0, 0)


def test_failures_and_overflow_are_counted_not_raised(tmp_path: Path) -> None:
    program = _synthesiser(tmp_path, "cat > /dev/null; exit 3")

    async def main() -> Speech:
        speech = Speech(program=str(program), max_queue=2)
        speech.start()
        for i in range(5):  # the queue holds 2: the oldest waiting lines are dropped
            speech.say(f"line {i}")
        await speech.close(5.0)
        return speech

    speech = asyncio.run(main())
    assert speech.spoken == 0
    assert speech.failed + speech.dropped == 5 and speech.dropped >= 2


def test_a_line_that_hangs_is_cut_off(tmp_path: Path) -> None:
    program = _synthesiser(tmp_path, "exec sleep 30")

    async def main() -> Speech:
        speech = Speech(program=str(program), line_timeout=0.3)
        speech.start()
        speech.say("hello")
        assert await speech.drain(5.0)
        await speech.close()
        return speech

    assert asyncio.run(main()).failed == 1


def test_without_a_synthesiser_nothing_is_spoken(tmp_path: Path) -> None:
    missing = Speech(program=str(tmp_path / "no-such-program"))
    disabled = Speech(program=str(_synthesiser(tmp_path)), enabled=False)
    for speech in (missing, disabled):
        assert not speech.available
        speech.say("hello")  # no error, no queue
        with pytest.raises(RuntimeError, match="espeak-ng"):
            speech.argv()


@pytest.mark.parametrize("voice", ["en us", "en;rm", "", "x" * 65])
def test_bad_voice_names_are_refused(voice: str) -> None:
    with pytest.raises(ValueError, match="voice"):
        Speech(voice=voice)


def test_espeak_ng_when_installed() -> None:
    speech = Speech()
    if not speech.available:
        pytest.skip("espeak-ng is not installed")
    assert Path(speech.argv()[0]).name.startswith("espeak")
