"""The docs name code that exists.

Every repository path (``knowledge/places/labeling.py``, ``tools/``, ``tests/test_x.py``),
every dotted module or name (``sim.world.load_world``, ``python -m tools.bench_sick``) and
every relative link in ``README.md`` and ``docs/*.md`` must resolve; on a package's own page
(its title starts with the package, ``# knowledge/places — ...``) a bare ``module.py`` in
backticks is looked up inside that package (a bare ``test_x.py`` anywhere under ``tests/``). ``docs/results/`` holds dated outputs and is not
read. Names after a module are looked up in its source (definitions, assignments, imports),
so a class that moved is found as well as a module that moved.
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import pytest

from agent.datasets import REPO

#: top-level folders a path in the docs may start with
TOP = ("agent", "knowledge", "drivers", "sim", "tools", "tests", "deploy", "ontology", "docs")
#: first-party packages a dotted name may start with
PACKAGES = ("agent", "knowledge", "drivers", "sim", "tools")
#: words that stand for a name in a pattern (``tools/NAME.py``, ``python -m tools.X``)
PLACEHOLDERS = {"NAME", "FILE", "DIR", "PATH", "OUT", "X", "N"}
#: suffixes that make ``agent.toml`` or ``sim.log`` a file name, not a module
FILE_SUFFIXES = {
    "toml",
    "log",
    "json",
    "json5",
    "jsonl",
    "yaml",
    "mcap",
    "png",
    "pgm",
    "npz",
    "md",
    "txt",
    "py",
}

_TOP, _PACKAGES = "|".join(TOP), "|".join(PACKAGES)
PATH = re.compile(rf"(?<![\w/.~$<-])((?:{_TOP})/[\w./-]*)")
DOTTED = re.compile(rf"(?<![\w/.-])((?:{_PACKAGES})(?:\.\w+)+)")
BARE = re.compile(r"`((?:\w+/)*\w+\.py)`")
LINK = re.compile(r"\]\(([^)\s]+)\)")
TITLE_PACKAGE = re.compile(rf"# ((?:{_PACKAGES})(?:/\w+)*) — ")

PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


@functools.cache
def defined_names(path: Path) -> frozenset[str]:
    """Names a module defines anywhere in its source: functions, classes, assignments, imports."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif isinstance(node, ast.Import | ast.ImportFrom):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return frozenset(names)


def module_file(parts: list[str]) -> Path | None:
    base = REPO.joinpath(*parts)
    for candidate in (base / "__init__.py", base.with_suffix(".py")):
        if candidate.is_file():
            return candidate
    return None


def dotted_problem(dotted: str) -> str | None:
    """Why ``pkg.module.name`` does not resolve, or None when it does."""
    parts = dotted.split(".")
    if parts[-1] in FILE_SUFFIXES:
        return None
    for k in range(len(parts), 0, -1):
        found = module_file(parts[:k])
        if found is None:
            continue
        rest = parts[k:]
        if not rest or rest[0] in defined_names(found) or rest[0] in PLACEHOLDERS:
            return None
        return f"{'.'.join(parts[:k])} ({found.relative_to(REPO)}) defines no {rest[0]!r}"
    return "no such module"


def page_problems(page: Path) -> list[str]:
    """What ``page`` names that does not exist, one line each (``page:line: what``)."""
    text = page.read_text(encoding="utf-8")
    label = page.relative_to(REPO) if page.is_relative_to(REPO) else page.name
    title = TITLE_PACKAGE.match(text)
    package = REPO / title.group(1) if title else None
    problems = []
    for number, line in enumerate(text.splitlines(), 1):
        where = f"{label}:{number}"
        for m in PATH.finditer(line):
            path = m.group(1).split("::")[0].rstrip(".")
            stems = {part.split(".")[0] for part in path.split("/")}
            if line[m.end() : m.end() + 1] in ("*", "{", "<") or "*" in path or stems & PLACEHOLDERS:
                continue  # a pattern: docs/results/topology_*, buildings_*.py, tools/NAME.py
            if "." not in Path(path).name and not path.endswith("/"):
                continue  # a bus key such as sim/truth, not a file
            if not (REPO / path).exists() and not (package and (package / path).exists()):
                problems.append(f"{where}: {path} does not exist")
        for m in DOTTED.finditer(line):
            why = dotted_problem(m.group(1))
            if why:
                problems.append(f"{where}: {m.group(1)}: {why}")
        if package is not None:
            for m in BARE.finditer(line):
                name = m.group(1)
                if name.split("/")[0] in TOP:
                    continue
                home = REPO / "tests" if Path(name).name.startswith("test_") else package
                if not (package / name).exists() and not any(home.rglob(name)):
                    problems.append(f"{where}: {name} is not in {package.relative_to(REPO)}/")
        for m in LINK.finditer(line):
            target = m.group(1).split("#")[0]
            if not target or re.match(r"[a-z]+:", target):
                continue
            if not (page.parent / target).exists():
                problems.append(f"{where}: the link {target} leads nowhere")
    return problems


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_the_docs_name_code_that_exists(page: Path) -> None:
    problems = page_problems(page)
    assert not problems, "\n".join(problems)


def test_the_check_finds_what_moved(tmp_path: Path) -> None:
    page = tmp_path / "old.md"
    page.write_text(
        "# old\n`knowledge/places/boosting.py`, `agent.pipeline.Pipeline`, `python -m agent.tools.bench`,\n"
        "`sim.world.no_such_name`, [a link](nowhere.md); fine: `knowledge/learning/boosting.py`,\n"
        "`sim.world.load_world`, `agent.toml`, `loci/<r>/sim/truth`, `docs/results/topology_*`\n",
        encoding="utf-8",
    )
    problems = page_problems(page)
    assert len(problems) == 5, problems
    assert problems[0] == "old.md:2: knowledge/places/boosting.py does not exist"
    assert "defines no 'no_such_name'" in problems[3]
    assert problems[4] == "old.md:3: the link nowhere.md leads nowhere"


def test_a_package_page_finds_its_modules_by_their_bare_names(tmp_path: Path) -> None:
    page = tmp_path / "places.md"
    page.write_text(
        "# knowledge/places — x\n| `labeling.py` | `registry.py` | `weak.py` |\n", encoding="utf-8"
    )
    assert page_problems(page) == ["places.md:2: weak.py is not in knowledge/places/"]
