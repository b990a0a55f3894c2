"""Checks against definitions written independently of the fast code (a reviewer's oracles).

- relaxation: eq. 4.6/4.7 evaluated literally, cell by cell, neighbour by neighbour;
- Fourier descriptors: the FFT of the boundary resampled densely at equal arc length;
- ray casting: dense sampling along each beam (2 mm steps) instead of a cell walk.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.raycast import cast, cast_cells
from knowledge.places.features import FeatureExtractor
from knowledge.places.relaxation import DIRECTIONS, CompatibilityStats, relax


@pytest.mark.parametrize("per_direction", [False, True])
def test_relaxation_matches_the_literal_formula(per_direction: bool) -> None:
    rng = np.random.default_rng(0)
    H, W, K = 9, 11, 4  # three place classes + wall
    occ = rng.random((H, W)) < 0.25
    lab = rng.integers(1, 4, (H, W)).astype(np.uint8)
    lab[occ] = 0
    stats = CompatibilityStats.from_label_images(
        [(lab, occ)], (1, 2, 3), per_direction=per_direction, smoothing=1.0
    )
    free = ~occ
    P0 = rng.dirichlet([1, 1, 1], size=(H, W))
    P = np.zeros((H, W, K))
    P[free, :3] = P0[free]
    P[~free, 3] = 1.0
    wall = np.array([0.0, 0.0, 0.0, 1.0])  # outside the map counts as wall
    for _ in range(3):
        Q = np.zeros_like(P)
        for r in range(H):
            for c in range(W):
                q = np.zeros(K)
                for d, (dr, dc) in enumerate(DIRECTIONS):
                    rr, cc = r + dr, c + dc
                    pj = P[rr, cc] if 0 <= rr < H and 0 <= cc < W else wall
                    q += (1 / 8) * stats.r_for(d).astype(np.float64) @ pj  # eq. 4.7, o_ij = 1/8
                u = P[r, c] * (1 + q)  # eq. 4.6
                Q[r, c] = u / u.sum()
        P = Q
    backends = ("numpy",) if per_direction else ("numpy", "cv2")
    for backend in backends:
        R = relax(P0.astype(np.float32), stats, free_mask=free, iterations=3, backend=backend)  # type: ignore[arg-type]
        assert np.abs(R - P).max() < 1e-5, backend


def test_fourier_descriptors_match_an_fft_of_the_resampled_boundary() -> None:
    rng = np.random.default_rng(5)
    M = 360
    d = 2 + np.abs(np.cumsum(rng.normal(0, 0.05, M))) + 1.0 * (np.arange(M) % 90 < 10)
    orders = (-1, 2, -2, 3, 5, -7, 20, -33)
    names = [f"B.6[n={n}]" for n in orders] + ["B.7", "B.8"]
    got = np.atleast_2d(FeatureExtractor(names, max_range=30.0, dtype=np.float64)(d))[0]
    z = d * np.exp(1j * np.arange(M) * 2 * math.pi / M)
    zc = np.append(z, z[0])
    seg = np.abs(np.diff(zc))
    t = np.concatenate([[0.0], np.cumsum(seg)])
    N = 2**18
    ts = np.arange(N) * t[-1] / N
    k = np.searchsorted(t, ts, side="right") - 1
    zs = zc[k] + (ts - t[k]) / seg[k] * (zc[k + 1] - zc[k])
    C = np.fft.fft(zs) / N  # C[n] ≈ c_n for z(t) = Σ c_n e^{j 2π n t / T}

    def c(n: int) -> complex:
        return complex(C[n % N])

    want = [abs(c(n)) / abs(c(1)) for n in orders] + [abs(c(1)) + abs(c(-1)), abs(abs(c(1)) - abs(c(-1)))]
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-7)


def _sampled_range(
    grid: OccupancyGrid,
    occ: np.ndarray,
    x: float,
    y: float,
    a: float,
    max_range: float,
    t: np.ndarray | None = None,
) -> float:
    """The first sample along the beam that lies in an occupied cell (2 mm steps by default)."""
    if t is None:
        t = np.arange(0.0, max_range, 0.002)
    rc = grid.world_to_cell(np.column_stack([x + t * math.cos(a), y + t * math.sin(a)]))
    inb = grid.in_bounds(rc)
    hit = np.zeros(len(t), bool)
    hit[inb] = occ[rc[inb, 0], rc[inb, 1]]
    k = np.flatnonzero(hit)
    return float(t[k[0]]) if k.size else max_range


def test_casters_agree_with_dense_sampling_along_the_beams() -> None:
    """Within 2 cm (sampling step plus grazing hits), except on the 45° beams.

    Exactly diagonal beams from cell centres pass through grid corners, where the casters
    close corners (documented in knowledge/metric/raycast.py) and dense sampling does not.
    """
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(6):
        H, W = int(rng.integers(10, 30)), int(rng.integers(10, 30))
        occ = rng.random((H, W)) < 0.15
        yaw = float(rng.uniform(-3, 3))
        g = OccupancyGrid.from_masks(occ, 0.1, origin=(float(rng.normal()), float(rng.normal()), yaw))
        cells = g.free_cells()
        sel = cells[rng.choice(len(cells), min(8, len(cells)), replace=False)]
        R = cast_cells(g, sel, n_beams=72, max_range=5.0)
        xy = g.cell_to_world(sel)
        poses = np.column_stack([xy, np.full(len(sel), yaw)])
        Rp = cast(g, poses, n_beams=72, max_range=5.0)
        np.testing.assert_allclose(Rp, R, atol=1e-5)
        for i, (x, y) in enumerate(xy):
            for j in range(72):
                if (j * 5) % 45 == 0:
                    continue
                a = yaw + j * 2 * math.pi / 72
                ref = _sampled_range(g, occ, float(x), float(y), a, 5.0)
                if R[i, j] < ref - 0.02:
                    # a hit the 2 mm steps jumped over: the ray may clip a cell's corner by less
                    # than a step; sample 1 µm steps around the caster's hit to find it
                    fine = np.arange(max(0.0, R[i, j] - 0.005), R[i, j] + 0.005, 1e-6)
                    ref = _sampled_range(g, occ, float(x), float(y), a, 5.0, t=fine)
                assert abs(R[i, j] - ref) <= 0.02, (i, j, R[i, j], ref)
                checked += 1
    assert checked > 2000
