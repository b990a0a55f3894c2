"""Names of the single-valued scan features: families, parameters, the default grid.

A feature name is a family id (the book's numbering of Appendix A and B) followed, for the
parameterised families, by its parameters in brackets with their units::

    A.1   A.3[maxrange=5m]   A.7[gap=0.5m]   A.8[w=10,eps=0.02m]   A.15[ratio=1.5]
    B.6[n=-3]   B.9[phi=1]   B.7/B.8

``B.7/B.8`` is Ma/Mi, item 9 of set B in Sect. 3.4, which Appendix B does not number.
The family ids follow the *appendix* numbering (B.12 is the form factor 4πA/√P, B.14 the
normalised circularity 4πA/P²), which differs from the Sect. 3.4 list after B.8.

:func:`default_feature_names` is the book's "more than 300 simple features": every family,
the parameterised ones on the grids below. Any other parameter value that passes the
family's checks is accepted as well (``A.7[gap=0.33m]``).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache

#: Max-range thresholds θ of A.3/A.4 (metres).
MAXRANGE_GRID = (1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0, 12.0, 15.0, 20.0, 25.0)
#: Gap thresholds θ of A.7 (metres).
GAP_GRID = (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0)
#: Relative-gap thresholds θ of A.15 (dimensionless, d[i] / d[i+1] > θ).
RATIO_GRID = (1.05, 1.1, 1.15, 1.2, 1.25, 1.3, 1.4, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0, 5.0)
#: Line windows of A.8: window lengths w (beams) × RMS residual bounds ε (metres).
LINE_WINDOW_GRID = (5, 10, 20)
LINE_EPS_GRID = (0.01, 0.02, 0.05, 0.1)
#: Fourier orders of B.6: n = -1, 2, -2, 3, -3, ..., 100, -100, 101 (200 descriptors; n = 0
#: depends on the robot's position in the shape and |c_1|/|c_1| = 1, so both are left out).
FOURIER_ORDERS = tuple(n for k in range(1, 102) for n in (k, -k) if n not in (1, -101))
#: The largest |n| accepted for B.6.
MAX_FOURIER_ORDER = 1000


@dataclass(frozen=True)
class Param:
    """One parameter of a family: its key, unit suffix ('' if none) and value check."""

    key: str
    unit: str
    integer: bool
    check: Callable[[float], bool]
    rule: str


@dataclass(frozen=True)
class Family:
    """A feature family: id, the kernel group computing it, parameters and description.

    ``text`` is a format string over the parameter keys; ``unit`` the unit of the value.
    """

    id: str
    group: str
    text: str
    unit: str
    params: tuple[Param, ...] = ()


@dataclass(frozen=True)
class FeatureSpec:
    """A parsed feature name: family id and parameter values in the family's order."""

    name: str
    family: str
    params: tuple[float, ...]


def _positive(v: float) -> bool:
    return v > 0


_MAXRANGE = Param("maxrange", "m", False, _positive, "a positive length in metres")
_GAP = Param("gap", "m", False, lambda v: v >= 0, "a length ≥ 0 in metres")
_RATIO = Param("ratio", "", False, _positive, "a positive ratio (usually > 1)")
_WINDOW = Param("w", "", True, lambda v: v >= 3, "an integer number of beams ≥ 3")
_EPS = Param("eps", "m", False, lambda v: v >= 0, "a length ≥ 0 in metres")
_ORDER = Param(
    "n",
    "",
    True,
    lambda v: v not in (0, 1) and abs(v) <= MAX_FOURIER_ORDER,
    f"an integer other than 0 and 1 with |n| ≤ {MAX_FOURIER_ORDER}",
)
_PHI = Param("phi", "", True, lambda v: 1 <= v <= 7, "an integer from 1 to 7")

