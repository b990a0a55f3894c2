"""Whole-map ray casting by directional sweeps: every cell centre, one beam direction at a time.

Casting 360 beams from each of ~300 k free cells is ~10⁸ rays; walking them one cell at a
time is far too slow in numpy. For one beam direction, though, all rays are parallel: a
*sheared* copy of the grid turns them into (nearly) straight rows, along which a running
minimum finds, for every cell at once, the next blocking cell ahead. A direction and its
opposite share the shear (the running extreme just runs the other way).

Canonical frame. The march axis ``X`` is the grid axis the ray advances along fastest
(columns or rows), ``Y`` the other one, flipped if needed so that the slope ``s = dY/dX``
lies in ``[0, 1]``. The ray from the centre of cell ``(x, y)`` is
``Y(X) = y + ½ + s·(X − x − ½)``; in column ``X`` it touches rows ``⌊Y(X)⌋ … ⌊Y(X+1)⌋``
(at most two; three through a corner, see :data:`~knowledge.metric.beams.CORNER_EPS`).

Shear. Column ``X`` is shifted down by ``o(X) = ⌊s·X⌋`` cells, so a ray occupies sheared
rows ``q0 + δ + φ(X) … q0 + δ + φ(X) + s``, with ``q0 + δ`` its intercept (``δ`` the
fraction, which depends on the start column only) and ``φ(X) = s·X − o(X)``. Rays from
different start columns have different ``δ``, so no sheared row is exactly one ray.

Bands. Start cells are sorted into a few *phase bins* by ``δ``; for each bin and base row
``q0`` the *band* holds every cell some ray of the bin could touch. Its running extreme
gives each ray a *candidate* column never later than its true hit. Where every ray of the
bin enters the candidate column in a blocking cell, or in the same free cell below a
blocking one, the running extreme carries a code saying so, and the range follows from
the candidate (one comparison for the latter). Only the other candidates get the exact
test (≤ 3 cells, exact entry point). A false candidate sends its ray on from the next
column (shallow rays first skip along the grid row they are in), so a few vectorised
rounds settle every ray, and the result is exact: the same as walking the ray cell by cell.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from knowledge.metric.beams import CORNER_EPS

EPS = CORNER_EPS


@dataclass(frozen=True)
class _Direction:
    """One beam direction in canonical form."""

    beam: int  # index of the beam in the output
    transposed: bool  # march along grid rows (True) or columns (False)
    flipped: bool  # Y axis reversed so that the slope is non-negative
    slope: float  # s = dY/dX in [0, 1]
    forward: bool  # the ray advances towards +X


def canonical(beam: int, angle: float) -> _Direction:
    """Canonical form of the map-frame direction ``angle`` (radians, CCW from map +x)."""
    du, dv = math.cos(angle), -math.sin(angle)  # grid: column u to the right, row v down
    transposed = abs(du) < abs(dv)
    dx, dy = (dv, du) if transposed else (du, dv)
    s = dy / dx
    return _Direction(beam, transposed, s < 0.0, min(abs(s), 1.0), dx > 0.0)


def group_directions(angles: np.ndarray) -> list[list[_Direction]]:
    """Beams that share one shear (same canonical line family), in order of first appearance."""
    groups: dict[tuple[bool, bool, int], list[_Direction]] = {}
    for b, a in enumerate(angles):
        d = canonical(b, float(a))
        key = (d.transposed, d.flipped, round(d.slope * 1e12))
        groups.setdefault(key, []).append(d)
    return list(groups.values())


def sweep_cells(
    blocked: np.ndarray,
    cells: np.ndarray,
    angles: np.ndarray,
    max_t: float,
    *,
    scale: float = 1.0,
    bins: int = 2,
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
        bins: phase bins per shear (see the module docstring); a speed knob only.
        progress: called as ``progress(done, total)`` after each beam direction.
        out: ``(N, B)`` C-contiguous float32 array to fill (a fresh one if None).

    Returns:
        ``(N, B)`` float32 ranges, ``max_t·scale`` for beams that hit nothing.
    """
    blocked = np.ascontiguousarray(blocked, dtype=bool)
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    n, n_beams = cells.shape[0], len(angles)
    if out is None:
        out = np.empty((n, n_beams), dtype=np.float32)
    elif out.shape != (n, n_beams) or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ValueError(
            f"out must be a C-contiguous float32 array of shape {(n, n_beams)}, got {out.dtype} {out.shape}"
        )
    columns = _ColumnBlocks(out)
    own = blocked[cells[:, 0], cells[:, 1]]
    frames: dict[tuple[bool, bool], _Frame] = {}
    done = 0
    for group in group_directions(np.asarray(angles, dtype=np.float64)):
        d0 = group[0]
        key = (d0.transposed, d0.flipped)
        if key not in frames:
            frames[key] = _Frame.make(blocked, cells, own, *key)
        frame = frames[key]
        shear = _Shear(frame.A, d0.slope, bins)
        starts = shear.starts(frame)
        for forward in (True, False):
            members = [d for d in group if d.forward == forward]
            if not members:
                continue
            ranges = shear.cast(starts, frame, forward, max_t, scale)
            for d in members:
                columns.put(d.beam, ranges)
                done += 1
                if progress is not None:
                    progress(done, n_beams)
    return out


