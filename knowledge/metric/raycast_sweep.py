"""Whole-map ray casting by directional sweeps, compiled: every cell centre, one beam direction at a time.

Casting 360 beams from each of ~300 k free cells is ~10⁸ rays; walking each of them cell
by cell costs ~80 steps a ray. For one beam direction, though, all rays are parallel, so
one backward sweep over the grid can tell every ray where it may first meet a blocking
cell; a ray then only tests the cells there (exactly) and, rarely, asks again further on.
Compiled with numba, single-threaded: ~11 ns a ray on lab_intel (0.05 m, 360 beams).

Canonical frame. Each beam direction is mapped (transposing and mirroring the grid) to a
ray that advances towards +X one column at a time, with slope ``s = dY/dX`` in ``[0, 1]``.
The ray from the centre of cell ``(x, y)`` is ``Y(X) = y + ½ + s·(X − x − ½)``; it meets
column ``X`` at ``a = Y(X)`` and leaves it at ``a + s``, touching rows ``⌊a⌋ … ⌊a + s⌋``
(and the cells beside a grid corner it passes within ``ε`` of, see below).

Bands. Write ``a = r + δ + φ(X)``: the integer *base row* ``r = y + Q(x) + ⌊s·X⌋``, the
phase ``φ(X) = s·X − ⌊s·X⌋`` of the column and the fraction ``δ(x)`` of the start column
(``Q(x) + δ(x) = ½ − s·(x + ½)``). Start columns are sorted into :data:`BINS` phase bins
by ``δ``; for a bin ``[lo, hi]`` and a base row ``r`` the *band* of column ``X`` is rows
``r + ⌊lo + φ − ε⌋ … r + ⌊hi + φ + s + ε⌋``: every cell any ray of the bin with that base
row can touch there. The sweep runs from the last column back to the first, carrying
along each band (its base row rises by ``⌊s·(X+1)⌋ − ⌊s·X⌋`` per column) the first column
ahead whose band holds a blocking cell, and whether every ray of the bin enters that
column in a blocking cell (the range is then known): a table ``T[bin, X, r]`` the size of
the grid per bin. Rays are cast right behind the sweep (those of start column ``x`` once
column ``x + 1`` is done, while it is still in cache): a ray reads its *candidate* column
from the table, tests the one or two cells it touches there, and either has its hit or
reads the table again from the next column, in rounds over the rays still looking. A ray
that passes near a grid corner at its candidate takes the general walk
(:func:`_cast_one`); slope 1 exactly, where every ray passes through corners, has its own
sweep (:func:`_sweep_diagonal`).

Exact geometry, as :func:`~knowledge.metric.raycast_reference.reference_cast` walks it: a
ray entering column ``X`` across its left edge within ``ε`` of a grid corner tests both
cells of the column beside the corner; crossing a horizontal grid line within ``ε`` of a
corner it tests both cells beside the corner in the row it enters. ``ε`` is
:data:`~knowledge.metric.beams.CORNER_EPS`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np

from knowledge.metric.beams import CORNER_EPS
from knowledge.metric.raycast_poses import cast_centres

#: Cells: the corner rule's tolerance (a ray this close to a grid corner touches all four cells).
EPS = CORNER_EPS
#: Cells: the bands' margin, wider than :data:`EPS` so that float rounding never narrows them.
BAND_EPS = 1e-7
#: Slopes within this of 1 are the diagonal (45° beams come out ~10⁻¹⁶ short of 1): such a ray
#: strays from the grid corners by (1 − s)·distance, under 10⁻⁹ cell over 10⁵ cells.
DIAGONAL = 1e-14
#: Phase bins per direction; a speed knob only (more bins: narrower bands, more table to sweep).
BINS = 2
#: Free rows added on either side of a canonical grid, so band and corner reads need no bounds checks
#: (at least RP + 4, see :func:`_fill_column`).
PAD = 7
#: Base rows the tables hold below row 0 and above the last row.
RP = 3
#: Longest march (cells) the uint16 tables (entries ``2·column + 1``) can hold; beams marching
#: further, over maps over 3 km long at 0.1 m, walk each ray instead (:func:`cast_centres`).
MAX_MARCH = (np.iinfo(np.uint16).max - 1) // 2 - 1
#: Beams cast into a scratch buffer before they are copied into the result a block of each row at a
#: time (writing single strided columns would touch a cache line per value).
BLOCK = 32


def canonical(angle: float) -> tuple[bool, bool, bool, float]:
    """Canonical frame of the map-frame direction ``angle`` (radians, counter-clockwise from +x).

    Returns ``(transposed, flip_x, flip_y, s)``: march along grid rows (True) or columns,
    mirror the march axis, mirror the other axis, and the slope ``s`` in ``[0, 1]``.
    """
    du, dv = math.cos(angle), -math.sin(angle)  # grid: column u to the right, row v down
    transposed = abs(du) < abs(dv)
    major, minor = (dv, du) if transposed else (du, dv)
    return transposed, major < 0.0, minor < 0.0, min(abs(minor) / abs(major), 1.0)


def sweep_cells(
    blocked: np.ndarray,
    cells: np.ndarray,
    angles: np.ndarray,
    max_t: float,
    *,
    scale: float = 1.0,
    progress: Callable[[int, int], None] | None = None,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Ranges from the centres of ``cells`` along map-frame ``angles``.

    Args:
        blocked: ``(rows, cols)`` bool, the cells that stop a ray (image orientation).
        cells: ``(N, 2)`` int ``(row, col)`` start cells, inside the grid.
        angles: ``(B,)`` map-frame beam directions, radians counter-clockwise from +x.
        max_t: maximum range in cells; rays that hit nothing closer return it.
        scale: multiplies every range on output (the resolution, for metres).
        progress: called as ``progress(done, total)`` after each beam direction.
        out: ``(N, B)`` C-contiguous float32 array to fill (a fresh one if None).

    Returns:
        ``(N, B)`` float32 ranges, ``max_t·scale`` for beams that hit nothing.
    """
    mask = np.ascontiguousarray(blocked, dtype=bool)
    cells = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 2)
    angles = np.asarray(angles, dtype=np.float64).ravel()
    n, n_beams = cells.shape[0], angles.shape[0]
    if out is None:
        out = np.empty((n, n_beams), dtype=np.float32)
    elif out.shape != (n, n_beams) or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ValueError(
            f"out must be a C-contiguous float32 array of shape {(n, n_beams)}, got {out.dtype} {out.shape}"
        )
    if n == 0:
        return out
    grids: dict[tuple[bool, bool, bool], np.ndarray] = {}
    orders: dict[bool, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    tables: dict[bool, np.ndarray] = {}
    scratch = np.empty((min(BLOCK, n_beams), n), dtype=np.float32)
    for b0 in range(0, n_beams, BLOCK):
        b1 = min(b0 + BLOCK, n_beams)
        for b in range(b0, b1):
            transposed, flip_x, flip_y, s = canonical(float(angles[b]))
            key = (transposed, flip_x, flip_y)
            if key not in grids:
                grids[key] = _frame_grid(mask, transposed, flip_x, flip_y)
            if transposed not in orders:
                orders[transposed] = _cell_order(cells, mask.shape[0 if transposed else 1], transposed)
            G = grids[key]
            Xdim, Ydim = G.shape[0] - 1, G.shape[1] - 2 * PAD
            if transposed not in tables and Xdim <= MAX_MARCH:
                # base rows −RP … Ydim + RP − 1, and one more that always says "nothing ahead"
                tables[transposed] = np.empty((BINS, Xdim + 1, Ydim + 2 * RP + 1), dtype=np.uint16)
            ys, idx, starts = orders[transposed]
            if Xdim > MAX_MARCH:  # too long for the tables: walk each ray
                cast_centres(mask, cells, float(angles[b]), max_t, scale, scratch[b - b0])
            elif s >= 1.0 - DIAGONAL:
                _sweep_diagonal(G, ys, idx, starts, flip_x, flip_y, max_t, scale, scratch[b - b0])
            else:
                _sweep_direction(
                    G, ys, idx, starts, flip_x, flip_y, s, max_t, scale, tables[transposed], scratch[b - b0]
                )
            if progress is not None:
                progress(b + 1, n_beams)
        out[:, b0:b1] = scratch[: b1 - b0].T
    return out


def _frame_grid(blocked: np.ndarray, transposed: bool, flip_x: bool, flip_y: bool) -> np.ndarray:
    """``(Xdim + 1, Ydim + 2·PAD)`` uint8: ``blocked`` in a canonical frame, ``G[X, Y + PAD]``.

    Column ``Xdim`` and the ``PAD`` rows either side are free (outside the map).
    """
    A = blocked if transposed else blocked.T
    A = A[::-1] if flip_x else A
    A = A[:, ::-1] if flip_y else A
    G = np.zeros((A.shape[0] + 1, A.shape[1] + 2 * PAD), dtype=np.uint8)
    G[:-1, PAD:-PAD] = A
    return G


def _cell_order(cells: np.ndarray, Xdim: int, transposed: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The start cells grouped by their unmirrored march coordinate (row if ``transposed``, else column).

    Returns ``(ys, idx, starts)``: the other coordinate and the index into ``cells`` of each
    start, group by group, and ``(Xdim + 1,)`` offsets: group ``X0`` is ``starts[X0]:starts[X0 + 1]``.
    """
    along = cells[:, 0 if transposed else 1]
    key = along.astype(np.uint16) if Xdim <= np.iinfo(np.uint16).max else along  # radix-sorted
    idx = np.argsort(key, kind="stable").astype(np.int32)
    ys = cells[idx, 1 if transposed else 0].astype(np.int32)
    starts = np.zeros(Xdim + 1, dtype=np.int64)
    np.cumsum(np.bincount(along, minlength=Xdim), out=starts[1:])
    return ys, idx, starts


@numba.njit(cache=True, nogil=True)
def _sweep_direction(
    G: np.ndarray,
    ys: np.ndarray,
    idx: np.ndarray,
    starts: np.ndarray,
    flip_x: bool,
    flip_y: bool,
    s: float,
    max_t: float,
    scale: float,
    T: np.ndarray,
    result: np.ndarray,
) -> None:
    """Cast every start along one direction (slope ``s`` in the canonical grid ``G``) into ``result``.

    ``ys, idx, starts`` are :func:`_cell_order`'s; ``T`` is ``(BINS, Xdim + 1, Ydim + 2·RP + 1)``
    scratch for the tables; ``result[idx[j]]`` gets ``min(range, max_t)·scale`` (range in cells).

    Table entries are ``2·p + v``: ``p`` the candidate column (``Xdim``: none), ``v`` 1 where
    every ray of the bin enters column ``p`` in a blocking cell (its range is then known).
    """
    Xdim = G.shape[0] - 1
    Yg = G.shape[1]
    Ydim = Yg - 2 * PAD
    W = Ydim + 2 * RP
    n_bins = T.shape[0]
    L = math.sqrt(1.0 + s * s)  # ray length per column
    # per column: shift ⌊s·X⌋ of its band rows, phase φ(X), flat index of (X, row −shift) in G
    o = np.empty(Xdim + 2, dtype=np.int64)
    phi = np.empty(Xdim + 2)
    colbase = np.empty(Xdim + 2, dtype=np.int64)
    for X in range(Xdim + 2):
        sx = s * X
        o[X] = math.floor(sx)
        phi[X] = sx - o[X]
        colbase[X] = X * Yg + o[X] + PAD
    # per start column: base-row offset Q(x), fraction δ(x) and its bin; each bin's [lo, hi]
    Q = np.empty(Xdim, dtype=np.int64)
    delta = np.empty(Xdim)
    kb = np.empty(Xdim, dtype=np.int64)
    lo = np.full(n_bins, np.inf)
    hi = np.full(n_bins, -np.inf)
    for x in range(Xdim):
        c = 0.5 - s * (x + 0.5)
        q = math.floor(c)
        d = c - q
        k = min(int(d * n_bins), n_bins - 1)
        Q[x], delta[x], kb[x] = q, d, k
        lo[k] = min(lo[k], d)
        hi[k] = max(hi[k], d)
    T[:, Xdim, :] = 2 * Xdim  # nothing ahead
    T[:, :, W] = 2 * Xdim
    # s ≈ 1: the ray leaves its start cell through a corner, touching the cell above it
    corner_start = s >= 1.0 / (1.0 + 2.0 * EPS)
    size = np.max(starts[1:] - starts[:-1])
    act_j = np.empty(size, dtype=np.int64)  # rays still looking, and their next column
    act_X = np.empty(size, dtype=np.int64)
    gen_j = np.empty(size, dtype=np.int64)  # rays left to the general walk, and its column
    gen_X = np.empty(size, dtype=np.int64)
    yb, ysg = (Ydim - 1, -1) if flip_y else (0, 1)  # canonical row y = yb + ysg·ys
    geo = (s, L, L / s if s > 0.0 else 0.0, max_t, scale)
    tabs = (G, T, ys, idx, o, phi, colbase)
    act, gen = (act_j, act_X), (gen_j, gen_X)
    for x in range(Xdim - 1, -1, -1):
        X = x + 1  # the starts in column x read the table from column X on
        if x < Xdim - 1:  # (column Xdim, outside the map, has nothing ahead)
            _fill_column(G, T, X, o[X + 1] - o[X], phi[X], s, lo, hi)
        X0 = Xdim - 1 - x if flip_x else x
        if starts[X0] == starts[X0 + 1]:
            continue
        k = kb[x]
        # the start column's rays: ray y's table entry at column Xc is T[k, Xc, y + Q[x] + o[Xc] + RP]
        ray = (x, Q[x], delta[x], yb, ysg, k * (Xdim + 1) * (W + 1) + Q[x] + RP)
        # every ray's first candidate, then rounds over the rays still looking
        n_act, n_gen = _first_round(
            starts[X0], starts[X0 + 1] - starts[X0], tabs, ray, geo, corner_start, result, act, gen
        )
        while n_act > 0:
            n_act, n_gen = _next_round(n_act, tabs, ray, geo, result, act, gen, n_gen)
        Tk = T[k]
        for i in range(n_gen):
            j, Xc = gen_j[i], gen_X[i]
            y = yb + ysg * ys[j]
            result[idx[j]] = _cast_one(G, Tk, Xc, x, y, y + Q[x] + o[Xc], s, max_t, o, corner_start) * scale


@numba.njit(cache=True, nogil=True)
def _first_round(
    j0: int,
    n: int,
    tabs: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    ray: tuple[int, int, float, int, int, int],
    geo: tuple[float, float, float, float, float],
    corner_start: bool,
    result: np.ndarray,
    act: tuple[np.ndarray, np.ndarray],
    gen: tuple[np.ndarray, np.ndarray],
) -> tuple[int, int]:
    """The first candidate column of the ``n`` starts ``j0 …`` of one start column; the fast path.

    Writes each ray's range (final unless the ray looks on); puts at the front of ``act_*``
    the rays whose candidate was empty (they look on from the next column) and of ``gen_*``
    the rays the general walk must decide: near a grid corner at the candidate, starting
    in a blocking cell, or leaving the start cell through a corner. Returns how many of each.

    Written without unpredictable branches where it matters, so that the table and grid
    reads of successive rays overlap; and without helpers that take arrays (numba counts
    references at each such call). :func:`_next_round` is the same for later rounds.
    """
    G, T, ys, idx, o, phi, colbase = tabs
    act_j, act_X = act
    gen_j, gen_X = gen
    x, gq, dx, yb, ysg, tk = ray
    s, L, sL, max_t, scale = geo
    Xdim = G.shape[0] - 1
    W = T.shape[2] - 1
    Gf = G.ravel()
    Tf = T.ravel()
    cx = -(x + 0.5)
    own = x * G.shape[1] + PAD
    tX = tk + (x + 1) * (W + 1) + o[x + 1]
    n_act = n_gen = 0
    for j in range(j0, j0 + n):
        y = yb + ysg * ys[np.uint64(j)]
        code = Tf[np.uint64(tX + y)]
        p = code >> 1
        special = corner_start | (Gf[np.uint64(own + y)] != 0)
        if code & 1 and not special:  # every ray of the bin enters column p in a blocking cell
            result[np.uint64(idx[np.uint64(j)])] = min((p + cx) * L, max_t) * scale
            continue
        f = dx + phi[np.uint64(p)]  # the ray's row at the column's left edge less its base row
        i0 = 1 if f >= 1.0 else 0
        ea = f - i0  # where the ray enters the column, within the cell
        g = f + s
        i1 = int(g)
        eb = g - i1  # where it leaves the column, within the cell
        miss = (p >= Xdim) | ((p + cx - 1e-6) * L > max_t)
        cell = 0 if miss else colbase[np.uint64(p)] + y + gq + i0
        e0 = Gf[np.uint64(cell)]  # the cell entered
        e1 = Gf[np.uint64(cell + 1)] & (i1 > i0)  # the cell above, if the ray crosses into it
        hit = (e0 | e1) != 0
        clear = (ea > 2.0 * EPS) & (ea < 1.0 - 2.0 * EPS) & (eb > 2.0 * EPS) & (eb < 1.0 - 2.0 * EPS)
        t = (p + cx) * L + (0.0 if e0 else (1.0 - ea) * sL)
        result[np.uint64(idx[np.uint64(j)])] = (max_t if miss | (not hit) else min(t, max_t)) * scale
        act_j[np.uint64(n_act)], act_X[np.uint64(n_act)] = j, p + 1
        n_act += (not miss) & (not hit) & clear & (not special)
        gen_j[np.uint64(n_gen)], gen_X[np.uint64(n_gen)] = j, x + 1 if special else p
        n_gen += ((not miss) & (not clear)) | special
    return n_act, n_gen


@numba.njit(cache=True, nogil=True)
def _next_round(
    n: int,
    tabs: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    ray: tuple[int, int, float, int, int, int],
    geo: tuple[float, float, float, float, float],
    result: np.ndarray,
    act: tuple[np.ndarray, np.ndarray],
    gen: tuple[np.ndarray, np.ndarray],
    n_gen: int,
) -> tuple[int, int]:
    """:func:`_first_round` for the ``n`` rays ``act[0][:n]``, from columns ``act[1][:n]`` on."""
    G, T, ys, idx, o, phi, colbase = tabs
    act_j, act_X = act
    gen_j, gen_X = gen
    x, gq, dx, yb, ysg, tk = ray
    s, L, sL, max_t, scale = geo
    Xdim = G.shape[0] - 1
    W = T.shape[2] - 1
    Gf = G.ravel()
    Tf = T.ravel()
    cx = -(x + 0.5)
    n_act = 0
    for i in range(n):
        j, Xc = act_j[np.uint64(i)], act_X[np.uint64(i)]
        y = yb + ysg * ys[np.uint64(j)]
        p = Tf[np.uint64(tk + Xc * (W + 1) + min(y + o[np.uint64(Xc)], W - gq - RP))] >> 1
        f = dx + phi[np.uint64(p)]
        i0 = 1 if f >= 1.0 else 0
        ea = f - i0
        g = f + s
        i1 = int(g)
        eb = g - i1
        miss = (p >= Xdim) | ((p + cx - 1e-6) * L > max_t)
        cell = 0 if miss else colbase[np.uint64(p)] + y + gq + i0
        e0 = Gf[np.uint64(cell)]
        e1 = Gf[np.uint64(cell + 1)] & (i1 > i0)
        hit = (e0 | e1) != 0
        clear = (ea > 2.0 * EPS) & (ea < 1.0 - 2.0 * EPS) & (eb > 2.0 * EPS) & (eb < 1.0 - 2.0 * EPS)
        t = (p + cx) * L + (0.0 if e0 else (1.0 - ea) * sL)
        result[np.uint64(idx[np.uint64(j)])] = (max_t if miss | (not hit) else min(t, max_t)) * scale
        act_j[np.uint64(n_act)], act_X[np.uint64(n_act)] = j, p + 1
        n_act += (not miss) & (not hit) & clear
        gen_j[np.uint64(n_gen)], gen_X[np.uint64(n_gen)] = j, p
        n_gen += (not miss) & (not clear)
    return n_act, n_gen


@numba.njit(cache=True, nogil=True)
def _cast_one(
    G: np.ndarray,
    T: np.ndarray,
    X: int,
    x: int,
    y: int,
    r: int,
    s: float,
    max_t: float,
    o: np.ndarray,
    corner_start: bool,
) -> float:
    """Range in cells (at most ``max_t``) of the ray from the centre of ``(x, y)``, the general way.

    ``T`` is the table of the ray's bin, read from column ``X`` on (``x < X``), where the
    ray's base row is ``r``; ``o`` the columns' shifts.
    """
    Xdim = G.shape[0] - 1
    W = T.shape[1] - 1
    L = math.sqrt(1.0 + s * s)
    if G[x, y + PAD]:
        return 0.0
    if corner_start and G[x, y + 1 + PAD]:
        return min(0.5 / s * L, max_t)
    while r + RP < W:  # above the map: nothing ahead
        p = T[X, r + RP] >> 1
        if p >= Xdim or (p - x - 0.5 - 1e-6) * L > max_t:
            break
        off = _column_hit(G, p, y + 0.5 + s * (p - x - 0.5), s)
        if off < math.inf:
            return min((p - x - 0.5 + off) * L, max_t)
        r += o[p + 1] - o[X]
        X = p + 1
    return max_t


@numba.njit(cache=True, nogil=True)
def _fill_column(
    G: np.ndarray, T: np.ndarray, X: int, rise: int, phi: float, s: float, lo: np.ndarray, hi: np.ndarray
) -> None:
    """``T[k, X, i]`` for bin ``k``'s band with base row ``i − RP`` (see :func:`_sweep_direction`).

    ``2·X + v`` where the band holds a blocking cell in column ``X`` (``v``: all the rows the
    bin's rays enter the column by block), else the entry of the same band one column on,
    ``rise`` rows up. The band's rows are ``jlo … jlo + 3`` (``−1 ≤ jlo ≤ 1``) rows from the
    base row, so with ``PAD ≥ RP + 4`` every read stays inside the padded grid row.
    """
    W = T.shape[2] - 1
    g = G[X]
    for k in range(T.shape[0]):
        if lo[k] > hi[k]:
            continue  # no start column in this bin
        jlo = math.floor(lo[k] + phi - BAND_EPS)
        width = math.floor(hi[k] + phi + s + BAND_EPS) - jlo + 1  # band rows: 1 … 4
        entry = math.floor(hi[k] + phi + BAND_EPS) - jlo + 1  # of which the rays enter by 1 … 3
        # 0/1 masks of rows 1, 2, 3 of the band, and of the rows beyond the entry rows
        b1, b2, b3 = np.uint8(width > 1), np.uint8(width > 2), np.uint8(width > 3)
        n1, n2 = np.uint8(entry <= 1), np.uint8(entry <= 2)
        row = T[k, X, :W]
        nxt = T[k, X + 1, rise : rise + W]
        base = PAD - RP + jlo
        gw = g[base : base + W + 3]
        code = row.dtype.type(2 * X)
        for i in range(W):
            g0, g1, g2, g3 = gw[i], gw[i + 1], gw[i + 2], gw[i + 3]
            band = g0 | (g1 & b1) | (g2 & b2) | (g3 & b3)
            v = g0 & (g1 | n1) & (g2 | n2)
            row[i] = (code | v) if band else nxt[i]


@numba.njit(cache=True, nogil=True)
def _column_hit(G: np.ndarray, X: int, a: float, s: float) -> float:
    """Where the ray meets its first blocking cell in column ``X`` (``math.inf``: none).

    The ray enters the column at row coordinate ``a`` and leaves it at ``a + s``. Returns
    the X offset from the column's left edge (within ``±EPS`` of ``[0, 1]``). Tests the
    cells the reference walk tests there: the entry cell (both cells beside a corner), and
    the row entered across each horizontal grid line, at a corner both cells beside it
    (which may lie in the columns either side).
    """
    M = math.floor(a + 0.5)
    if abs(a - M) < EPS:
        if G[X, M - 1 + PAD] or G[X, M + PAD]:
            return 0.0
    elif G[X, math.floor(a) + PAD]:
        return 0.0
    if s > 0.0:
        m = math.floor(a - EPS * s) + 1
        top = a + s + EPS * s
        while m < top:
            xm = (m - a) / s
            if abs(xm) < EPS:
                blk = G[X - 1, m + PAD] or G[X, m + PAD]
            elif abs(xm - 1.0) < EPS:
                blk = G[X, m + PAD] or G[X + 1, m + PAD]
            else:
                blk = G[X, m + PAD]
            if blk:
                return xm
            m += 1
    return math.inf


@numba.njit(cache=True, nogil=True)
def _sweep_diagonal(
    G: np.ndarray,
    ys: np.ndarray,
    idx: np.ndarray,
    starts: np.ndarray,
    flip_x: bool,
    flip_y: bool,
    max_t: float,
    scale: float,
    result: np.ndarray,
) -> None:
    """:func:`_sweep_direction` for slope 1: rays from cell centres through every grid corner.

    The ray from the centre of ``(x, y)`` crosses column ``X``'s left edge at the corner
    ``(X, M)``, ``M = y + X − x``, and there touches cells ``(X, M − 1)``, ``(X, M)`` and
    ``(X − 1, M)``; nothing else. So the first column where one of them blocks, found by
    one backward sweep along each diagonal ``M − X``, is the exact hit.
    """
    Xdim = G.shape[0] - 1
    Ydim = G.shape[1] - 2 * PAD
    L = math.sqrt(2.0)
    first = np.full(Xdim + Ydim + 2, Xdim + 1, dtype=np.int64)  # by diagonal M − X + Xdim; Xdim + 1: none
    for X in range(Xdim, 0, -1):
        here, left = G[X], G[X - 1]  # column Xdim is outside the map, column Xdim − 1 is not
        for M in range(Ydim + 1):
            if here[M - 1 + PAD] | here[M + PAD] | left[M + PAD]:
                first[M - X + Xdim] = X
        x = X - 1
        X0 = Xdim - 1 - x if flip_x else x
        for j in range(starts[X0], starts[X0 + 1]):
            y = Ydim - 1 - ys[j] if flip_y else ys[j]
            p = first[y - x + Xdim]
            t = 0.0 if G[x, y + PAD] else (max_t if p > Xdim else min((p - x - 0.5) * L, max_t))
            result[idx[j]] = t * scale