_FAMILIES = (
    Family("A.1", "diff", "average |d[i] − d[i+1]| of consecutive beams", "m"),
    Family("A.2", "diff", "standard deviation of |d[i] − d[i+1]| of consecutive beams", "m"),
    Family(
        "A.3",
        "clipped",
        "average |d[i] − d[i+1]| of consecutive beams clipped at max-range {maxrange} m",
        "m",
        (_MAXRANGE,),
    ),
    Family(
        "A.4",
        "clipped",
        "standard deviation of |d[i] − d[i+1]| of consecutive beams clipped at max-range {maxrange} m",
        "m",
        (_MAXRANGE,),
    ),
    Family("A.5", "beams", "average beam length", "m"),
    Family("A.6", "beams", "standard deviation of the beam length", "m"),
    Family(
        "A.7", "gaps", "number of gaps: consecutive beams differing by more than {gap} m", "count", (_GAP,)
    ),
    Family(
        "A.8",
        "lines",
        "number of beams on lines: beams inside a window of {w} consecutive hits whose end points "
        "fit a line with RMS orthogonal residual ≤ {eps} m",
        "count",
        (_WINDOW, _EPS),
    ),
    Family("A.9", "minima", "Euclidean distance between the end points of the two lowest local minima", "m"),
    Family("A.10", "minima", "angle between the beams of the two lowest local minima", "rad, 0..π"),
    Family("A.11", "ratio", "average ratio d[i] / d[i+1] of consecutive beams", "1"),
    Family("A.12", "ratio", "standard deviation of the ratio d[i] / d[i+1] of consecutive beams", "1"),
    Family("A.13", "beams", "average beam length normalised by the longest beam", "1"),
    Family("A.14", "beams", "standard deviation of the beam length normalised by the longest beam", "1"),
    Family(
        "A.15",
        "rgaps",
        "number of relative gaps: consecutive beams with d[i] / d[i+1] > {ratio}",
        "count",
        (_RATIO,),
    ),
    Family("A.16", "beams", "kurtosis of the beam lengths (excess, −3 for a constant scan)", "1"),
    Family("B.1", "shape", "area of the polygon Pol(z)", "m²"),
    Family("B.2", "shape", "perimeter of Pol(z)", "m"),
    Family("B.3", "shape", "area of Pol(z) divided by its perimeter", "m"),
    Family("B.4", "shape", "mean distance between the centroid and the vertices of Pol(z)", "m"),
    Family(
        "B.5",
        "shape",
        "standard deviation of the distances between the centroid and the vertices of Pol(z)",
        "m",
    ),
    Family(
        "B.6",
        "fourier",
        "Fourier descriptor |c_n| / |c_1| of Pol(z) for n = {n} (similarity invariant)",
        "1",
        (_ORDER,),
    ),
    Family(
        "B.7",
        "fourier",
        "major semi-axis |c_1| + |c_-1| of the ellipse of the first Fourier coefficients",
        "m",
    ),
    Family(
        "B.8",
        "fourier",
        "minor semi-axis ||c_1| − |c_-1|| of the ellipse of the first Fourier coefficients",
        "m",
    ),
    Family(
        "B.7/B.8",
        "fourier",
        "Ma/Mi: ratio of the ellipse's major to minor axis (Sect. 3.4, set B item 9)",
        "1",
    ),
    Family("B.9", "hu", "Hu invariant φ{phi} of the vertex moments of Pol(z)", "1", (_PHI,)),
    Family("B.10", "shape", "compactness: area / (μ20 + μ02) of Pol(z)", "1/M"),
    Family("B.11", "shape", "eccentricity √((μ20 − μ02)² + 4μ11²) / (μ20 + μ02) of Pol(z)", "1"),
    Family("B.12", "shape", "form factor 4πA/√P of Pol(z), as printed in (B.44)", "m^1.5"),
    Family("B.13", "shape", "circularity P²/A of Pol(z)", "1"),
    Family("B.14", "shape", "normalised circularity 4πA/P² of Pol(z) (1 for a circle)", "1"),
    Family("B.15", "shape", "mean centroid–vertex distance of Pol(z) normalised by the largest one", "1"),
    Family("B.16", "shape", "standard deviation of the normalised centroid–vertex distances of Pol(z)", "1"),
)
FAMILIES: dict[str, Family] = {f.id: f for f in _FAMILIES}

_NAME = re.compile(r"^(?P<family>[AB]\.\d+(?:/B\.8)?)(?:\[(?P<params>[^\[\]]*)\])?$")
_PARAM = re.compile(r"^\s*(?P<key>[a-z]+)\s*=\s*(?P<value>[-+0-9.eE]+)\s*(?P<unit>[a-z]*)\s*$")


def format_number(v: float) -> str:
    """The shortest text of ``v`` used in canonical names (``0.5``, ``10``, ``-3``)."""
    return f"{v:g}"


def format_name(family: str, params: Sequence[float] = ()) -> str:
    """The canonical name of ``family`` with ``params`` (in the family's order)."""
    fam = FAMILIES[family]
    if not fam.params:
        return fam.id
    inner = ",".join(f"{p.key}={format_number(v)}{p.unit}" for p, v in zip(fam.params, params, strict=True))
    return f"{fam.id}[{inner}]"


