"""One meaning of ``--json`` (docs/tools.md, "JSON output"; agent/commands/options.py).

Every ``loci`` command (walked from :func:`agent.cli.build_parser`, sub-commands included) and
every ``python -m tools.X`` program (its ``build_parser()``) is checked: ``--json`` is a flag
that prints one JSON object, ``--json-lines`` a flag for a stream of records, ``--json-file
FILE`` writes the object to a file; no other option starts with ``--json``. A benchmark is then
run for real both ways.
"""

from __future__ import annotations

import argparse
import importlib
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from agent.cli import build_parser
from agent.datasets import REPO

#: the only options that start with --json
VARIANTS = {"--json", "--json-lines", "--json-file"}
TOOLS = sorted(p.stem for p in (REPO / "tools").glob("*.py") if p.stem != "__init__")


def _walk(parser: argparse.ArgumentParser, name: str) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """``parser`` and every sub-command's parser below it, with the command line that reaches it."""
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub, p in action.choices.items():
                yield from _walk(p, f"{name} {sub}")


def _tool_parser(name: str) -> argparse.ArgumentParser:
    module = importlib.import_module(f"tools.{name}")
    assert hasattr(module, "build_parser"), f"tools/{name}.py has main() but no build_parser()"
    parser = module.build_parser()
    assert isinstance(parser, argparse.ArgumentParser)
    return parser


def _parsers() -> Iterator[tuple[str, argparse.ArgumentParser]]:
    yield from _walk(build_parser(), "loci")
    for name in TOOLS:
        yield f"python -m tools.{name}", _tool_parser(name)


def _json_problems(where: str, parser: argparse.ArgumentParser) -> list[str]:
    problems = []
    for action in parser._actions:
        for opt in action.option_strings:
            if not opt.startswith("--json"):
                continue
            if opt not in VARIANTS:
                problems.append(f"{where}: {opt} is not one of {sorted(VARIANTS)}")
            elif opt in ("--json", "--json-lines") and not isinstance(action, argparse._StoreTrueAction):
                problems.append(f"{where}: {opt} takes a value; it must be a flag (store_true)")
            elif opt == "--json-file" and (
                not isinstance(action, argparse._StoreAction)
                or action.nargs is not None
                or action.type is not Path
            ):
                problems.append(f"{where}: --json-file must take exactly one FILE (a Path)")
    return problems


def test_every_tool_with_a_main_builds_its_parser_apart() -> None:
    for name in TOOLS:
        module = importlib.import_module(f"tools.{name}")
        if hasattr(module, "main"):
            _tool_parser(name)


def test_json_options_mean_one_thing_in_every_parser() -> None:
    seen: dict[str, int] = {opt: 0 for opt in VARIANTS}
    problems = []
    for where, parser in _parsers():
        problems += _json_problems(where, parser)
        for opt in VARIANTS:
            seen[opt] += opt in parser._option_string_actions
    assert not problems, "\n".join(problems)
    # the walk reached the commands and programs that have them (so an empty walk cannot pass)
    assert seen["--json"] >= 20 and seen["--json-file"] >= 12 and seen["--json-lines"] >= 1, seen


def test_the_check_refuses_the_old_spellings() -> None:
    old = argparse.ArgumentParser(prog="old")
    old.add_argument("--json", type=Path, metavar="FILE")
    old.add_argument("--json-out", action="store_true")
    optional = argparse.ArgumentParser(prog="optional")
    optional.add_argument("--json", nargs="?", const="-")
    optional.add_argument("--json-file", nargs="?")
    problems = _json_problems("old", old) + _json_problems("optional", optional)
    assert len(problems) == 4, problems


@pytest.fixture(scope="module")
def bench_sick_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, str, Path]:
    """``python -m tools.bench_sick`` with ``--json`` and with ``--json-file`` (a small buffer)."""
    out = tmp_path_factory.mktemp("bench") / "deep" / "sick.json"
    cmd = [sys.executable, "-m", "tools.bench_sick", "--telegrams", "50"]
    as_json = subprocess.run(
        [*cmd, "--json"], cwd=REPO, capture_output=True, text=True, timeout=120, check=True
    )
    as_text = subprocess.run(
        [*cmd, "--json-file", str(out)], cwd=REPO, capture_output=True, text=True, timeout=120, check=True
    )
    return as_json.stdout, as_text.stdout, out


def test_a_benchmark_prints_one_object_with_json_and_writes_it_with_json_file(
    bench_sick_runs: tuple[str, str, Path],
) -> None:
    printed, text, path = bench_sick_runs
    obj = json.loads(printed)  # the whole of stdout is one JSON object
    assert isinstance(obj, dict) and obj["telegrams"] == 50
    assert text.startswith("LMS codec, 50 telegrams") and "{" not in text
    written = json.loads(path.read_text(encoding="utf-8"))
    assert set(written) == set(obj) and written["telegrams"] == 50
