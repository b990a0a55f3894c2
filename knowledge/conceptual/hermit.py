"""Running the HermiT reasoner (bundled with owlready2) on an N-Triples file.

We call HermiT ourselves instead of ``owlready2.sync_reasoner`` so that the Java path is per
map (no module global), the results are returned instead of being written into the world
(the conceptual map writes them into its own *inferred* ontology), and Python's cached
entities are never re-parented behind our back. One call starts one JVM (≈0.5–1.4 s).
"""

from __future__ import annotations

import os
import re
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import owlready2  # type: ignore[import-untyped]

from knowledge.conceptual.errors import InconsistentKnowledge, ReasonerError

_HERMIT_DIR = Path(owlready2.__file__).parent / "hermit"
CLASSPATH = os.pathsep.join((str(_HERMIT_DIR), str(_HERMIT_DIR / "HermiT.jar")))
NOTHING = "http://www.w3.org/2002/07/owl#Nothing"
_OWL = "http://www.w3.org/2002/07/owl#"
_LINE = re.compile(r"^(SubClassOf|EquivalentClasses|Type)\( ((?:<[^>]+>\s*)+)\)$", re.MULTILINE)
_IRI = re.compile(r"<([^>]+)>")
# small heap, quick start: our ontologies are tiny and the JVM start dominates
JVM_OPTIONS = ("-Xmx512M", "-XX:+UseSerialGC", "-XX:TieredStopAtLevel=1", "-Xshare:auto")


@dataclass
class HermitResult:
    """What HermiT found: direct superclasses, equivalences, direct types of individuals (IRIs)."""

    supers: dict[str, set[str]] = field(default_factory=dict)
    equivalents: dict[str, set[str]] = field(default_factory=dict)
    types: dict[str, set[str]] = field(default_factory=dict)
    unsatisfiable: set[str] = field(default_factory=set)

    def ancestors(self, cls: str) -> set[str]:
        """Every named superclass of ``cls`` (and its equivalents), ``cls`` included; no owl: classes."""
        out: set[str] = set()
        stack = [cls]
        while stack:
            c = stack.pop()
            if c in out or c.startswith(_OWL):
                continue
            out.add(c)
            stack.extend(self.supers.get(c, ()))
            stack.extend(self.equivalents.get(c, ()))
        return out

    def all_types(self, individual: str) -> set[str]:
        """Every named class of ``individual`` (the closure of its direct types)."""
        out: set[str] = set()
        for t in self.types.get(individual, ()):
            out |= self.ancestors(t)
        return out


def parse_output(text: str) -> HermitResult:
    """Parse the output of HermiT's ``-c -I`` (classification and realisation)."""
    res = HermitResult()
    for relation, iris_text in _LINE.findall(text):
        iris = _IRI.findall(iris_text)
        if relation == "SubClassOf" and len(iris) == 2:
            res.supers.setdefault(iris[0], set()).add(iris[1])
        elif relation == "Type" and len(iris) == 2:
            res.types.setdefault(iris[0], set()).add(iris[1])
        elif relation == "EquivalentClasses":
            if NOTHING in iris:
                res.unsatisfiable.update(i for i in iris if not i.startswith(_OWL))
                continue
            for a in iris:
                res.equivalents.setdefault(a, set()).update(b for b in iris if b != a)
    return res


def run_hermit(ntriples: Path, java: str, *, timeout: float = 120.0) -> HermitResult:
    """Classify and realise the ontology in ``ntriples`` with HermiT on the Java at ``java``.

    Raises :class:`InconsistentKnowledge` if the ontology is inconsistent and
    :class:`ReasonerError` if HermiT fails otherwise or takes more than ``timeout`` seconds.
    """
    cmd = [java, *JVM_OPTIONS, "-cp", CLASSPATH, "org.semanticweb.HermiT.cli.CommandLine", "-c", "-I"]
    cmd.append(Path(ntriples).resolve().as_uri())
    try:
        out = subprocess.run(cmd, capture_output=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired as e:
        raise ReasonerError(f"HermiT took more than {timeout:.0f} s") from e
    except OSError as e:
        raise ReasonerError(f"cannot start Java for HermiT ({java}): {e}") from e
    text = (out.stdout + out.stderr).decode("utf-8", "replace")
    if out.returncode != 0:
        if "Inconsistent ontology" in text or "InconsistentOntologyException" in text:
            raise InconsistentKnowledge("the reasoner found the knowledge inconsistent")
        raise ReasonerError(f"HermiT failed (exit {out.returncode}): {text.strip()[-800:]}")
    return parse_output(out.stdout.decode("utf-8", "replace"))