def _parse(name: str) -> FeatureSpec | str:
    """The spec of ``name`` or a short reason why it is not a feature name."""
    if not isinstance(name, str):
        return f"not a string ({type(name).__name__})"
    m = _NAME.match(name)
    if m is None or m.group("family") not in FAMILIES:
        return "unknown family"
    fam = FAMILIES[m.group("family")]
    raw = m.group("params")
    if not fam.params:
        return FeatureSpec(name, fam.id, ()) if raw is None else f"{fam.id} takes no parameters"
    if raw is None:
        keys = ",".join(f"{p.key}=…{p.unit}" for p in fam.params)
        return f"{fam.id} needs parameters [{keys}]"
    given: dict[str, float] = {}
    for part in raw.split(","):
        pm = _PARAM.match(part)
        if pm is None:
            return f"cannot read parameter {part.strip()!r}"
        key = pm.group("key")
        param = next((p for p in fam.params if p.key == key), None)
        if param is None:
            return f"{fam.id} has no parameter {key!r}"
        if pm.group("unit") != param.unit:
            return f"{key} takes unit {param.unit or 'none'!r}, got {pm.group('unit') or 'none'!r}"
        try:
            value = float(pm.group("value"))
        except ValueError:
            return f"{key}: {pm.group('value')!r} is not a number"
        if param.integer and value != int(value):
            return f"{key} must be {param.rule}"
        if not (value == value and abs(value) != float("inf") and param.check(value)):
            return f"{key} must be {param.rule}"
        if key in given:
            return f"{key} given twice"
        given[key] = value
    missing = [p.key for p in fam.params if p.key not in given]
    if missing:
        return f"{fam.id} needs {', '.join(missing)}"
    return FeatureSpec(name, fam.id, tuple(given[p.key] for p in fam.params))


@cache
def parse_name(name: str) -> FeatureSpec:
    """The spec of a feature name; ValueError (with the reason) for an unknown one."""
    spec = _parse(name)
    if isinstance(spec, str):
        raise ValueError(f"unknown feature name {name!r}: {spec}")
    return spec


def validate_feature_names(names: Sequence[str]) -> None:
    """Check every name; one ValueError listing every unknown name and why.

    Raises:
        ValueError: if ``names`` is empty, a plain string, or holds unknown names.
    """
    if isinstance(names, str):
        raise ValueError(f"feature names must be a sequence of names, not the string {names!r}")
    names = list(names)
    if not names:
        raise ValueError("no feature names given; use default_feature_names() for the full family")
    bad = [(n, r) for n in names if isinstance(r := _parse(n), str)]
    if bad:
        listed = "; ".join(f"{n!r} ({r})" for n, r in bad)
        raise ValueError(
            f"{len(bad)} unknown feature name(s): {listed}. Names look like 'A.1', 'A.7[gap=0.5m]', "
            "'B.6[n=-3]'; default_feature_names() lists the full family"
        )


def default_feature_names() -> list[str]:
    """The full feature family in a stable order (309 names, App. A then App. B)."""
    return list(_default_names())


@cache
def _default_names() -> tuple[str, ...]:
    grid: dict[str, list[tuple[float, ...]]] = {
        "A.3": [(t,) for t in MAXRANGE_GRID],
        "A.4": [(t,) for t in MAXRANGE_GRID],
        "A.7": [(t,) for t in GAP_GRID],
        "A.8": [(w, e) for w in LINE_WINDOW_GRID for e in LINE_EPS_GRID],
        "A.15": [(t,) for t in RATIO_GRID],
        "B.6": [(n,) for n in FOURIER_ORDERS],
        "B.9": [(k,) for k in range(1, 8)],
    }
    names: list[str] = []
    for fam in _FAMILIES:
        for params in grid.get(fam.id, [()]):
            names.append(format_name(fam.id, params))
    return tuple(names)


def describe(name: str) -> str:
    """Human text for a feature name, e.g. ``"A.7[gap=0.5m]: number of gaps: ... (count)"``."""
    spec = parse_name(name)
    fam = FAMILIES[spec.family]
    values = {p.key: format_number(v) for p, v in zip(fam.params, spec.params, strict=True)}
    return f"{name}: {fam.text.format(**values)} [{fam.unit}]"
