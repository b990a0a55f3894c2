"""Every ``--help`` page of every ``loci`` command renders (argparse formats help strings
with ``%``: a stray percent sign in one crashes that page, as ``loci localize --help`` did)."""

from __future__ import annotations

import argparse
import contextlib
import io

import pytest

from agent.cli import build_parser


def _pages(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
) -> list[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """``(command path, parser)`` for the parser and every sub-command below it."""
    out = [(path, parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out += _pages(sub, (*path, name))
    return out


PAGES = _pages(build_parser())


def test_the_tree_has_every_command_group() -> None:
    names = {p[0] for p, _ in PAGES if p}
    assert {"run", "replay", "localize", "demo", "places", "people", "sim", "import"} <= names
    assert len(PAGES) > 30


@pytest.mark.parametrize("path", [p for p, _ in PAGES], ids=lambda p: " ".join(p) or "loci")
def test_every_help_page_renders(path: tuple[str, ...]) -> None:
    parser = build_parser()
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as exc:
        parser.parse_args([*path, "--help"])
    assert exc.value.code == 0
    text = out.getvalue()
    assert text.startswith("usage: ") and len(text) > 40
