"""Associative Markov networks on a cell grid: MAP by α-expansion, max-margin learning (Sect. 4.6.1).

The network of eq. 4.9 with the associative restriction of [22] (Taskar et al.): node i
with features x_i ∈ R^D scores label k with w_n^k · (x_i, 1), or, with ``tied`` weights, with
one w shared by the classes over class k's block of x_i and an intercept per class (for the
nearest-neighbour distances of :mod:`.nn_transform`, whose columns come class by class;
:func:`class_features`); an edge scores λ_k = w_e^k · x_ij when both
ends take the same label k and 0 otherwise, with x_ij = 1 on every edge of the 8-connected
grid (so λ_k is one number per class) and λ_k ≥ 0. MAP maximises

    Σ_i θ_i(y_i) + Σ_(ij) λ_{y_i} [y_i = y_j],      θ_i(k) = w_n^k · x_i,

i.e. minimises the energy E(y) = −(that). With λ ≥ 0 every expansion move is a submodular
binary problem (V(α,α) + V(β,γ) ≤ V(β,α) + V(α,γ) reads −λ_α − λ_β[β=γ] ≤ 0), solved exactly
by one min cut; :func:`alpha_expansion` cycles over the labels until no move lowers E.
The min cuts are PyMaxflow's (Boykov–Kolmogorov), not ours.

Learning (:class:`AMN`): the max-margin objective of [22],

    min_w  c/2 ‖w − w_0‖² + 1/N [ max_y (w·Φ(x, y) + Δ(y, y*)) − w·Φ(x, y*) ],   λ ≥ 0,

with Δ the Hamming loss (each node's weighted by 1 / (K · its class's frequency) unless
``balanced=False``) and w_0 the start (0 unless given), minimised by projected subgradient descent (Ratliff, Bagnell and
Zinkevich, 2007): each step runs loss-augmented MAP (α-expansion with Δ folded into the node
scores) and moves w along Φ(y*) − Φ(ŷ). The book's procedure solves the same objective as
one quadratic program over the LP relaxation of MAP, with marginal variables for every node
and edge and label (≈ 8,000 nodes × 30,000 edges × K here); that needs a QP solver the
project does not have and memory that grows with the map. The subgradient method needs only
the MAP solver we already have, and stops at a chosen number of passes; it keeps the
weights of the step with the lowest objective.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from knowledge.errors import NotFittedError

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

#: The 4 "forward" offsets of the 8-neighbourhood (the other 4 are their reverses).
FORWARD = ((0, 1), (1, -1), (1, 0), (1, 1))


def _maxflow() -> Any:
    """PyMaxflow (the ``iamn`` extra: GPL, so not a dependency of the MIT-licensed project)."""
    try:
        import maxflow
    except ImportError as exc:
        raise ImportError(
            "the iAMN needs PyMaxflow: pip install 'genius-loci[iamn]' (or pip install PyMaxflow; GPL-licensed)"
        ) from exc
    return maxflow


def grid_edges(cells: npt.ArrayLike, *, connectivity: int = 8) -> IntArray:
    """``(E, 2)`` index pairs (i < j by construction of the offsets) of grid neighbours among ``cells``.

    Args:
        cells: ``(N, 2)`` distinct (row, col) cells.
        connectivity: 8 (the book's grid) or 4.
    """
    C = np.asarray(cells, dtype=np.int64)
    if C.ndim != 2 or C.shape[1] != 2:
        raise ValueError(f"cells must be (N, 2) (row, col), got shape {C.shape}")
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, got {connectivity}")
    if len(C) == 0:
        return np.zeros((0, 2), dtype=np.intp)
    lo = C.min(axis=0) - 1
    shape = C.max(axis=0) - lo + 2
    index = np.full(tuple(int(s) for s in shape), -1, dtype=np.intp)
    rc = C - lo
    index[rc[:, 0], rc[:, 1]] = np.arange(len(C))
    offsets = FORWARD if connectivity == 8 else ((0, 1), (1, 0))
    pairs = []
    for dr, dc in offsets:
        j = index[rc[:, 0] + dr, rc[:, 1] + dc]
        ok = j >= 0
        pairs.append(np.column_stack([np.flatnonzero(ok), j[ok]]))
    return np.vstack(pairs).astype(np.intp)


def energy(unary: FloatArray, edges: IntArray, lam: FloatArray, labels: IntArray) -> float:
    """E(y) = −Σ_i θ_i(y_i) − Σ_(ij) λ_{y_i}[y_i = y_j] (lower is better).

    Args:
        unary: ``(N, K)`` node scores θ_i(k) (higher is better).
        edges: ``(E, 2)`` node index pairs.
        lam: ``(K,)`` λ_k ≥ 0.
        labels: ``(N,)`` label indices.
    """
    y = np.asarray(labels)
    e = -float(np.sum(unary[np.arange(len(y)), y]))
    if len(edges):
        a, b = y[edges[:, 0]], y[edges[:, 1]]
        same = a == b
        e -= float(np.sum(lam[a[same]]))
    return e


def expansion_move(
    unary: FloatArray, edges: IntArray, lam: FloatArray, labels: IntArray, alpha: int
) -> IntArray:
    """The best α-expansion of ``labels`` (each node keeps its label or switches to α), by one min cut.

    Binary variable x_i = 1 means "switch to α". The pairwise energies of an edge are
    A = V(y_i, y_j), B = V(y_i, α), C = V(α, y_j), D = V(α, α) with V(a, b) = −λ_a[a = b],
    decomposed as A + (C − A)x_i + (D − C)x_j + (B + C − A − D)(1 − x_i)x_j.
    """
    y = np.asarray(labels, dtype=np.intp)
    n = len(y)
    cost1 = -unary[:, alpha].astype(np.float64)  # energy if the node switches to α
    cost0 = -unary[np.arange(n), y].astype(np.float64)  # energy if it keeps its label
    lin = cost1 - cost0  # coefficient of x_i
    i, j = edges[:, 0], edges[:, 1]
    yi, yj = y[i], y[j]
    A = np.where(yi == yj, -lam[yi], 0.0)
    B = np.where(yi == alpha, -lam[alpha], 0.0)
    C = np.where(yj == alpha, -lam[alpha], 0.0)
    D = np.full(len(i), -lam[alpha])
    np.add.at(lin, i, C - A)
    np.add.at(lin, j, D - C)
    w = B + C - A - D  # ≥ 0 when λ ≥ 0: the move is submodular
    maxflow = _maxflow()
    g = maxflow.Graph[float](n, len(i))
    nodes = g.add_nodes(n)
    # a node in the sink segment (x = 1) pays its source capacity, one in the source segment its sink capacity
    g.add_grid_tedges(nodes, np.maximum(lin, 0.0), np.maximum(-lin, 0.0))
    keep = w > 0
    if np.any(keep):
        # edge i -> j is cut when i is in the source segment (x_i = 0) and j in the sink (x_j = 1)
        g.add_edges(nodes[i[keep]], nodes[j[keep]], w[keep], np.zeros(int(keep.sum())))
    g.maxflow()
    x = g.get_grid_segments(nodes).astype(bool)
    out = y.copy()
    out[x] = alpha
    return out


@dataclass(frozen=True)
class MapResult:
    """The labels α-expansion reached and the energy after each sweep over the labels."""

    labels: IntArray
    energies: tuple[float, ...]


def alpha_expansion(
    unary: npt.ArrayLike,
    edges: npt.ArrayLike,
    lam: npt.ArrayLike,
    *,
    init: npt.ArrayLike | None = None,
    max_sweeps: int = 10,
) -> MapResult:
    """MAP labels of the AMN by α-expansion (Boykov, Veksler and Zabih).

    Args:
        unary: ``(N, K)`` node scores θ_i(k), higher is better.
        edges: ``(E, 2)`` node index pairs.
        lam: ``(K,)`` associative edge rewards λ_k ≥ 0.
        init: ``(N,)`` start labels (default: each node's best score).
        max_sweeps: passes over all K labels at most; stops earlier when a pass changes nothing.

    Returns:
        :class:`MapResult`; ``energies[0]`` is the start's, then one value per sweep (never rising).
    """
    U = np.asarray(unary, dtype=np.float64)
    E = np.asarray(edges, dtype=np.intp).reshape(-1, 2)
    L = np.asarray(lam, dtype=np.float64)
    if U.ndim != 2 or L.shape != (U.shape[1],):
        raise ValueError(f"unary must be (N, K) and lam (K,), got {U.shape} and {L.shape}")
    if np.any(L < 0) or not np.all(np.isfinite(L)) or not np.all(np.isfinite(U)):
        raise ValueError("lam must be finite and >= 0 (associative potentials) and unary finite")
    y = np.argmax(U, axis=1) if init is None else np.asarray(init, dtype=np.intp).copy()
    if len(U) == 0:
        return MapResult(labels=y.astype(np.intp), energies=(0.0,))
    current = energy(U, E, L, y)
    energies = [current]
    for _ in range(max_sweeps):
        changed = False
        for alpha in range(U.shape[1]):
            proposal = expansion_move(U, E, L, y, alpha)
            e = energy(U, E, L, proposal)
            if e < current - 1e-9 * max(1.0, abs(current)):
                y, current, changed = proposal, e, True
        energies.append(current)
        if not changed:
            break
    return MapResult(labels=y.astype(np.intp), energies=tuple(energies))


def node_features(X: npt.ArrayLike) -> FloatArray:
    """``(N, D + 1)``: the node features and a constant 1 (the per-class intercept)."""
    A = np.asarray(X, dtype=np.float64)
    return np.hstack([A, np.ones((len(A), 1))])


def class_features(X: npt.ArrayLike, n_classes: int, *, tied: bool) -> FloatArray:
    """``(N, K, P)``: the joint features of node i taking label k, so that θ_i(k) = w · F[i, k].

    Untied (eq. 4.9): F[i, k] holds (x_i, 1) in the k-th of K blocks and zeros elsewhere, so w
    is the K weight vectors w_n^k one after the other (P = K (D + 1)). Tied: the columns of
    x_i are K equal blocks, block k describing class k (as τ_M's are), and F[i, k] is block k
    followed by the one-hot of k (P = D / K + K): one weight per neighbour rank, shared by the
    classes, and a per-class intercept.
    """
    A = np.asarray(X, dtype=np.float64)
    N, K = len(A), n_classes
    if not tied:
        Fn = node_features(A)
        out = np.zeros((N, K, K * Fn.shape[1]))
        for k in range(K):
            out[:, k, k * Fn.shape[1] : (k + 1) * Fn.shape[1]] = Fn
        return out
    if A.shape[1] % K:
        raise ValueError(f"tied weights need K={K} equal blocks of columns, got {A.shape[1]} columns")
    M = A.shape[1] // K
    out = np.zeros((N, K, M + K))
    for k in range(K):
        out[:, k, :M] = A[:, k * M : (k + 1) * M]
        out[:, k, M + k] = 1.0
    return out


class AMN:
    """A pairwise associative Markov network on a grid, learned max-margin (see the module doc).

    Args:
        C: weight of the regulariser c/2 ‖w − w_0‖² (per node, the loss is averaged over nodes).
        epochs: subgradient steps.
        step: initial step size; step t uses step / √t.
        max_sweeps: α-expansion sweeps per MAP.
        balanced: weigh each node's Hamming loss by 1 / (K · frequency of its true class), so
            a rare class (doorways: 5 % of the nodes) is not given up for the margin of the others.
        tied: share the node weights between classes (:func:`class_features`); far fewer
            parameters (M + K instead of K (K M + 1) on τ_M), so less to overfit on one map.

    Fitted attributes: ``w_node_`` ``(P,)`` (the node weights over :func:`class_features`),
    ``w_edge_`` ``(K,)`` (λ, ≥ 0), ``n_classes_``, ``history_`` (the training objective per step).
    """

    def __init__(
        self,
        *,
        C: float = 1e-3,
        epochs: int = 60,
        step: float = 0.5,
        max_sweeps: int = 5,
        balanced: bool = True,
        tied: bool = False,
    ) -> None:
        self.C = C
        self.epochs = epochs
        self.step = step
        self.max_sweeps = max_sweeps
        self.balanced = balanced
        self.tied = tied

    @staticmethod
    def _phi(F3: FloatArray, edges: IntArray, y: IntArray, K: int) -> tuple[FloatArray, FloatArray]:
        node = F3[np.arange(len(y)), y].sum(axis=0)
        a, b = y[edges[:, 0]], y[edges[:, 1]]
        edge = np.bincount(a[a == b], minlength=K).astype(np.float64)
        return node, edge

    def fit(
        self,
        X: npt.ArrayLike,
        edges: npt.ArrayLike,
        y: npt.ArrayLike,
        n_classes: int,
        *,
        init: npt.ArrayLike | None = None,
    ) -> AMN:
        """Learn w from one labelled network: node features ``(N, D)``, edges ``(E, 2)``, labels ``(N,)``.

        ``init``: start node weights ``(P,)`` over :func:`class_features` (default 0), e.g. a
        rule known to be good; the regulariser then reads c/2 ‖w_n − init‖² + c/2 ‖λ‖², so a
        large ``C`` keeps the node weights near that rule and learns mostly the edge rewards.
        """
        A = np.asarray(X, dtype=np.float64)
        E = np.asarray(edges, dtype=np.intp).reshape(-1, 2)
        truth = np.asarray(y, dtype=np.intp)
        if truth.shape != (len(A),) or len(A) == 0:
            raise ValueError(f"need one label per node and at least one node, got {truth.shape} for {len(A)}")
        if truth.min() < 0 or truth.max() >= n_classes:
            raise ValueError(f"labels must be in 0..{n_classes - 1}")
        K, n = n_classes, len(A)
        F3 = class_features(A, K, tied=self.tied)
        P = F3.shape[2]
        W = np.zeros(P) if init is None else np.array(init, dtype=np.float64)
        if W.shape != (P,):
            raise ValueError(f"init must be ({P},), got {W.shape}")
        W0 = W.copy()  # the regulariser pulls towards the start, not towards 0
        lam = np.zeros(K)
        phi_n, phi_e = self._phi(F3, E, truth, K)
        counts = np.bincount(truth, minlength=K).astype(np.float64)
        weight = n / (np.count_nonzero(counts) * np.maximum(counts, 1.0)) if self.balanced else np.ones(K)
        loss_aug = np.repeat(weight[truth][:, None], K, axis=1)
        loss_aug[np.arange(n), truth] = 0.0  # the (weighted) Hamming loss folded into the node scores
        history: list[float] = []
        best = (np.inf, W.copy(), lam.copy())
        for t in range(1, self.epochs + 1):
            unary = F3 @ W + loss_aug
            y_hat = alpha_expansion(unary, E, lam, max_sweeps=self.max_sweeps).labels
            h_n, h_e = self._phi(F3, E, y_hat, K)
            margin = float(
                (W @ h_n + lam @ h_e + np.sum(loss_aug[np.arange(n), y_hat])) - (W @ phi_n + lam @ phi_e)
            )
            obj = 0.5 * self.C * float(np.sum((W - W0) ** 2) + lam @ lam) + max(margin, 0.0) / n
            history.append(float(obj))
            if obj < best[0]:
                best = (obj, W.copy(), lam.copy())
            eta = self.step / np.sqrt(t)
            W -= eta * (self.C * (W - W0) + (h_n - phi_n) / n)
            lam = np.maximum(lam - eta * (self.C * lam + (h_e - phi_e) / n), 0.0)
        # the last subgradient step is not the best one: keep the lowest objective seen
        self.w_node_, self.w_edge_ = best[1], best[2]
        self.n_classes_ = K
        self.history_ = tuple(history)
        return self

    def set_weights(self, w_node: npt.ArrayLike, w_edge: npt.ArrayLike) -> AMN:
        """Restore fitted weights (as stored in a model file)."""
        self.w_node_ = np.asarray(w_node, dtype=np.float64)
        self.w_edge_ = np.asarray(w_edge, dtype=np.float64)
        self.n_classes_ = len(self.w_edge_)
        return self

    def scores(self, X: npt.ArrayLike) -> FloatArray:
        """``(N, K)`` node scores θ_i(k)."""
        if not hasattr(self, "w_node_"):
            raise NotFittedError("AMN is not fitted: call fit(...) first")
        return np.asarray(class_features(X, self.n_classes_, tied=self.tied) @ self.w_node_)

    def predict(self, X: npt.ArrayLike, edges: npt.ArrayLike) -> MapResult:
        """MAP labels ``(N,)`` of a network (node features ``(N, D)``, edges ``(E, 2)``)."""
        return alpha_expansion(self.scores(X), edges, self.w_edge_, max_sweeps=self.max_sweeps)