class _ColumnBlocks:
    """Fills an ``(N, B)`` array one column (beam) at a time, a block of columns per write.

    A block of 16 float32 columns is one 64-byte cache line per row: copying whole blocks
    into the row-major result is several times cheaper than writing strided columns, and
    needs no ``(B, N)`` intermediate the size of the result.
    """

    BLOCK = 16

    def __init__(self, array: np.ndarray) -> None:
        self.array = array
        self._pending: dict[int, np.ndarray] = {}

    def put(self, column: int, values: np.ndarray) -> None:
        self._pending[column] = values
        b0 = column - column % self.BLOCK
        b1 = min(b0 + self.BLOCK, self.array.shape[1])
        if all(b in self._pending for b in range(b0, b1)):
            np.stack([self._pending.pop(b) for b in range(b0, b1)], axis=1, out=self.array[:, b0:b1])


#: Above this slope a grid row holds at most a few columns of a ray: following it does not pay.
_ROW_SKIP_SLOPE = 0.3
#: Row-run value for "no blocking cell ahead" (forward) and "behind" (backward).
_NONE_F = int(np.iinfo(np.int32).max)
_NONE_B = -1


@dataclass(frozen=True)
class _Frame:
    """The grid and the start cells in one canonical orientation (shared by its shears)."""

    A: np.ndarray  # (Xdim, Ydim) bool blocking mask, A[X, Y]
    x: np.ndarray  # (N,) int64 canonical column of each start
    y: np.ndarray  # (N,) int64 canonical row
    x0: np.ndarray  # (N,) float64 centre, X
    y0: np.ndarray  # (N,) float64 centre, Y
    gap_f: np.ndarray  # (N,) float32 x0 + 1: p − gap_f is the X distance to padded column p's left edge
    gap_b: np.ndarray  # (N,) float32 x0: gap_b − p is the X distance to padded column p's right edge
    own: np.ndarray  # (N,) bool: the start cell blocks
    runs_f: np.ndarray  # (Xdim, Ydim) int32: next blocking X at or after X in row Y
    runs_b: np.ndarray  # (Xdim, Ydim) int32: last blocking X at or before X in row Y

    @classmethod
    def make(
        cls, blocked: np.ndarray, cells: np.ndarray, own: np.ndarray, transposed: bool, flipped: bool
    ) -> _Frame:
        A = blocked if transposed else np.ascontiguousarray(blocked.T)
        x = np.ascontiguousarray(cells[:, 0] if transposed else cells[:, 1])
        y = np.ascontiguousarray(cells[:, 1] if transposed else cells[:, 0])
        if flipped:
            A = np.ascontiguousarray(A[:, ::-1])
            y = A.shape[1] - 1 - y
        x0 = x + 0.5
        return cls(
            A=A,
            x=x,
            y=y,
            x0=x0,
            y0=y + 0.5,
            gap_f=(x0 + 1.0).astype(np.float32),
            gap_b=x0.astype(np.float32),
            own=own,
            runs_f=_row_runs(A, True),
            runs_b=_row_runs(A, False),
        )


@dataclass(frozen=True)
class _Starts:
    """Per start quantities of one shear, shared by a direction and its opposite."""

    delta: np.ndarray  # fractional part of the sheared intercept
    q1: np.ndarray  # 1 + integer part of the sheared intercept (S's column offset included)
    nb_index: np.ndarray  # flat index of (padded column x, bin, q0) in the running extremes
    above: np.ndarray | None  # 45° only: the cell the ray touches at the corner leaving its own column
    below: np.ndarray | None  # ... going backward


