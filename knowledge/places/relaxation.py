"""Probabilistic relaxation labeling of a labelled grid map (book Sect. 4.5, eq. 4.6–4.8).

Every cell of an occupancy grid is a node of the 8-connected grid graph and carries a
histogram over the labels ``classes + (wall,)``: the place classes of the classifier (label
codes from :mod:`knowledge.labels`, e.g. room, corridor, doorway, and hallway when the model
has it) followed by *wall* as the **last** column. Free cells start with the classifier's
histogram and ``p(wall) = 0``, every other cell (occupied or unknown) with ``p(wall) = 1``.
Each iteration applies

    q_i(k)       = Σ_j o_ij Σ_k' r_ij(k, k') p_j(k')                       (4.7)
    p_i'(k)      = p_i(k) [1 + q_i(k)] / Σ_k' p_i(k') [1 + q_i(k')]         (4.6)

with ``o_ij = o`` (1/8) for the eight neighbours and compatibilities ``r`` from label
statistics of training maps (eq. 4.8, :class:`CompatibilityStats`).

Consequences worth knowing:

* A cell with ``p(wall) = 1`` stays wall, and a free cell never gains ``p(wall) > 0``
  (eq. 4.6 multiplies, it never creates mass). So only free cells change, and a wall
  neighbour adds the constant ``o · r(k, wall)`` to ``q_i(k)``; :func:`relax` uses that to
  iterate over the free classes only.
* **Map border**: a neighbour outside the map counts as a wall cell (``border="wall"``, the
  default: what lies beyond the map is not free space the classifier saw), or contributes
  nothing (``border="none"``: as if ``o_ij = 0`` for missing neighbours, so border cells
  are smoothed less).
* ``o`` must not exceed 1/8: then ``|q| ≤ 1`` and ``1 + q ≥ 0``, so histograms stay
  non-negative.
* Probabilities that fall below 1e-30 are set to 0 after each iteration (denormal floats
  would otherwise slow every step several times over).

Shared or per-direction compatibilities: the book writes ``r_ij`` for a generic neighbour
pair. By default one matrix ``r(k, k')`` serves all eight neighbours (pair counts pooled over
the eight directions, the book's plainest reading, and it keeps relaxation equivariant under
flips and 90° rotations of the map). ``per_direction=True`` keeps one matrix per direction
``(dr, dc)`` instead (e.g. "a doorway has a room above it"), which ties the statistics to the
axes of the training maps.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np

from knowledge.labels import CLASS_NAMES

#: The eight neighbour offsets ``(dr, dc)`` of a cell, in this fixed order: a neighbour ``j``
#: of cell ``i = (r, c)`` is ``(r + dr, c + dc)``.
DIRECTIONS: np.ndarray = np.array(
    [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)], dtype=np.int64
)
DIRECTIONS.setflags(write=False)

#: Probabilities below this become 0 after each iteration. Left alone they decay into
#: denormal floats, which made iterations 5× slower on real maps; a class at 1e-30 cannot
#: come back within any sensible number of iterations anyway.
_FLUSH = 1e-30

_KERNEL8 = np.ones((3, 3), np.float32)
_KERNEL8[1, 1] = 0.0

Backend = Literal["auto", "cv2", "numpy"]
Border = Literal["wall", "none"]


def compatibility(prior: np.ndarray, conditional: np.ndarray) -> np.ndarray:
    """Compatibility coefficients ``r(k, k')`` of eq. 4.8.

    Args:
        prior: ``(..., K)`` ``p_i(k)``.
        conditional: ``(..., K, K)`` ``p_ij(k | k')``, indexed ``[k, k']``.

    Returns:
        ``(..., K, K)`` float64 ``r(k, k')`` in ``[-1, 1]``: ``(1 - p(k)/p(k|k')) / (1 - p(k))``
        where ``p(k) < p(k|k')``, else ``p(k|k')/p(k) - 1``. Where ``p(k) = 0`` (a label never
        seen) ``r = 0``: no evidence either way.
    """
    p = np.asarray(prior, np.float64)[..., :, None]
    c = np.asarray(conditional, np.float64)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        up = (1.0 - p / c) / (1.0 - p)
        down = c / p - 1.0
    r = np.where(p < c, up, down)
    r = np.where(p > 0, r, 0.0)
    return np.clip(r, -1.0, 1.0)


@dataclass(frozen=True, eq=False)
class CompatibilityStats:
    """Label statistics of training maps and the compatibilities they give (eq. 4.8).

    Attributes:
        classes: label codes of the place classes, in histogram column order; the wall
            label is the extra last column (``K = len(classes) + 1`` labels in all).
        counts: ``(D, K, K)`` float64 counts of ordered neighbour pairs ``(i, j)`` with
            label ``k`` at ``i`` and ``k'`` at ``j``, ``[d, k, k']``. ``D = 1`` (pooled over the
            eight directions) or ``D = 8`` (one per :data:`DIRECTIONS` offset ``j - i``).
        smoothing: pseudo-count added to every pair count before the probabilities are
            taken (0 keeps eq. 4.8's ``r = -1`` for pairs never seen).

    Derived (computed on construction): ``prior`` ``(D, K)`` ``p_i(k)``, the marginal of the
    pair counts over ``i`` (so a label independent of its neighbours gets ``r = 0`` exactly);
    ``conditional`` ``(D, K, K)`` ``p_ij(k | k')``; ``r`` ``(D, K, K)`` float32.
    """

    classes: tuple[int, ...]
    counts: np.ndarray
    smoothing: float = 0.0
    prior: np.ndarray = field(init=False, repr=False)
    conditional: np.ndarray = field(init=False, repr=False)
    r: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        classes = tuple(int(c) for c in self.classes)
        if not classes or len(set(classes)) != len(classes) or min(classes) <= 0 or max(classes) > 255:
            raise ValueError(f"classes must be distinct label codes in 1..255, got {self.classes}")
        K = len(classes) + 1
        counts = np.array(self.counts, dtype=np.float64)
        if counts.ndim == 2:
            counts = counts[None]
        if counts.shape not in ((1, K, K), (8, K, K)):
            raise ValueError(
                f"counts must have shape (1, {K}, {K}) or (8, {K}, {K}) for {len(classes)} classes + wall, "
                f"got {np.shape(self.counts)}"
            )
        if not np.all(np.isfinite(counts)) or (counts < 0).any():
            raise ValueError("pair counts must be finite and non-negative")
        if not (math.isfinite(self.smoothing) and self.smoothing >= 0):
            raise ValueError(f"smoothing must be a non-negative pseudo-count, got {self.smoothing}")
        joint = counts + self.smoothing
        total = joint.sum(axis=(1, 2))
        if (total <= 0).any():
            raise ValueError("no neighbour pairs were counted: train on maps with labelled free cells")
        prior = joint.sum(axis=2) / total[:, None]
        col = joint.sum(axis=1, keepdims=True)  # (D, 1, K'): pairs with label k' at j
        with np.errstate(divide="ignore", invalid="ignore"):
            cond = np.where(col > 0, joint / col, 0.0)
        r = compatibility(prior, cond)
        # a neighbour label never seen carries no evidence (its conditional is undefined)
        r = np.where(col > 0, r, 0.0)
        counts.setflags(write=False)
        for name, value in (
            ("classes", classes),
            ("counts", counts),
            ("smoothing", float(self.smoothing)),
            ("prior", prior),
            ("conditional", cond),
            ("r", r.astype(np.float32)),
        ):
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ properties
    @property
    def n_labels(self) -> int:
        """``K``: the place classes plus wall."""
        return len(self.classes) + 1

    @property
    def per_direction(self) -> bool:
        """True when there is one compatibility matrix per neighbour direction."""
        return int(self.counts.shape[0]) == 8

    @property
    def label_names(self) -> tuple[str, ...]:
        """Names of the ``K`` labels in column order (codes without a standard name as ``"code7"``)."""
        return (*(CLASS_NAMES.get(c, f"code{c}") for c in self.classes), "wall")

    def r_for(self, direction: int) -> np.ndarray:
        """``(K, K)`` ``r(k, k')`` for neighbour ``DIRECTIONS[direction]`` (the same for all when pooled)."""
        return self.r[direction if self.per_direction else 0]

    # ------------------------------------------------------------------ training
    @classmethod
    def from_label_images(
        cls,
        samples: Iterable[tuple[np.ndarray, np.ndarray]],
        classes: Sequence[int],
        *,
        per_direction: bool = False,
        smoothing: float = 0.0,
    ) -> CompatibilityStats:
        """Count neighbour label pairs on training maps.

        Args:
            samples: ``(labels, occupied)`` pairs: a ``(rows, cols)`` integer label image
                (codes, 0 = no label) and a same-shaped bool mask of occupied cells.
            classes: the place classes' label codes, in the classifier's column order.
            per_direction: keep one pair table per neighbour direction (default: pooled).
            smoothing: pseudo-count added to every pair count.

        Which cells count: labelled cells that are not occupied carry their class; occupied
        cells are *wall*, but only where they touch (8-neighbourhood) a labelled free cell.
        Unlabelled free cells (code 0) and unknown cells are ignored, and so are walls
        deeper inside thick walls or outside the building: during relaxation such cells never
        influence a free cell, and counting them would make ``p(wall)`` depend on how much
        margin a map image happens to have. Only pairs of two counted cells are counted.

        Raises:
            ValueError: a label code outside ``classes`` occurs on a free cell (map it to one
                of the classes first, e.g. hallway → corridor for a three-class model).
        """
        classes_t = tuple(int(c) for c in classes)
        K = len(classes_t) + 1
        lut = np.full(256, -2, dtype=np.int64)
        lut[0] = -1
        for idx, code in enumerate(classes_t):
            if not 0 < code <= 255:
                raise ValueError(f"class codes must lie in 1..255, got {code}")
            lut[code] = idx
        counts = np.zeros((8 if per_direction else 1, K, K), dtype=np.float64)
        n_samples = 0
        for labels, occupied in samples:
            n_samples += 1
            lab = np.asarray(labels)
            occ = np.asarray(occupied, dtype=bool)
            if lab.ndim != 2 or lab.shape != occ.shape:
                raise ValueError(
                    f"training sample {n_samples}: labels {lab.shape} and occupied {occ.shape} must be "
                    "same-shaped 2-D arrays"
                )
            if lab.size and (lab.min() < 0 or lab.max() > 255):
                raise ValueError(f"training sample {n_samples}: label codes must lie in 0..255")
            state = lut[lab.astype(np.int64)]
            free_state = state[~occ]
            if (free_state == -2).any():
                unknown = sorted({int(v) for v in np.unique(lab[~occ & (state == -2)])})
                raise ValueError(
                    f"training sample {n_samples}: label codes {unknown} are not among the classes "
                    f"{classes_t}; map them to a class (or to 0) first"
                )
            labelled = (state >= 0) & ~occ
            touches = cv2.dilate(labelled.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
            state = np.where(occ, np.where(touches, K - 1, -1), state)
            state = np.where(state >= 0, state, -1)
            for d, (dr, dc) in enumerate(DIRECTIONS):
                a, b = _pair_views(state, int(dr), int(dc))
                ok = (a >= 0) & (b >= 0)
                pairs = np.bincount((a[ok] * K + b[ok]).ravel(), minlength=K * K).reshape(K, K)
                counts[d if per_direction else 0] += pairs
        if n_samples == 0:
            raise ValueError("no training samples given: pass (labels, occupied) pairs")
        return cls(classes_t, counts, smoothing)

    # ------------------------------------------------------------------ serialisation
    def to_arrays(self, prefix: str = "relaxation_") -> dict[str, np.ndarray]:
        """Plain arrays for an ``.npz`` (no pickle): classes, pair counts and smoothing.

        ``r``, ``prior`` and ``conditional`` are included for readers of the file; they are
        recomputed from the counts on loading.
        """
        return {
            f"{prefix}classes": np.asarray(self.classes, dtype=np.int64),
            f"{prefix}counts": np.array(self.counts),
            f"{prefix}smoothing": np.asarray(self.smoothing, dtype=np.float64),
            f"{prefix}r": np.array(self.r),
            f"{prefix}prior": np.array(self.prior),
            f"{prefix}conditional": np.array(self.conditional),
        }

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray], prefix: str = "relaxation_") -> CompatibilityStats:
        """Inverse of :meth:`to_arrays` (e.g. on an ``np.load(..., allow_pickle=False)`` result)."""
        try:
            classes = tuple(int(c) for c in np.asarray(arrays[f"{prefix}classes"]).ravel())
            counts = np.asarray(arrays[f"{prefix}counts"], dtype=np.float64)
            smoothing = float(np.asarray(arrays[f"{prefix}smoothing"]))
        except KeyError as exc:
            raise ValueError(f"relaxation statistics are missing array {exc.args[0]!r}") from exc
        return cls(classes, counts, smoothing)


def _pair_views(a: np.ndarray, dr: int, dc: int) -> tuple[np.ndarray, np.ndarray]:
    """Views ``(x_i, x_j)`` of all cell pairs with ``j = i + (dr, dc)`` inside the array."""
    rows, cols = a.shape
    ri = slice(max(0, -dr), rows - max(0, dr))
    ci = slice(max(0, -dc), cols - max(0, dc))
    rj = slice(max(0, dr), rows - max(0, -dr))
    cj = slice(max(0, dc), cols - max(0, -dc))
    return a[ri, ci], a[rj, cj]


# ---------------------------------------------------------------------- relaxation
def initial_histograms(
    P0: np.ndarray, free_mask: np.ndarray, stats: CompatibilityStats
) -> tuple[np.ndarray, np.ndarray]:
    """Validate and normalise the classifier's histograms.

    Args:
        P0: ``(rows, cols, K)`` histograms with the wall column last, or ``(rows, cols, K-1)``
            without it; only free cells are read.
        free_mask: ``(rows, cols)`` bool.

    Returns:
        ``(P, free)``: ``(rows, cols, K-1)`` float32 place-class probabilities, each free row
        summing to 1 (a free row of all zeros becomes uniform), zero elsewhere; and the bool mask.
    """
    P = np.asarray(P0)
    free = np.asarray(free_mask, dtype=bool)
    Kf = len(stats.classes)
    if P.ndim != 3 or P.shape[2] not in (Kf, Kf + 1):
        raise ValueError(
            f"histograms must have shape (rows, cols, {Kf + 1}) (classes {stats.classes} then wall) "
            f"or (rows, cols, {Kf}), got {P.shape}"
        )
    if free.shape != P.shape[:2]:
        raise ValueError(f"free_mask {free.shape} must match the histograms' grid {P.shape[:2]}")
    out = np.zeros((*P.shape[:2], Kf), dtype=np.float32)
    vals = P[free, :Kf].astype(np.float32)
    if not np.all(np.isfinite(vals)) or (vals < 0).any():
        raise ValueError("histograms of free cells must be finite and non-negative")
    s = vals.sum(axis=1, keepdims=True)
    vals = np.where(s > 0, vals / np.where(s > 0, s, 1), np.float32(1.0 / Kf))
    out[free] = vals
    return out, free


def relax(
    P0: np.ndarray,
    stats: CompatibilityStats,
    *,
    free_mask: np.ndarray,
    iterations: int = 50,
    o: float = 1.0 / 8.0,
    border: Border = "wall",
    backend: Backend = "auto",
) -> np.ndarray:
    """Run probabilistic relaxation (eq. 4.6–4.7) over the whole grid.

    Args:
        P0: ``(rows, cols, K)`` initial histograms, columns ``stats.classes`` then wall (or
            ``(rows, cols, K-1)`` without wall). Free rows are normalised; their wall
            probability is set to 0. Non-free rows are ignored and start as wall.
        stats: the compatibilities.
        free_mask: ``(rows, cols)`` bool, the free cells; every other cell is wall.
        iterations: number of updates (the book uses 50).
        o: the neighbour weight ``o_ij``, in ``(0, 1/8]``.
        border: what a neighbour outside the map is (see the module docstring).
        backend: ``"cv2"`` (OpenCV filters; pooled compatibilities and 2–4 place classes),
            ``"numpy"`` (anything), or ``"auto"`` (cv2 when it can). Both compute the same.

    Returns:
        ``(rows, cols, K)`` float32 relaxed histograms, wall column last: 1 on non-free cells.

    All work is whole-array arithmetic (no loop over cells) over the bounding box of the free
    cells; memory is the ``(rows, cols, K)`` result plus about five float32 copies of the box's
    ``K-1`` place-class channels.
    """
    if int(iterations) != iterations or iterations < 0:
        raise ValueError(f"iterations must be a non-negative integer, got {iterations}")
    if not (math.isfinite(o) and 0 < o <= 1.0 / 8.0 + 1e-12):
        raise ValueError(f"o must lie in (0, 1/8] so that histograms stay non-negative, got {o}")
    if border not in ("wall", "none"):
        raise ValueError(f"border must be 'wall' or 'none', got {border!r}")
    if backend not in ("auto", "cv2", "numpy"):
        raise ValueError(f"backend must be 'auto', 'cv2' or 'numpy', got {backend!r}")
    Kf = len(stats.classes)
    P0a = np.asarray(P0)
    free = np.asarray(free_mask, dtype=bool)
    if P0a.ndim != 3 or free.shape != P0a.shape[:2]:
        raise ValueError(
            f"histograms (rows, cols, {Kf + 1}) and free_mask (rows, cols) must share the grid, "
            f"got {P0a.shape} and {free.shape}"
        )
    rows, cols = free.shape
    cv2_ok = 2 <= Kf <= 4 and not stats.per_direction
    if backend == "cv2" and not cv2_ok:
        raise ValueError(
            "the cv2 backend handles pooled compatibilities with 2 to 4 place classes: use backend='numpy'"
        )
    use_cv2 = cv2_ok and backend in ("cv2", "auto")

    out = np.zeros((rows, cols, Kf + 1), dtype=np.float32)
    out[..., Kf] = ~free
    if not free.any():
        initial_histograms(P0a, free, stats)  # still validate the shape
        return out
    # Only free cells change and every cell outside their bounding box is wall, so the work
    # is done on that box; its surroundings enter through the wall term.
    r0, r1, c0, c1 = _bbox(free)
    Pc, fc = initial_histograms(P0a[r0:r1, c0:c1], free[r0:r1, c0:c1], stats)
    if iterations > 0:
        edges = (r0 == 0, r1 == rows, c0 == 0, c1 == cols)  # box sides on the map border
        base = _wall_term(fc, edges, stats, o, border)
        if use_cv2:
            Pc = _iterate_cv2(Pc, base, fc, stats, o, int(iterations))
        else:
            Pc = _iterate_numpy(Pc, base, fc, stats, o, int(iterations))
    out[r0:r1, c0:c1, :Kf] = Pc
    return out


def _bbox(mask: np.ndarray) -> tuple[int, int, int, int]:
    rr = np.flatnonzero(mask.any(axis=1))
    cc = np.flatnonzero(mask.any(axis=0))
    return int(rr[0]), int(rr[-1]) + 1, int(cc[0]), int(cc[-1]) + 1


def _wall_term(
    free: np.ndarray,
    edges: tuple[bool, bool, bool, bool],
    stats: CompatibilityStats,
    o: float,
    border: Border,
) -> np.ndarray:
    """``1 + o Σ_{j wall} r_ij(k, wall)`` for every cell of a box: wall neighbours never change.

    ``edges`` says which sides of the box (top, bottom, left, right) lie on the map border;
    the ring around the box is wall elsewhere, and follows ``border`` there.
    """
    Kf = len(stats.classes)
    wp = cv2.copyMakeBorder((~free).astype(np.float32), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=1.0)
    if border == "none":
        top, bottom, left, right = edges
        if top:
            wp[0] = 0.0
        if bottom:
            wp[-1] = 0.0
        if left:
            wp[:, 0] = 0.0
        if right:
            wp[:, -1] = 0.0
    rows, cols = free.shape
    base = np.ones((rows, cols, Kf), dtype=np.float32)
    if stats.per_direction:
        for d, (dr, dc) in enumerate(DIRECTIONS):
            nb = wp[1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols]
            base += nb[..., None] * (o * stats.r_for(d)[:Kf, Kf])
    else:
        n_wall = cv2.filter2D(wp, -1, _KERNEL8, borderType=cv2.BORDER_CONSTANT)[1:-1, 1:-1]
        base += n_wall[..., None] * (o * stats.r_for(0)[:Kf, Kf])
    return base


def _iterate_cv2(
    P: np.ndarray,
    base: np.ndarray,
    free: np.ndarray,
    stats: CompatibilityStats,
    o: float,
    iterations: int,
    band: int = 32,
) -> np.ndarray:
    """Pooled compatibilities with OpenCV: the neighbour sum is one 3×3 filter.

    The grid is swept in bands of ``band`` rows (each cropped to its free columns) between two
    padded buffers, old and new: a band's temporaries stay in the CPU cache, which makes an
    iteration over a 4 M-cell map 3–5× faster than whole-array passes, and bands without free
    cells are skipped.
    """
    rows, cols, Kf = P.shape
    r = (o * stats.r_for(0)[:Kf, :Kf]).astype(np.float32)
    ones = np.ones((Kf, Kf), np.float32)
    z_fix = _z_fix(free, Kf)
    old = np.zeros((rows + 2, cols + 2, Kf), np.float32)
    old[1:-1, 1:-1] = P
    new = old.copy()
    bands = []
    for b0 in range(0, rows, band):
        b1 = min(rows, b0 + band)
        cc = np.flatnonzero(free[b0:b1].any(axis=0))
        if cc.size:
            bands.append((b0, b1, int(cc[0]), int(cc[-1]) + 1))
    for _ in range(iterations):
        for b0, b1, c0, c1 in bands:
            halo = old[b0 : b1 + 2, c0 : c1 + 2]  # the band and its neighbours (padded coordinates)
            S = cv2.filter2D(halo, -1, _KERNEL8, borderType=cv2.BORDER_ISOLATED)[1:-1, 1:-1]
            Q = cv2.transform(S, r).reshape(S.shape)  # q(k) = o Σ_k' r(k, k') Σ_j p_j(k')
            np.add(Q, base[b0:b1, c0:c1], out=Q)
            U = cv2.multiply(old[b0 + 1 : b1 + 1, c0 + 1 : c1 + 1], Q).reshape(S.shape)  # p(k) [1 + q(k)]
            Z = cv2.transform(U, ones).reshape(S.shape)  # the normaliser, in every channel
            np.add(Z, z_fix[b0:b1, c0:c1], out=Z)
            out = new[b0 + 1 : b1 + 1, c0 + 1 : c1 + 1]
            np.divide(U, Z, out=out)
            cv2.threshold(out, _FLUSH, 0.0, cv2.THRESH_TOZERO, dst=out)
        old, new = new, old
    return np.ascontiguousarray(old[1:-1, 1:-1])


def _z_fix(free: np.ndarray, Kf: int) -> np.ndarray:
    """Added to the normaliser: 1 on non-free cells (0/1 keeps them empty), and a tiny amount
    on free cells so that a row the update wiped out stays 0 instead of becoming NaN."""
    return np.repeat(np.where(free, np.float32(1e-30), np.float32(1.0))[..., None], Kf, axis=2)


def _iterate_numpy(
    P: np.ndarray, base: np.ndarray, free: np.ndarray, stats: CompatibilityStats, o: float, iterations: int
) -> np.ndarray:
    """Any number of classes, pooled or per-direction compatibilities: shifted views of a padded copy."""
    rows, cols, Kf = P.shape
    Pp = np.zeros((rows + 2, cols + 2, Kf), dtype=np.float32)
    Pp[1:-1, 1:-1] = P
    inner = Pp[1:-1, 1:-1]
    rts = [(o * stats.r_for(d)[:Kf, :Kf]).T.astype(np.float32) for d in range(8)]
    ones = np.ones((Kf, Kf), np.float32)
    z_fix = _z_fix(free, Kf)
    S, Q, Z = (np.empty((rows, cols, Kf), np.float32) for _ in range(3))
    views = [Pp[1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols] for dr, dc in DIRECTIONS]
    for _ in range(iterations):
        np.copyto(Q, base)
        if stats.per_direction:
            for d, view in enumerate(views):
                np.matmul(view, rts[d], out=S)
                np.add(Q, S, out=Q)
        else:
            np.copyto(S, views[0])
            for view in views[1:]:
                np.add(S, view, out=S)
            np.add(Q, np.matmul(S, rts[0], out=Z), out=Q)
        np.multiply(inner, Q, out=Q)
        np.matmul(Q, ones, out=Z)
        np.add(Z, z_fix, out=Z)
        np.divide(Q, Z, out=inner)
        inner[inner < _FLUSH] = 0.0
    return np.ascontiguousarray(inner)


def argmax_labels(
    P: np.ndarray, stats: CompatibilityStats, free_mask: np.ndarray | None = None
) -> np.ndarray:
    """``(rows, cols)`` uint8 label codes of the most probable label.

    Wall, an all-zero histogram (e.g. an occupied cell of a classifier's output) and cells
    outside ``free_mask`` (when given) become 0 (no label). Ties go to the earlier column (the
    class listed first in ``stats.classes``).
    """
    P = np.asarray(P)
    K = stats.n_labels
    if P.ndim != 3 or P.shape[2] not in (K - 1, K):
        raise ValueError(
            f"histograms must have shape (rows, cols, {K}) or (rows, cols, {K - 1}), got {P.shape}"
        )
    codes = np.array([*stats.classes, 0][: P.shape[2]], dtype=np.uint8)
    out = codes[np.argmax(P, axis=2)]
    out[~(P.max(axis=2) > 0)] = 0
    if free_mask is not None:
        free = np.asarray(free_mask, dtype=bool)
        if free.shape != out.shape:
            raise ValueError(f"free_mask {free.shape} must match the histograms' grid {out.shape}")
        out[~free] = 0
    return out
