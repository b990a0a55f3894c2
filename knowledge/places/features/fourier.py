"""B.6–B.8 and Ma/Mi: Fourier coefficients of Pol(z) as a closed curve in arc length.

With the vertices ``v_k`` as complex numbers, the edges ``Δv_k = v_{k+1} − v_k`` of length
``ℓ_k``, unit directions ``Δs_k = Δv_k / ℓ_k``, arc positions ``t_k = Σ_{i<k} ℓ_i`` and the
perimeter T, the Fourier coefficients of the polygon z(t), t ∈ [0, T), are

    c_n = −T / (2πn)² · Σ_k (Δs_k − Δs_{k−1}) · e^{−j n (2π/T) t_k}          (n ≠ 0)

(integrate ``z(t) e^{−jωt}`` by parts twice: z'' is a sum of Dirac impulses, the turn
``Δs_k − Δs_{k−1}`` at vertex k, which sits at ``t_k``). The book's (B.13) prints "π" for
the n of the exponent (see shared/BOOK.md) and pairs the turn at vertex k+1 with ``t_k``;
we pair each turn with its own vertex, which makes c_n the exact coefficients of the
polygon: for a circle of radius r, |c_1| = r and c_n = 0 otherwise, and B.7/B.8 are the
semi-axes of the ellipse ``c_1 e^{jωt} + c_{−1} e^{−jωt}`` in metres.

**B.6** is the magnitude of the book's similarity-invariant descriptor (B.18),
``|c_n| / |c_1|``: invariant to rotation, translation, scale and to the start vertex (a
rotation of the scan by whole beams only changes phases). The 200 descriptors of the
default family are n = −100..−1 and 2..101: n = 0 is the centroid (it depends on where the
robot stands, not on the shape) and n = 1 is 1 by construction. If |c_1| is degenerate
(``|Σ_1| < 1e-9``; it never happens for a star-shaped scan polygon) the descriptors are 0.
**Ma/Mi** (``B.7/B.8``) is ``Ma / max(Mi, 1e-6·Ma)``, capped at 10⁶ when the ellipse
degenerates to a segment.

Speed: per scan the sums ``S_n = Σ_k τ_k E_k^n`` with ``E_k = e^{−j2πt_k/T}`` are needed for
the requested n only. Writing ``n = qB + b`` (B ≈ √max|n|), the powers ``E^b`` (b < B) and
``E^{qB}`` come from short recurrences, and a block of orders sharing q is one small matrix
product per scan, ``(τ ∘ E^{qB}) @ [E^0 .. E^{B−1}]`` (negative n use
``S_{−n} = conj(Σ conj(τ) E^n)``), done as real products on the interleaved (re, im) views
(see :func:`_real_products` for why not complex ones). A block with one or two requested
orders is done as dot products. All 200 descriptors cost about 2·M·(2B)·(2·max|n|/B) ≈ 0.3 M
multiply-adds per 360-beam scan, the same as the direct sums.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache

import numpy as np

from knowledge.places.features.batch import ScanBatch
from knowledge.places.features.raw import Kernel
from knowledge.places.features.registry import FeatureSpec

#: A block with at least this many requested orders uses the matrix product.
_MIN_BLOCK_FOR_MATMUL = 3
#: |S_1| below this means c_1 = 0 (degenerate polygon): descriptors are defined as 0.
_DEGENERATE_S1 = 1e-9
#: Multiply-adds per BLAS call: below OpenBLAS's threading threshold (65536·4), see _real_products.
_MAX_MATMUL_MNK = 150_000
#: Cap of Ma/Mi when the minor axis vanishes.
_MAX_AXIS_RATIO = 1e6


@dataclass(frozen=True)
class _Plan:
    """How to get S_n for a set of orders: block size B, blocks by (q, sign), output layout."""

    block: int
    #: (q, sign) of the blocks done as one matrix product each, in row order
    matmul_rows: tuple[tuple[int, int], ...]
    #: (q, sign, ((n, b), ...)) of the blocks done as dot products
    dot_rows: tuple[tuple[int, int, tuple[tuple[int, int], ...]], ...]
    max_q: int
    #: the orders, and the column of each in the (C, N) array of sums
    orders: tuple[int, ...]
    column: dict[int, int]
    #: for the matrix-product orders: their columns, flat (row·B + b) positions and signs
    mm_columns: np.ndarray
    mm_flat: np.ndarray
    mm_sign: np.ndarray


@cache
def _plan(orders: frozenset[int]) -> _Plan:
    K = max(abs(n) for n in orders)
    B = math.isqrt(K) + 1
    ordered = tuple(sorted(orders, key=lambda v: (abs(v), v)))
    blocks: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for n in ordered:
        q, b = divmod(abs(n), B)
        blocks.setdefault((q, 1 if n > 0 else -1), []).append((n, b))
    keys = sorted(blocks)
    mm = tuple(k for k in keys if len(blocks[k]) >= _MIN_BLOCK_FOR_MATMUL)
    dot = tuple((q, s, tuple(blocks[q, s])) for q, s in keys if len(blocks[q, s]) < _MIN_BLOCK_FOR_MATMUL)
    column = {n: j for j, n in enumerate(ordered)}
    mm_n = [(n, r * B + b, s) for r, (q, s) in enumerate(mm) for n, b in blocks[q, s]]
    return _Plan(
        block=B,
        matmul_rows=mm,
        dot_rows=dot,
        max_q=max(q for q, _ in keys),
        orders=ordered,
        column=column,
        mm_columns=np.array([column[n] for n, _, _ in mm_n], dtype=np.intp),
        mm_flat=np.array([f for _, f, _ in mm_n], dtype=np.intp),
        mm_sign=np.array([s for _, _, s in mm_n], dtype=np.float64),
    )


def _turns_and_phases(batch: ScanBatch) -> tuple[np.ndarray, np.ndarray]:
    """Turns ``τ_k = Δs_k − Δs_{k−1}`` and ``E_k = e^{−j2πt_k/T}``, both (C, M) complex."""
    x, y = batch.xy
    ell = batch.edge_len
    dx = np.roll(x, -1, axis=1) - x
    dy = np.roll(y, -1, axis=1) - y
    inv = np.divide(1.0, ell, out=np.zeros_like(ell), where=ell > 0)
    u = np.empty(x.shape, dtype=np.complex128)
    np.multiply(dx, inv, out=u.real)
    np.multiply(dy, inv, out=u.imag)
    tau = u - np.roll(u, 1, axis=1)
    t = np.cumsum(ell, axis=1)
    t -= ell
    theta = t * (2.0 * math.pi / batch.perimeter)[:, None]
    E = np.empty_like(tau)
    np.cos(theta, out=E.real)
    np.sin(theta, out=E.imag)
    np.negative(E.imag, out=E.imag)
    return tau, E


def fourier_sums(batch: ScanBatch) -> tuple[dict[int, int], np.ndarray]:
    """``S_n = Σ_k τ_k E_k^n`` for every n in ``batch.fourier_orders`` (cached per batch).

    Returns the column of each order and the (C, N) complex array of sums.
    """
    cached = batch.cache.get("fourier")
    if cached is not None:
        return cached
    plan = _plan(batch.fourier_orders)
    tau, E = _turns_and_phases(batch)
    C, M = tau.shape
    B = plan.block
    sums = np.empty((C, len(plan.orders)), dtype=np.complex128)
    # powers[:, b] = conj(E)^b and powers[:, B + b] = j·conj(E)^b: with W = τ·E^{qB}, the real
    # dot products of the interleaved (re, im) views give Re and Im of Σ W·E^b (see _real_products)
    powers = np.empty((C, 2 * B, M), dtype=np.complex128)
    powers[:, 0] = 1.0
    conj_e = np.conj(E)
    for b in range(1, B):
        np.multiply(powers[:, b - 1], conj_e, out=powers[:, b])
    np.multiply(powers[:, :B], 1j, out=powers[:, B:])
    step = np.conj(powers[:, B - 1]) * E  # E^B
    ctau = np.conj(tau)
    W = np.empty((C, len(plan.matmul_rows), M), dtype=np.complex128)
    mm_index = {key: r for r, key in enumerate(plan.matmul_rows)}
    dot_rows = {(q, s): orders for q, s, orders in plan.dot_rows}
    Q = np.ones_like(E)  # E^{qB}
    for q in range(plan.max_q + 1):
        if q > 0:
            Q *= step
        for sign, base in ((1, tau), (-1, ctau)):
            r = mm_index.get((q, sign))
            if r is not None:
                np.multiply(base, Q, out=W[:, r])
            orders = dot_rows.get((q, sign))
            if orders:
                row = (base * Q).view(np.float64)
                for n, b in orders:
                    re = np.einsum("ij,ij->i", row, powers[:, b].view(np.float64))
                    im = np.einsum("ij,ij->i", row, powers[:, B + b].view(np.float64))
                    sums[:, plan.column[n]] = re + 1j * sign * im
    if plan.matmul_rows:
        re_im = _real_products(W, powers)  # (C, rows, 2B)
        flat = (re_im[:, :, :B] + 1j * re_im[:, :, B:]).reshape(C, -1)[:, plan.mm_flat]
        flat.imag *= plan.mm_sign
        sums[:, plan.mm_columns] = flat
    result = (plan.column, sums)
    batch.cache["fourier"] = result
    return result


def _real_products(W: np.ndarray, powers: np.ndarray) -> np.ndarray:
    """``out[c, r, k] = Σ_m Re(W[c, r, m]·conj(powers[c, k, m]))`` as real matrix products.

    On the interleaved float views (re, im, re, im, ...) a real dot product of ``w`` and
    ``p`` is ``Re(Σ w·conj(p))``. OpenBLAS runs complex products of this size on several
    threads, which on a busy machine waits for descheduled workers (5–20× slower); real
    products below ~2.6e5 multiply-adds stay on the calling thread, so the rows are cut
    into blocks of at most :data:`_MAX_MATMUL_MNK` multiply-adds.
    """
    C, R, M = W.shape
    K = powers.shape[1]
    wv = W.view(np.float64)  # (C, R, 2M)
    pv = powers.view(np.float64).transpose(0, 2, 1)  # (C, 2M, K)
    rows = max(1, _MAX_MATMUL_MNK // (K * 2 * M))
    out = np.empty((C, R, K), dtype=np.float64)
    for r0 in range(0, R, rows):
        np.matmul(wv[:, r0 : r0 + rows], pv, out=out[:, r0 : r0 + rows])
    return out


def fourier_kernel(batch: ScanBatch, specs: Sequence[FeatureSpec]) -> np.ndarray:
    """B.6 descriptors ``|c_n|/|c_1|``, B.7 Ma, B.8 Mi (metres) and ``B.7/B.8`` Ma/Mi."""
    column, sums = fourier_sums(batch)
    a1 = np.abs(sums[:, column[1]])
    degenerate = a1 < _DEGENERATE_S1
    out = np.empty((batch.d.shape[0], len(specs)), dtype=np.float64)
    desc = [j for j, s in enumerate(specs) if s.family == "B.6"]
    if desc:
        n = np.array([specs[j].params[0] for j in desc])
        values = np.abs(sums[:, [column[int(v)] for v in n]])
        values /= np.where(degenerate, 1.0, a1)[:, None] * (n * n)[None, :]
        values[degenerate] = 0.0
        out[:, desc] = values
    rest = [j for j, s in enumerate(specs) if s.family != "B.6"]
    if rest:
        am1 = np.abs(sums[:, column[-1]])
        scale = batch.perimeter / (4.0 * math.pi**2)  # |c_n| = T / (2πn)² · |S_n|
        major = scale * (a1 + am1)
        minor = scale * np.abs(a1 - am1)
        floor = major / _MAX_AXIS_RATIO
        ratio = major / np.where(minor > floor, minor, np.where(floor > 0, floor, 1.0))
        ratio = np.where(major > 0, ratio, 1.0)
        for j in rest:
            fam = specs[j].family
            out[:, j] = major if fam == "B.7" else minor if fam == "B.8" else ratio
    return out


def orders_needed(specs: Sequence[FeatureSpec]) -> frozenset[int]:
    """The Fourier orders n whose sums S_n the Fourier features in ``specs`` need."""
    orders: set[int] = set()
    for spec in specs:
        if spec.family == "B.6":
            orders.update((1, int(spec.params[0])))
        elif spec.family in ("B.7", "B.8", "B.7/B.8"):
            orders.update((1, -1))
    return frozenset(orders)


KERNELS: dict[str, Kernel] = {"fourier": fourier_kernel}