class _Shear:
    """The sheared grid of one line family, its phase-bin bands and their running extremes.

    Arrays indexed by column use the padded index ``p = X + 1``: rows ``0`` and ``Xdim + 1``
    are empty, so "nothing found" lands on a harmless empty column.
    """

    def __init__(self, A: np.ndarray, s: float, bins: int) -> None:
        Xdim, Ydim = A.shape
        self.s, self.Xdim, self.Ydim = s, Xdim, Ydim
        X = np.arange(Xdim, dtype=np.float64)
        sX = s * X
        self.o = np.floor(sX).astype(np.int64)
        self.phi = np.zeros(Xdim + 2)
        self.phi[1:-1] = sX - self.o  # where column X's shifted rows start, within a cell
        self.pad = int(self.o[-1]) + 3
        self.Hs = Hs = Ydim + self.pad + 4
        # S[X + 1, 1 + q] = A[X, q + o(X) − pad]; one spare cell below q = 0 for the band shifts
        self.W = Hs + 4
        S = np.zeros((Xdim + 2, self.W), dtype=bool)
        for x in range(Xdim):
            lo = 1 + self.pad - int(self.o[x])
            S[x + 1, lo : lo + Ydim] = A[x]
        self.S2 = S
        self.S = S.ravel()
        # the ray from the centre of (x, y) has sheared intercept y + q_off(x) + δ(x)
        b = 0.5 - s * (X + 0.5) + self.pad
        q_off = np.floor(b)
        self.delta = b - q_off
        self.q_off = q_off.astype(np.int64)
        k = np.minimum((self.delta * bins).astype(np.int64), bins - 1)
        used = [i for i in range(bins) if (k == i).any()]
        self.bin_edges = np.array([(self.delta[k == i].min(), self.delta[k == i].max()) for i in used])
        self.bin_of = np.searchsorted(np.array(used), k)
        self.K = len(used)
        # running extremes hold 4·p + code: int16 while that fits
        self.code_dtype = np.int16 if 4 * (Xdim + 2) + 3 < np.iinfo(np.int16).max else np.int32
        self._band: np.ndarray | None = None
        self._nb: dict[bool, np.ndarray] = {}

    # ------------------------------------------------------------------ running extremes
    def _shift(self, j: int) -> np.ndarray:
        """``(Xdim + 2, Hs)`` bool view: ``S[X, q + j]``."""
        return self.S2[:, 1 + j : 1 + j + self.Hs]

    def _rows(self, lo: np.ndarray, hi: np.ndarray, combine: str) -> np.ndarray:
        """OR (``"any"``) or AND (``"all"``) of ``S[X, q + j]`` over ``⌊lo(X) − ε⌋ ≤ j ≤ ⌊hi(X) + ε⌋``."""
        jlo, jhi = np.floor(lo - EPS), np.floor(hi + EPS)
        out: np.ndarray | None = None
        for j in range(-1, 3):
            m = (jlo <= j) & (j <= jhi)
            if not m.any():
                continue
            if combine == "any":
                term = self._shift(j) if m.all() else self._shift(j) & m[:, None]
                out = term.copy() if out is None else out | term
            else:
                term = self._shift(j) | ~m[:, None]
                out = term if out is None else out & term
        assert out is not None
        return out

    def _certain(self, lo: float, hi: float, forward: bool) -> tuple[np.ndarray, np.ndarray]:
        """Where the first blocking cell a ray of the phase bin ``[lo, hi]`` touches is known.

        Returns two ``(Xdim + 2, Hs)`` bool masks, by base row: *V*, every ray meets a
        blocking cell right where it enters the column (left edge forward, right edge
        backward); *H*, every ray enters the column in the same free cell and the cell it
        would cross into next (up forward, down backward) blocks: each ray then either
        crosses into it inside the column (a hit) or leaves the column without touching
        anything (a false candidate), which :meth:`cast` tells apart with one comparison.
        """
        s, phi = self.s, self.phi
        enter = phi if forward else phi + s
        V = self._rows(lo + enter, hi + enter, "all")
        H = np.zeros_like(V)
        if s >= 1.0 - 3.0 * EPS:  # near 45° a ray may also touch a corner two rows on
            return V, H
        jl, jr = np.floor(lo + enter - EPS), np.floor(hi + enter + EPS)
        # every ray of the bin enters the column in the same row, and some leave it inside
        if forward:
            cols = (jl == jr) & (hi + phi + s + EPS >= jl + 1.0)
        else:
            cols = (jl == jr) & (lo + phi - EPS < jr)
        for j in (-1, 0, 1) if forward else (0, 1, 2):
            m = cols & (jl == j)
            if m.any():
                H |= ~self._shift(j) & self._shift(j + 1 if forward else j - 1) & m[:, None]
        return V, H

    def _next_blocked(self, forward: bool) -> np.ndarray:
        """Flat ``(Xdim + 2, K, Hs)`` running extremes, encoded as ``4·p + code``.

        ``p`` is the padded index of the first column ahead (forward: at or after, backward:
        at or before) in which some ray of the bin may touch a blocking cell; nothing
        ahead: the padding column. ``code`` is 1 (*V*) or 2 (*H*) where :meth:`_certain`
        settles the hit for every ray of the bin, 0 where each ray must be tested.
        """
        if forward in self._nb:
            return self._nb[forward]
        n, K, Hs, s = self.Xdim + 2, self.K, self.Hs, self.s
        if self._band is None:
            self._band = np.empty((n, K, Hs), dtype=bool)
            for k, (lo, hi) in enumerate(self.bin_edges):
                self._band[:, k] = self._rows(lo + self.phi, hi + self.phi + s, "any")
        dt = self.code_dtype
        idx = np.arange(n, dtype=dt)[:, None, None]
        if forward:
            none = dt(4 * (n - 1))
            code = self._band.view(np.uint8) * (4 * idx - none)
            code += none
        else:
            code = self._band.view(np.uint8) * (4 * idx)
        for k, (lo, hi) in enumerate(self.bin_edges):
            V, H = self._certain(lo, hi, forward)
            c = H.view(np.uint8) << 1
            c |= V.view(np.uint8)
            code[:, k] += c
        self._nb[forward] = _running_extreme(code, forward).ravel()
        if len(self._nb) == 2:
            self._band = None
        return self._nb[forward]

    # ------------------------------------------------------------------ casting
    def starts(self, fr: _Frame) -> _Starts:
        """Per-start quantities of this shear for the starts of frame ``fr``."""
        K, Hs, W = self.K, self.Hs, self.W
        x, y = fr.x, fr.y
        cols = np.arange(self.Xdim, dtype=np.int64)
        above = below = None
        if self.s >= 1.0 - 2.0 * EPS:  # the ray leaves its own column through a corner
            own_pos = ((cols + 1) * W + 1 + self.pad - self.o)[x] + y
            above, below = self.S[own_pos + 1], self.S[own_pos - 1]
        return _Starts(
            delta=self.delta[x],
            q1=(self.q_off + 1)[x] + y,
            nb_index=((cols * K + self.bin_of) * Hs + self.q_off)[x] + y,
            above=above,
            below=below,
        )

    def cast(self, st: _Starts, fr: _Frame, forward: bool, max_t: float, scale: float) -> np.ndarray:
        """Float32 range to the first blocking cell from each start, ``max_t`` if none, times ``scale``.

        ``max_t`` is in cells.
        """
        s = self.s
        length = math.sqrt(1.0 + s * s)  # ray length per unit of X, in cells
        max_x = max_t / length
        max_x32 = np.float32(max_x)
        KH = self.K * self.Hs  # one column on in the running extremes
        nb_all = self._next_blocked(forward)
        # nb_index points at padded column x (real x − 1): the first candidate is real x ± 1
        nb = nb_all[2 * KH :] if forward else nb_all
        # first round on every start at once, in float32 (exact for these integer + ½ distances)
        code = nb[st.nb_index]
        p = code >> 2
        c = code & 3
        if forward:
            colx = np.subtract(p, fr.gap_f, dtype=np.float32)  # to the left edge of padded column p
            valid = p <= self.Xdim
        else:
            colx = np.subtract(fr.gap_b, p, dtype=np.float32)  # to its right edge
            valid = p >= 1
        inside = colx < max_x32
        result = np.where((c == 1) & inside, colx, max_x32)
        exact = (c == 0) & valid & inside
        # own column: the start cell, or (45° only) the cell touched at the corner leaving it
        corner = st.above if forward else st.below
        own_hit = fr.own if corner is None else fr.own | corner
        if own_hit.any():
            result[own_hit] = np.where(fr.own, 0.0, min(0.5, max_x))[own_hit]
            exact &= ~own_hit
            inside &= ~own_hit
        hh = np.flatnonzero((c == 2) & inside)
        false_idx, false_p = self._cross(hh, p[hh].astype(np.int64), st, fr, forward, result, max_x)
        idx = np.flatnonzero(exact)
        pp = p[idx].astype(np.int64)
        runs = fr.runs_f if forward else fr.runs_b
        while True:
            if idx.size:
                x0 = fr.x0[idx]
                dx, hit, false = self._exact(pp, st.delta[idx], st.q1[idx], x0, forward, max_x)
                result[idx[hit]] = np.minimum(dx[hit], max_x)
                false_idx = np.concatenate([false_idx, idx[false]])
                false_p = np.concatenate([false_p, pp[false]])
            if not false_idx.size:
                break
            # a false candidate: ask the bands again from the next column on; shallow rays first
            # follow the grid row they are in (rays grazing a wall would take many rounds)
            idx, cand = false_idx, false_p - 1
            if s < _ROW_SKIP_SLOPE:
                cur, settled, dx_run = self._skip_run(cand, fr.x0[idx], fr.y0[idx], forward, runs)
                result[idx[settled]] = np.minimum(dx_run[settled], max_x)
                keep = ~settled & (cur >= 0) & (cur < self.Xdim)
            else:
                cur = cand + 1 if forward else cand - 1
                keep = (cur >= 0) & (cur < self.Xdim)
            idx, cur = idx[keep], cur[keep]
            code = nb_all[st.nb_index[idx] + (cur + 1 - fr.x[idx]) * KH]
            pp = (code >> 2).astype(np.int64)
            c = code & 3
            x0 = fr.x0[idx]
            col = pp - (x0 + 1.0) if forward else x0 - pp
            near = col < max_x
            v = near & (c == 1)
            result[idx[v]] = col[v]
            h = near & (c == 2)
            false_idx, false_p = self._cross(idx[h], pp[h], st, fr, forward, result, max_x)
            keep = near & (c == 0) & ((pp <= self.Xdim) if forward else (pp >= 1))
            idx, pp = idx[keep], pp[keep]
        result *= np.float32(length * scale)
        return result

    def _cross(
        self,
        idx: np.ndarray,
        p: np.ndarray,
        st: _Starts,
        fr: _Frame,
        forward: bool,
        result: np.ndarray,
        max_x: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rays ``idx`` at an *H* candidate (padded column ``p``): record those that cross into
        the blocking row there; return the others (false candidates) and their ``p``."""
        s = self.s
        f = st.delta[idx] + self.phi[p]  # sheared row of the ray at the column's left edge, above q0
        if forward:
            row = np.floor(f)
            off = row + 1.0 - f  # rise still needed to enter the next row
            hit = off <= s + EPS
            dx = p - (fr.x0[idx] + 1.0)
        else:
            g = f + s
            row = np.floor(g)
            off = g - row  # drop (from the right edge) still needed to enter the row below
            hit = off <= s + EPS
            dx = fr.x0[idx] - p
        off *= 1.0 / s if s > 0.0 else 0.0
        np.minimum(off, 1.0, out=off)
        dx += off
        result[idx[hit]] = np.minimum(dx[hit], max_x)
        miss = ~hit
        return idx[miss], p[miss]

    def _exact(
        self, p: np.ndarray, delta: np.ndarray, q1: np.ndarray, x0: np.ndarray, forward: bool, max_x: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact test of the candidate columns (padded index ``p``, never the start column).

        Returns the X distance from the sensor to the entry of the first blocking cell the
        ray touches there, whether it touches any, and which candidates were false and
        still within ``max_x`` (the search goes on past them). Rays with no candidate are
        neither hit nor false.
        """
        s, S = self.s, self.S
        f = delta + self.phi[p]  # the ray is at sheared row q0 + f at the left edge, q0 + f + s at the right
        inv_s = 1.0 / s if s > 0.0 else 0.0
        corners = s >= 1.0 - 3.0 * EPS  # only near 45° can one column touch three rows
        if forward:
            j = np.floor(f - EPS)  # lowest row touched
            pos = p * self.W + q1 + j.astype(np.int64)
            b0, b1 = S[pos], S[pos + 1]
            reach = f + (s + EPS) - j
            b1 &= reach >= 1.0
            hit = b0 | b1
            if corners:
                hit |= S[pos + 2] & (reach >= 2.0)
            # entering sheared row q0 + m happens where f + s·(X − cand) = m: m = j + 1 (b1) or j + 2
            off = j + 2.0 - f
            off -= b1
            dx = p - (x0 + 1.0)
            valid = p <= self.Xdim
        else:
            j = np.floor(f + s + EPS)  # highest row touched
            pos = p * self.W + q1 + j.astype(np.int64)
            b0, b1 = S[pos], S[pos - 1]
            reach = j - f + EPS
            b1 &= reach > 0.0
            hit = b0 | b1
            if corners:
                hit |= S[pos - 2] & (reach > 1.0)
            # leaving down into sheared row m − 1 happens where f + s·(X − cand) = m, m = j (b1) or j − 1
            off = f + s - j
            off += ~b1
            dx = x0 - p
            valid = p >= 1
        off *= inv_s
        if s < 1e-3:  # the EPS slack divided by a tiny slope: keep the entry inside the column
            np.clip(off, 0.0, 1.0, out=off)
        off[b0] = 0.0
        false = valid & ~hit & (dx < max_x)  # the column itself is in range
        dx += off
        return dx, hit, false

    def _skip_run(
        self, cand: np.ndarray, x0: np.ndarray, y0: np.ndarray, forward: bool, runs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """After a false candidate: follow each ray along the canonical grid row it is in.

        Returns the column to search from next, whether the ray was settled inside the row
        (a blocking cell in it; or, for s = 0, none: a miss), and the X distance for those.
        """
        s = self.s
        edge = cand + 1 if forward else cand  # where the ray leaves column cand
        Yc = y0 + s * (edge - x0)
        R = np.floor(Yc)
        corner = (Yc - R < EPS) | (R + 1.0 - Yc < EPS)
        nxt = cand + 1 if forward else cand - 1
        if s > 0.0:
            # X where the ray leaves row R (forward: up through R + 1; backward: down through R)
            x_exit = x0 + ((R + 1.0 if forward else R) - y0) / s
        else:
            x_exit = np.full(x0.shape, math.inf if forward else -math.inf)
        Ri = R.astype(np.int64)
        ok = (Ri >= 0) & (Ri < self.Ydim) & (nxt >= 0) & (nxt < self.Xdim) & ~corner
        h = np.full(cand.shape, _NONE_F if forward else _NONE_B, dtype=np.int64)
        h[ok] = runs[nxt[ok], Ri[ok]]
        if forward:
            hit = ok & (h != _NONE_F) & (h <= x_exit + EPS)
            dx = h - x0
            cur = np.where(
                corner, nxt, np.maximum(nxt, np.floor(np.minimum(x_exit, 1e9) - EPS).astype(np.int64))
            )
        else:
            hit = ok & (h != _NONE_B) & (h + 1.0 >= x_exit - EPS)
            dx = x0 - (h + 1.0)
            cur = np.where(
                corner, nxt, np.minimum(nxt, np.ceil(np.maximum(x_exit, -1e9) + EPS).astype(np.int64) - 1)
            )
        gone = ~corner & ~hit & np.isinf(x_exit)  # s = 0: the row is all there is
        return cur, hit | gone, np.where(hit, dx, math.inf)


def _running_extreme(W: np.ndarray, forward: bool) -> np.ndarray:
    """Running minimum (forward: from the end) or maximum (backward) of ``W`` along axis 0, in place.

    A row-by-row loop of vectorised minima: numpy's ``accumulate`` along an outer axis does
    not vectorise and is several times slower.
    """
    n = W.shape[0]
    if forward:
        for i in range(n - 2, -1, -1):
            np.minimum(W[i], W[i + 1], out=W[i])
    else:
        for i in range(1, n):
            np.maximum(W[i], W[i - 1], out=W[i])
    return W


def _row_runs(A: np.ndarray, forward: bool) -> np.ndarray:
    """``(Xdim, Ydim)`` int32: the next (forward) or previous blocking ``X`` in each row ``Y`` of ``A``."""
    n = A.shape[0]
    none = _NONE_F if forward else _NONE_B
    idx = np.arange(n, dtype=np.int64)[:, None]
    W = (A.view(np.uint8) * (idx - none) + none).astype(np.int32)
    return _running_extreme(W, forward)
