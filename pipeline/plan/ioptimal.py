"""I-optimal selection of measurements (pure numpy): minimise the average predicted variance of
the tool point over evaluation configurations spread across the workspace.

Candidate j contributes a block A_j (k × P: its residuals' Jacobian over the P identifiable
parameters, divided by the noise σ).  With prior information M₀ (P × P; a tiny ridge when there
is none) the parameter covariance of a selection S is Σ(S) = (M₀ + Σ_{j∈S} A_jᵀA_j)⁻¹, and the
criterion is

    I(S) = mean_t tr(G_t Σ G_tᵀ) = tr(H Σ),   H = mean_t G_tᵀ G_t,

G_t (3 × P) the tool-point Jacobian at evaluation configuration t: the mean squared 3-D error
of the calibrated model there (m²).  Selection:

1. **greedy**: add the block with the largest drop tr((I + A_jΣA_jᵀ)⁻¹ A_jΣHΣA_jᵀ)
   (Sherman–Morrison–Woodbury), Σ kept by rank-k updates;
2. **exchange** (Fedorov): the change of I for swapping a selected i with an unselected j is
   evaluated for every pair at once from k × k blocks (module `_swap_deltas`); the best swap is
   made while it lowers I by more than `tol` (relative), so an exchange never worsens the criterion.

Every step is vectorised over candidates (no per-candidate Python loop).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np


@dataclass
class ISelection:
    index: np.ndarray  # (m,) selected candidate indices
    value: float  # I(S): mean predicted squared tool-point error, m²
    greedy_value: float
    exchanges: int
    elapsed_s: float
    history: list[float] = field(default_factory=list)  # I after the greedy step and after each exchange


def eval_matrix(G: np.ndarray) -> np.ndarray:
    """H = mean_t G_tᵀG_t (P × P) from tool-point Jacobians G (T, 3, P) at evaluation configurations."""
    G = np.asarray(G, float)
    return np.einsum("tip,tiq->pq", G, G) / G.shape[0]


def criterion(A: np.ndarray, idx: np.ndarray, info0: np.ndarray, H: np.ndarray) -> float:
    """I(S) = tr(H (M₀ + Σ_{j∈S} A_jᵀA_j)⁻¹), computed directly (for checks and reports)."""
    B = np.asarray(A, float)[np.asarray(idx, int)].reshape(-1, A.shape[-1])
    return float(np.trace(H @ np.linalg.inv(info0 + B.T @ B)))


def _blocks(A: np.ndarray) -> np.ndarray:
    A = np.asarray(A, float)
    return A[:, None, :] if A.ndim == 2 else A


def _update(Sigma: np.ndarray, a: np.ndarray, sign: float = 1.0) -> np.ndarray:
    """(Σ⁻¹ ± aᵀa)⁻¹ from Σ for a block a (k × P)."""
    U = a @ Sigma  # k × P
    S = sign * np.eye(a.shape[0]) + U @ a.T
    return Sigma - U.T @ np.linalg.solve(S, U)


def greedy(A: np.ndarray, m: int, info0: np.ndarray, H: np.ndarray, allowed: np.ndarray | None = None,
           groups: np.ndarray | None = None) -> np.ndarray:
    """Greedy I-optimal order of m blocks of A (N, k, P).  With `groups` (N,) ints, the first
    picks cover every group that has an allowed candidate (one each, best first), then free."""
    A = _blocks(A)
    N, k, _ = A.shape
    Sigma = np.linalg.inv(info0)
    chosen = np.zeros(N, bool) if allowed is None else ~np.asarray(allowed, bool)
    todo = set() if groups is None else set(np.unique(groups[~chosen]).tolist())
    order: list[int] = []
    I = np.eye(k)
    for _ in range(min(m, int((~chosen).sum()))):
        U = A @ Sigma  # (N, k, P): A_jΣ
        if k == 1:
            gain = np.einsum("np,np->n", U[:, 0] @ H, U[:, 0]) / (1 + np.einsum("np,np->n", U[:, 0], A[:, 0]))
        else:
            D = U @ np.swapaxes(A, 1, 2)
            W = (U @ H) @ np.swapaxes(U, 1, 2)
            gain = np.trace(np.linalg.solve(I + D, W), axis1=1, axis2=2)
        gain[chosen] = -np.inf
        if todo:
            gain[~np.isin(groups, list(todo))] = -np.inf
        j = int(np.argmax(gain))
        chosen[j] = True
        order.append(j)
        if todo:
            todo.discard(int(groups[j]))
        Sigma = _update(Sigma, A[j])
    return np.array(order, int)


def _swap_deltas(A_in: np.ndarray, A_out: np.ndarray, Sigma: np.ndarray, H: np.ndarray) -> np.ndarray:
    """ΔI (m, n) for swapping each selected block i for each candidate j.
    Removing i: Σ₋ = Σ + U_iᵀE_iU_i (U = AΣ, E_i = (I − D_ii)⁻¹, D_xy = A_xΣA_yᵀ), I rises by
    tr(E_i W_ii) (W_xy = U_x H U_yᵀ); adding j then lowers it by tr(S⁻¹ V H Vᵀ) with
    V = U_j + F_ijᵀU_i (F_ij = E_i D_ij), S = I + D_jj + D_ijᵀF_ij, so that
    VHVᵀ = W_jj + F_ijᵀW_ij + W_ijᵀF_ij + F_ijᵀW_iiF_ij.  Only k × k blocks per pair."""
    k = A_in.shape[1]
    if k == 1:
        return _swap_deltas_rows(A_in[:, 0], A_out[:, 0], Sigma, H)
    I = np.eye(k)
    U_i = np.einsum("mkp,pq->mkq", A_in, Sigma)
    U_j = np.einsum("nkp,pq->nkq", A_out, Sigma)
    HU_i = np.einsum("mkp,pq->mkq", U_i, H)
    D_ii = np.einsum("mkp,mlp->mkl", U_i, A_in)
    W_ii = np.einsum("mkp,mlp->mkl", HU_i, U_i)
    E = np.linalg.inv(I - D_ii)
    rise = np.trace(E @ W_ii, axis1=1, axis2=2)
    D_jj = np.einsum("nkp,nlp->nkl", U_j, A_out)
    W_jj = (U_j @ H) @ np.swapaxes(U_j, 1, 2)
    D_ij = np.einsum("mkp,nlp->mnkl", U_i, A_out)
    W_ij = np.einsum("mkp,nlp->mnkl", HU_i, U_j)
    F = np.einsum("mab,mnbc->mnac", E, D_ij)
    Ft = np.swapaxes(F, 2, 3)
    S = I + D_jj[None] + np.einsum("mnba,mnbc->mnac", D_ij, F)
    VHV = (W_jj[None] + Ft @ W_ij + np.swapaxes(W_ij, 2, 3) @ F
           + np.einsum("mnab,mbc,mncd->mnad", Ft, W_ii, F))
    drop = np.trace(np.linalg.solve(S, VHV), axis1=2, axis2=3)
    ok = np.all(np.linalg.eigvalsh(I - D_ii) > 1e-12, axis=1)  # a block carrying all the information cannot go
    return np.where(ok[:, None], rise[:, None] - drop, np.inf)


def _swap_deltas_rows(a_in: np.ndarray, a_out: np.ndarray, Sigma: np.ndarray, H: np.ndarray) -> np.ndarray:
    """`_swap_deltas` for one-row blocks (k = 1): the same formulas with scalars per pair."""
    U_i, U_j = a_in @ Sigma, a_out @ Sigma
    HU_i = U_i @ H
    d_ii, w_ii = np.einsum("mp,mp->m", U_i, a_in), np.einsum("mp,mp->m", HU_i, U_i)
    d_jj, w_jj = np.einsum("np,np->n", U_j, a_out), np.einsum("np,np->n", U_j @ H, U_j)
    D, W = U_i @ a_out.T, HU_i @ U_j.T  # (m, n)
    ok = 1 - d_ii > 1e-12
    e = 1 / np.where(ok, 1 - d_ii, 1.0)
    F = e[:, None] * D
    drop = (w_jj[None] + 2 * F * W + F**2 * w_ii[:, None]) / (1 + d_jj[None] + D * F)
    return np.where(ok[:, None], (e * w_ii)[:, None] - drop, np.inf)


def exchange(A: np.ndarray, sel: np.ndarray, info0: np.ndarray, H: np.ndarray, allowed: np.ndarray | None = None,
             max_exchanges: int | None = None, tol: float = 1e-6,
             groups: np.ndarray | None = None) -> tuple[np.ndarray, list[float]]:
    """Fedorov exchange from selection `sel`: best swap while it lowers I by > tol·I.  With
    `groups` (N,), a swap may not leave a group the selection covers uncovered.  Returns
    (selection, I after each accepted swap, starting with the initial value)."""
    A = _blocks(A)
    N = A.shape[0]
    sel = np.array(sel, int)
    inside = np.zeros(N, bool)
    inside[sel] = True
    pool_ok = np.ones(N, bool) if allowed is None else np.asarray(allowed, bool)
    B = A[sel].reshape(-1, A.shape[-1])
    Sigma = np.linalg.inv(info0 + B.T @ B)
    value = float(np.trace(H @ Sigma))
    history = [value]
    limit = 10 * sel.size if max_exchanges is None else max_exchanges
    for n_ex in range(limit):
        out = np.flatnonzero(~inside & pool_ok)
        if out.size == 0:
            break
        d = _swap_deltas(A[sel], A[out], Sigma, H)
        if groups is not None:
            gi, gj = groups[sel], groups[out]
            count = np.bincount(gi, minlength=int(groups.max()) + 1)
            d[~((count[gi] > 1)[:, None] | (gi[:, None] == gj[None, :]))] = np.inf
        i_pos, j_pos = np.unravel_index(int(np.argmin(d)), d.shape)
        if not d[i_pos, j_pos] < -tol * value:
            break
        i, j = int(sel[i_pos]), int(out[j_pos])
        Sigma = _update(_update(Sigma, A[j]), A[i], sign=-1.0)
        inside[i], inside[j] = False, True
        sel[i_pos] = j
        if (n_ex + 1) % 10 == 0:  # refresh against round-off
            B = A[sel].reshape(-1, A.shape[-1])
            Sigma = np.linalg.inv(info0 + B.T @ B)
        value = float(np.trace(H @ Sigma))
        history.append(value)
    return sel, history


def select(A: np.ndarray, m: int, info0: np.ndarray, H: np.ndarray, allowed: np.ndarray | None = None,
           groups: np.ndarray | None = None, max_exchanges: int | None = None, tol: float = 1e-6) -> ISelection:
    """I-optimal m of the N blocks A (N, k, P): greedy (covering `groups` first), then exchange
    (keeping the coverage)."""
    t0 = time.perf_counter()
    A = _blocks(A)
    sel = greedy(A, m, info0, H, allowed, groups)
    g0 = criterion(A, sel, info0, H)
    sel, hist = exchange(A, sel, info0, H, allowed, max_exchanges, tol, groups)
    return ISelection(index=sel, value=criterion(A, sel, info0, H), greedy_value=g0, exchanges=len(hist) - 1,
                      elapsed_s=time.perf_counter() - t0, history=hist)
