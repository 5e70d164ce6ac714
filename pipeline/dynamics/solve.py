"""Least-squares solvers of the linear dynamics model y = X θ: ordinary, weighted (per-joint noise,
Gautier's two-step), and physically consistent (each body's pseudo-inertia positive semidefinite, friction
and armature non-negative: a semidefinite programme solved by cvxpy).

Inputs are the rows of the fitted joints, X (T, F, P) and y (T, F) (N·m, N); outputs θ (P,).  OLS and WLS
solve on the base columns (`base.BaseSet`) and set the dependent ones to 0 (any θ with the same base
parameters predicts the same torques).  The consistent solve works on every parameter: what the data
cannot fix is held near the URDF's values by a small ridge, `ridge` × each column's energy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.dynamics.base import BaseSet
from pipeline.dynamics.rigid_body import pseudo_inertia


@dataclass(frozen=True)
class Solution:
    """θ (P,), the base parameters β (r,) with their standard deviations (r,), per-joint residual σ (F,)."""

    theta: np.ndarray
    beta: np.ndarray
    beta_std: np.ndarray
    sigma: np.ndarray
    solver: str


def _lstsq(Xb: np.ndarray, y: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(β, cov β) of rows Xb (T, F, r), y (T, F), row weights w (F,) (1/σ per joint).  Solved through the
    r × r normal equations (the regressor is column-scaled first: its condition stays ~10³–10⁴, squared
    well within double precision), so a fold costs one matrix product, not a LAPACK least squares.  Rows left out
    of the fit come zeroed (`identify.prepare`): the residual variance is over the rows fitted, not all T·F."""
    T, F, r = Xb.shape
    A = Xb.reshape(T * F, r)
    b = y.reshape(T * F)
    if w is not None:
        ww = np.tile(w, T)
        A, b = A * ww[:, None], b * ww
    s = np.sqrt(np.einsum("ij,ij->j", A, A))
    s = np.where(s > 0, s, 1.0)
    G = (A.T @ A) / np.outer(s, s)
    h = (A.T @ b) / s
    Gi = np.linalg.pinv(G, hermitian=True)
    beta = (Gi @ h) / s
    res = b - A @ beta
    s2 = float(res @ res) / max(int(np.count_nonzero(np.any(A != 0, axis=1))) - r, 1)
    cov = Gi / np.outer(s, s) * (1.0 if w is not None else s2)
    return beta, cov


def _sigma(X: np.ndarray, y: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Per-joint residual RMS (F,) over the rows fitted (a row left out of the fit is zeroed: not counted)."""
    r = y - X @ theta
    used = np.any(X != 0, axis=2)
    return np.sqrt(np.sum(r**2, axis=0) / np.maximum(used.sum(axis=0), 1))


def ols(X: np.ndarray, y: np.ndarray, base: BaseSet) -> Solution:
    beta, cov = _lstsq(X[:, :, base.independent], y)
    theta = np.zeros(X.shape[2])
    theta[base.independent] = beta
    return Solution(theta, beta, np.sqrt(np.diag(cov)), _sigma(X, y, theta), "ols")


def wls(X: np.ndarray, y: np.ndarray, base: BaseSet) -> Solution:
    """Weighted least squares: each joint's rows weighted by 1/σ_j of its OLS residual (Gautier 1997)."""
    s0 = ols(X, y, base).sigma
    w = 1.0 / np.maximum(s0, 1e-12)
    beta, cov = _lstsq(X[:, :, base.independent], y, w)
    theta = np.zeros(X.shape[2])
    theta[base.independent] = beta
    return Solution(theta, beta, np.sqrt(np.diag(cov)), _sigma(X, y, theta), "wls")


def consistent(X: np.ndarray, y: np.ndarray, base: BaseSet, n_bodies: int, prior: np.ndarray,
               carried: np.ndarray, nonneg: np.ndarray, ridge: float = 1e-4, margin: float = 1e-6,
               weighted: bool = True) -> Solution:
    """min ‖X θ − y‖² + ridge·Σ_p e_p (θ_p − prior_p)²  s.t. pseudo_inertia(π_link,k) ⪰ margin·1 for every body
    k (π = π_link + carried, the locked subtrees at their URDF values) and θ_p ≥ 0 where `nonneg` (viscous,
    Coulomb, armature); e_p the energy of column p; `weighted`: each joint's rows weighted by 1/σ_j of its
    OLS residual, as `wls`.  Returns θ with π the bodies' whole parameters."""
    import cvxpy as cp

    T, F, P = X.shape
    n = 10 * n_bodies
    w = 1.0 / np.maximum(ols(X, y, base).sigma, 1e-12) if weighted else np.ones(F)
    A = (X * w[None, :, None]).reshape(T * F, P)
    b = ((y - X[:, :, :n] @ carried) * w).reshape(T * F)  # fit the links' own parameters
    scale = np.sqrt(np.einsum("ij,ij->j", A, A))
    scale = np.where(scale > 0, scale, 1.0)
    As = A / scale
    lam, V = np.linalg.eigh(As.T @ As)  # ‖As z − b‖² = ‖Ra z‖² − 2 gᵀz + ‖b‖², Ra = Λ^½ Vᵀ
    Ra = np.sqrt(np.clip(lam, 0, None))[:, None] * V.T
    g = As.T @ b
    z = cp.Variable(P)  # θ_link · scale
    prior_z = np.r_[prior[:n] - carried, prior[n:]] * scale
    obj = cp.sum_squares(Ra @ z) - 2 * g @ z + ridge * cp.sum_squares(z - prior_z)
    cons = []
    for k in range(n_bodies):
        m, hx, hy, hz, xx, xy, yy, xz, yz, zz = (z[10 * k + i] / scale[10 * k + i] for i in range(10))
        tr = 0.5 * (xx + yy + zz)
        J = cp.bmat([[tr - xx, -xy, -xz, hx], [-xy, tr - yy, -yz, hy], [-xz, -yz, tr - zz, hz], [hx, hy, hz, m]])
        cons.append(0.5 * (J + J.T) >> margin * np.eye(4))
    idx = np.flatnonzero(nonneg)
    if idx.size:
        cons.append(z[idx] >= 0)
    prob = cp.Problem(cp.Minimize(obj), cons)
    prob.solve(solver=cp.CLARABEL)
    if z.value is None:
        raise ArithmeticError(f"the physically consistent fit did not solve ({prob.status})")
    theta = np.asarray(z.value) / scale
    theta[:n] += carried
    beta = base.beta(theta)
    return Solution(theta, beta, np.full(beta.size, np.nan), _sigma(X, y, theta), "consistent")


def is_consistent(pi: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """(bodies,) bool: each body's pseudo-inertia positive semidefinite (within `tol` of its scale)."""
    out = []
    for k in range(len(pi) // 10):
        J = pseudo_inertia(pi[10 * k:10 * k + 10])
        out.append(np.linalg.eigvalsh(J).min() >= -tol * max(np.abs(J).max(), 1e-12))
    return np.array(out)
