"""The import graph runs down the layers of docs/architecture.md.

Every ``import`` in the shipped packages and in ``tools/`` is read from the source (function
bodies included; ``if TYPE_CHECKING:`` blocks are types only and skipped) and checked against
the layer order below. A module may import its own component and any component *below* it;
two components on the same rank do not import each other. A second test imports the pure
core in a fresh interpreter and checks that no transport or device library came with it.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from agent.datasets import REPO

#: Components, lowest first; a component may import the components of lower ranks.
RANKS: tuple[tuple[str, ...], ...] = (
    # knowledge: the pure core, by the book's chapters
    ("knowledge",),  # errors, file I/O helpers, label codes, the schema vocabulary
    ("knowledge.metric", "knowledge.learning"),
    ("knowledge.places", "knowledge.people", "knowledge.objects"),
    ("knowledge.navigation", "knowledge.localization"),
    ("knowledge.topology",),
    ("knowledge.conceptual",),
    ("knowledge.evaluation",),
    # devices and their twins
    ("drivers",),
    ("drivers.sick", "drivers.camera"),
    ("drivers.sim",),
    # the simulated worlds
    ("sim",),
    # the agent: the pure core first, then the runtime
    ("agent.base",),
    ("agent.core",),
    ("agent.training",),  # the bundled place models: generated buildings, the real log through core
    ("agent.bus",),
    ("agent.recording", "agent.live"),
    ("agent.ros2",),
    ("agent.config",),
    ("agent.conversation", "agent.dialogue"),
    ("agent.runtime",),
    ("agent.demo",),  # the guided tour and the simulated robot's node
    ("agent.commands",),
    ("tools",),
)
RANK = {c: i for i, comp in enumerate(RANKS) for c in comp}

#: Modules at the top of ``agent/`` that are plain helpers (no session, no device).
AGENT_BASE = {"agent", "agent.tables", "agent.ratelog", "agent.datasets", "agent.progress"}
#: The robot-side process modules at the top of ``agent/``.
AGENT_RUNTIME = {
    "agent.runtime",
    "agent.supervisor",
    "agent.conceptual_service",
    "agent.people_tracks",
}
PACKAGES = ("knowledge", "drivers", "sim", "agent", "tools")


def component(module: str) -> str | None:
    """The component of a first-party module, ``None`` for anything else."""
    parts = module.split(".")
    if parts[0] not in PACKAGES:
        return None
    if parts[0] == "agent":
        name = ".".join(parts[:2])
        if name in AGENT_BASE or module == "agent":
            return "agent.base"
        if name == "agent.sim_node":
            return "agent.demo"
        if name == "agent.cli":
            return "agent.commands"
        if name in AGENT_RUNTIME:
            return "agent.runtime"
        return name  # a subpackage, agent.config, or a new module RANKS must place
    if parts[0] in ("knowledge", "drivers") and len(parts) >= 2 and (REPO / parts[0] / parts[1]).is_dir():
        return ".".join(parts[:2])
    return parts[0]


def module_name(path: Path) -> str:
    rel = path.relative_to(REPO).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _imports(tree: ast.AST) -> Iterator[tuple[int, str]]:
    """``(line, module)`` of every absolute import, skipping ``if TYPE_CHECKING:`` bodies."""
    stack: list[ast.AST] = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            stack.extend(node.orelse)
            continue
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            for alias in node.names:
                # "from knowledge.topology import persistence" imports the module below
                full = f"{node.module}.{alias.name}"
                yield node.lineno, full if _is_module(full) else node.module
        stack.extend(ast.iter_child_nodes(node))


def _is_module(name: str) -> bool:
    p = REPO / Path(*name.split("."))
    return p.with_suffix(".py").is_file() or (p / "__init__.py").is_file()


def sources() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (REPO / pkg).rglob("*.py") if "__pycache__" not in p.parts)


def violations() -> list[str]:
    found = []
    for path in sources():
        src = module_name(path)
        src_comp = component(src)
        assert src_comp is not None and src_comp in RANK, f"{src} has no layer ({src_comp}); add it to RANKS"
        for line, target in _imports(ast.parse(path.read_text(encoding="utf-8"))):
            dst = component(target)
            if dst is None or dst == src_comp:
                continue
            assert dst in RANK, f"{target} has no layer ({dst}); add it to RANKS"
            if RANK[dst] >= RANK[src_comp]:
                found.append(
                    f"{path.relative_to(REPO)}:{line}: {src_comp} imports {target} ({dst}), "
                    f"which is not below it"
                )
    return found


@pytest.mark.slow
def test_imports_point_down_the_layers() -> None:
    assert sources(), "no sources found"
    bad = violations()
    assert not bad, "imports against the layers:\n" + "\n".join(bad)


def test_the_check_sees_an_upward_import(tmp_path: Path) -> None:
    """The rule can fail: an import of topology from places is reported, one of metric is not."""
    tree = ast.parse(
        "from knowledge.metric.grid import OccupancyGrid\n"
        "def f():\n    from knowledge.topology.areas import AreaMap\n"
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from agent.config import AgentConfig\n"
    )
    targets = [component(t) for _, t in _imports(tree)]
    assert "knowledge.metric" in targets and "knowledge.topology" in targets
    assert "agent.config" not in targets
    assert RANK["knowledge.topology"] > RANK["knowledge.places"] > RANK["knowledge.metric"]


#: The pure core's entry points, and the libraries none of them may load.
CORE = ("knowledge.places.model", "knowledge.topology.pipeline", "agent.core.pipeline", "agent.core.mapviz")
IO_LIBRARIES = ("zenoh", "serial", "serial_asyncio_fast", "mcap", "foxglove", "websockets", "owlready2")


def test_the_core_loads_no_transport_or_device() -> None:
    """The pure core opens nothing: no Zenoh, serial port, recording, reasoner or viewer comes with it."""
    code = (
        "import importlib, json, sys\n"
        f"bad = {IO_LIBRARIES!r}\n"
        "out = {}\n"
        f"for m in {CORE!r}:\n"
        "    importlib.import_module(m)\n"
        "    out[m] = [b for b in bad if b in sys.modules]\n"
        "print(json.dumps(out))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    loaded = json.loads(proc.stdout)
    assert set(loaded) == set(CORE)
    assert all(not libs for libs in loaded.values()), f"the core loads {loaded}"
