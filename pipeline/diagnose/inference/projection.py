"""Orthonormal bases and projections (the linear algebra every diagnosis step shares)."""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.special
import scipy.stats


def orthonormal(A: np.ndarray, rel_tol: float = 1e-9) -> np.ndarray:
    """Orthonormal basis (n, r) of the columns of A (column-scaled, rank-revealing QR)."""
    if A.size == 0 or A.shape[1] == 0:
        return np.zeros((A.shape[0], 0))
    norms = np.linalg.norm(A, axis=0)
    keep = norms > 0
    if not keep.any():
        return np.zeros((A.shape[0], 0))
    As = A[:, keep] / norms[keep]
    Q, R, _ = scipy.linalg.qr(As, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    return Q[:, : int(np.sum(d > rel_tol * max(d[0], 1e-300)))]


def project_out(A: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """(I − QQᵀ)A."""
    return A - Q @ (Q.T @ A) if Q.shape[1] else A.copy()


def residual_of(D: np.ndarray, y: np.ndarray, rel_tol: float = 1e-12) -> np.ndarray:
    """y's least-squares residual (n,) on the columns of D (n, c), for a tall D: the normal equations of the
    unit-scaled columns solved on their eigenbasis (directions whose eigenvalue is below `rel_tol` of the largest
    left out: singular values below 10⁻⁶ of the largest, where a rank-revealing QR keeps down to 10⁻⁹), then one
    step of iterative refinement (the semi-normal equations, Björck) — n·c² work in a matrix product instead of a
    pivoted QR of D; for estimates of the noise (a near-degenerate direction of D left in e changes its RMS by
    ~10⁻⁴ of itself), not for tests."""
    norms = np.linalg.norm(D, axis=0)
    Ds = D / np.where(norms > 0, norms, 1.0)
    w, V = np.linalg.eigh(Ds.T @ Ds)
    keep = w > rel_tol * max(w[-1], 1e-300) if w.size else np.zeros(0, bool)
    V, w = V[:, keep], w[keep]
    e = np.asarray(y, float).copy()
    for _ in range(2):  # the solve, then one refinement on its residual
        e -= Ds @ (V @ ((V.T @ (Ds.T @ e)) / w))
    return e
