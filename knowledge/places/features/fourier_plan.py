"""The plan of the Fourier kernel: which powers E^n to form, and how, for the requested orders.

The kernel (:mod:`.fourier`) needs, per block of vertices, ``V_n = E^n`` for every requested
order |n| (one pass over the vertices accumulates both signs from it). This module writes
the program of complex row products that makes them, by baby steps and giant steps:

* baby steps ``E^b = E^{b−1}·E`` for b < B,
* the giant step ``G = E^B``, its squares ``G², G⁴, ...`` as needed, and the giant powers
  ``Q_q = E^{qB}`` for each q in use, each from the previous one by the binary digits of the
  gap (one product per digit: consecutive q cost one product each, sparse high orders a few),
* per order ``|n| = qB + b`` a pass over ``E^b`` (q = 0), ``Q_q`` (b = 0) or the product
  ``Q_q·E^b`` formed on the fly.

B is chosen to minimise the estimated cost (products and passes, weighted by their measured
relative costs); rows of the work array are reused once a giant power is no longer needed.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from typing import NamedTuple

import numpy as np

from knowledge.places.features.registry import FeatureSpec

#: Op codes of :attr:`FourierPlan.ops`: ``(MUL, a, b, c)`` sets rows c, c+1 to the complex
#: product of rows (a, a+1) and (b, b+1); ``(DOT, p, q, j)`` accumulates the sums of order j
#: over ``V`` = rows p (q < 0) or rows p times rows q.
MUL, DOT = 0, 1
#: Rows of the work array holding the block's τ (0, 1) and E (2, 3).
TAU_ROW, E_ROW = 0, 2
#: Relative costs of a product (it stores two rows), a pass over a stored power and one over
#: a product formed on the fly (measured on 360-beam scans).
_COST_MUL, _COST_DOT, _COST_DOT_PRODUCT = 1.0, 0.3, 0.7

#: Slots of the single-valued Fourier features in :attr:`FourierPlan.single`.
MAJOR, MINOR, RATIO = 0, 1, 2
SINGLE = ("B.7", "B.8", "B.7/B.8")
#: Families :func:`make_plan` serves.
FAMILIES = frozenset((*SINGLE, "B.6"))


class FourierPlan(NamedTuple):
    """What the compiled kernel computes and where the values go.

    ``ops`` (P, 4) is the program (see :data:`MUL`, :data:`DOT`) run per block of vertices on
    a work array of ``rows`` rows. Per requested order |n| (index j, ascending, |n| = 1 first):
    ``order_nn`` = n², ``order_pos``/``order_neg`` the output columns of B.6[|n|] and B.6[−|n|]
    (−1 if not requested: n = ±1 are always computed for the normalisation and the ellipse).
    ``single`` holds the columns of B.7, B.8 and B.7/B.8 (−1 if not requested).
    """

    ops: np.ndarray
    rows: int
    order_nn: np.ndarray
    order_pos: np.ndarray
    order_neg: np.ndarray
    single: np.ndarray

    @property
    def active(self) -> bool:
        return self.order_nn.size > 0


def make_plan(specs: Sequence[FeatureSpec], columns: Sequence[int]) -> FourierPlan:
    """The plan for the Fourier features ``specs`` (B.6, B.7, B.8, B.7/B.8) written to ``columns``."""
    single = np.full(len(SINGLE), -1, dtype=np.int64)
    wanted: dict[int, int] = {}
    for spec, col in zip(specs, columns, strict=True):
        if spec.family == "B.6":
            wanted[int(spec.params[0])] = col
        else:
            single[SINGLE.index(spec.family)] = col
    if not wanted and (single < 0).all():
        none = np.empty(0, dtype=np.int64)
        return FourierPlan(np.empty((0, 4), dtype=np.int64), 4, np.empty(0), none, none, single)
    orders = tuple(sorted({1, *(abs(n) for n in wanted)}))
    ops, rows = best_program(orders)
    return FourierPlan(
        ops=np.array(ops, dtype=np.int64).reshape(-1, 4),
        rows=rows,
        order_nn=np.array([float(n * n) for n in orders]),
        order_pos=np.array([wanted.get(n, -1) for n in orders], dtype=np.int64),
        order_neg=np.array([wanted.get(-n, -1) for n in orders], dtype=np.int64),
        single=single,
    )


@cache
def best_program(orders: tuple[int, ...]) -> tuple[tuple[tuple[int, int, int, int], ...], int]:
    """The cheapest :func:`program` over the block sizes B = 1..max|n|+1: (ops, rows)."""
    best = min(
        (program(orders, B) for B in range(1, orders[-1] + 2)),
        key=lambda p: (p[2], p[1]),
    )
    return best[0], best[1]


def program(orders: Sequence[int], B: int) -> tuple[tuple[tuple[int, int, int, int], ...], int, float]:
    """The ops making ``E^n`` for the ascending orders ``orders`` with block size B, the rows
    they use and their estimated cost (see the module doc)."""
    ops: list[tuple[int, int, int, int]] = []
    cost = 0.0
    free: list[int] = []
    top = 4  # first row not yet used (rows come in (re, im) pairs)

    def alloc() -> int:
        nonlocal top
        if free:
            return free.pop()
        top += 2
        return top - 2

    def mul(a: int, b: int) -> int:
        nonlocal cost
        c = alloc()
        ops.append((MUL, a, b, c))
        cost += _COST_MUL
        return c

    giant_needed = orders[-1] >= B
    baby = {1: E_ROW}  # E^b → row
    for b in range(2, (B - 1 if giant_needed else orders[-1]) + 1):
        baby[b] = mul(baby[b - 1], E_ROW)
    squares: list[int] = []  # G^(2^i) → row
    if giant_needed:
        squares.append(E_ROW if B == 1 else mul(baby[B - 1], E_ROW))
    q_now, q_row = 0, -1  # the current giant power Q_q = G^q and its row (−1: none yet)
    for j, n in enumerate(orders):
        q, b = divmod(n, B)
        if q == 0:
            ops.append((DOT, baby[b], -1, j))
            cost += _COST_DOT
            continue
        gap, bit = q - q_now, 0
        while gap:
            if gap & 1:
                while len(squares) <= bit:  # G^(2^i): reuse Q if it is that power, else square
                    if q_now == 1 << len(squares) and q_row not in squares:
                        squares.append(q_row)
                    else:
                        squares.append(mul(squares[-1], squares[-1]))
                if q_row < 0:
                    q_row = squares[bit]
                else:
                    row = mul(q_row, squares[bit])
                    if q_row not in squares:
                        free.append(q_row)
                    q_row = row
                q_now += 1 << bit
            gap >>= 1
            bit += 1
        if b == 0:
            ops.append((DOT, q_row, -1, j))
            cost += _COST_DOT
        else:
            ops.append((DOT, baby[b], q_row, j))
            cost += _COST_DOT_PRODUCT
    return tuple(ops), top, cost
