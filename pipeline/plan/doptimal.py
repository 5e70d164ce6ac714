"""D-optimal selection of M measurements out of N candidates (pure numpy).

Candidate j contributes a block A_j (k × L: its residuals' Jacobian over the L free
parameters) to the information matrix  M(S) = Σ_{j∈S} A_jᵀ A_j.  We maximise log det M(S):

1. **greedy**: add the candidate with the largest gain log det(I + A_j M⁻¹ A_jᵀ) (matrix
   determinant lemma), M⁻¹ kept by Sherman–Morrison–Woodbury updates; a tiny ridge makes
   the first L steps well defined;
2. **exchange** (Fedorov 1972): swap the selected i / unselected j pair with the largest
   det ratio det(M − A_iᵀA_i + A_jᵀA_j)/det M = det([[I + D_jj, D_ji], [−D_ij, I − D_ii]])
   (D_xy = A_x M⁻¹ A_yᵀ), evaluated for all M×(N−M) pairs at once, until no swap gains.

Every step is vectorised over candidates; cost per step O(N·k·L²).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from pipeline.errors import RobocalError


@dataclass
class Selection:
    index: np.ndarray  # (M,) selected candidate indices, in selection order
    logdet: float  # log det of the information matrix of the selection (scaled columns)
    greedy_logdet: float
    exchanges: int
    elapsed_s: float
    history: list[float] = field(default_factory=list)  # logdet after each exchange


def scale(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Columns scaled so the information of *all* candidates has unit diagonal (units drop out;
    D-optimality is invariant to it, the arithmetic is better conditioned)."""
    norms = np.sqrt(np.einsum("nkp,nkp->p", A, A))
    norms = np.where(norms > 0, norms, 1.0)
    return A / norms, norms


def logdet_info(A: np.ndarray, idx: np.ndarray) -> float:
    """log det Σ_{j∈idx} A_jᵀA_j (−inf if singular)."""
    B = A[idx].reshape(-1, A.shape[-1])
    sign, ld = np.linalg.slogdet(B.T @ B)
    return float(ld) if sign > 0 else -np.inf


def woodbury_update(Minv: np.ndarray, a: np.ndarray, sign: float = 1.0) -> np.ndarray:
    """(M ± aᵀa)⁻¹ from M⁻¹ for a block a (k × L)."""
    Ma = Minv @ a.T  # L × k
    S = np.eye(a.shape[0]) * sign + a @ Ma
    return Minv - Ma @ np.linalg.solve(S, Ma.T)


class SelectionError(RobocalError, ValueError):
    """The requested selection is impossible (more than the candidates, or too few to identify)."""


def select(A: np.ndarray, m: int, *, ridge: float = 1e-8, max_exchanges: int | None = None,
           tol: float = 1e-9) -> Selection:
    """Choose `m` of the N candidate blocks A (N, k, L) maximising log det of the information."""
    t0 = time.perf_counter()
    A = np.asarray(A, float)
    if A.ndim == 2:
        A = A[:, None, :]
    N, k, L = A.shape
    if not L <= m * k or m > N:
        raise SelectionError(f"cannot select {m} of {N} candidates for {L} identifiable parameters ({k} residuals "
                             f"each): need --select ≤ --candidates and --select × {k} ≥ {L}")
    A, _ = scale(A)
    Minv = np.eye(L) / ridge
    chosen = np.zeros(N, bool)
    order: list[int] = []
    I = np.eye(k)
    for _ in range(m):  # greedy
        MA = np.einsum("pq,nkq->nkp", Minv, A)  # M⁻¹ A_jᵀ for every j
        D = np.einsum("nkp,nlp->nkl", A, MA)  # A_j M⁻¹ A_jᵀ
        gain = np.linalg.slogdet(I + D)[1]
        gain[chosen] = -np.inf
        j = int(np.argmax(gain))
        chosen[j] = True
        order.append(j)
        Minv = woodbury_update(Minv, A[j])
    sel = np.array(order)
    Minfo = np.einsum("nkp,nkq->pq", A[sel], A[sel])
    Minv = np.linalg.inv(Minfo)
    greedy = logdet_info(A, sel)
    ld = greedy
    history = [ld]
    n_ex = 0
    limit = max_exchanges if max_exchanges is not None else 10 * m
    while n_ex < limit:
        out = np.flatnonzero(~chosen)
        MA_in = np.einsum("pq,skq->skp", Minv, A[sel])  # (m, k, L)
        D_ii = np.einsum("skp,slp->skl", A[sel], MA_in)  # (m, k, k)
        D_ij = np.einsum("skp,nlp->snkl", MA_in, A[out])  # A_j M⁻¹ A_iᵀ arranged (i, j, k, k): D_ji = A_j M⁻¹ A_iᵀ
        MA_out = np.einsum("pq,nkq->nkp", Minv, A[out])
        D_jj = np.einsum("nkp,nlp->nkl", A[out], MA_out)  # (n, k, k)
        s, n = sel.size, out.size
        B = np.empty((s, n, 2 * k, 2 * k))
        B[:, :, :k, :k] = I + D_jj[None]
        B[:, :, :k, k:] = np.swapaxes(D_ij, 2, 3)  # D_ji = A_j M⁻¹ A_iᵀ (k×k)
        B[:, :, k:, :k] = -D_ij  # −D_ij = −A_i M⁻¹ A_jᵀ
        B[:, :, k:, k:] = I - D_ii[:, None]
        sign, lr = np.linalg.slogdet(B)
        lr = np.where(sign > 0, lr, -np.inf)
        best = np.unravel_index(int(np.argmax(lr)), lr.shape)
        if lr[best] <= tol:
            break
        i_pos, j_pos = int(best[0]), int(best[1])
        i, j = int(sel[i_pos]), int(out[j_pos])
        Minv = woodbury_update(woodbury_update(Minv, A[j]), A[i], sign=-1.0)
        chosen[i], chosen[j] = False, True
        sel[i_pos] = j
        n_ex += 1
        if n_ex % 10 == 0:  # refresh against round-off
            Minv = np.linalg.inv(np.einsum("nkp,nkq->pq", A[sel], A[sel]))
        ld = ld + float(lr[best])
        history.append(ld)
    return Selection(index=sel, logdet=logdet_info(A, sel), greedy_logdet=greedy, exchanges=n_ex,
                     elapsed_s=time.perf_counter() - t0, history=history)
