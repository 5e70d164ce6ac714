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
