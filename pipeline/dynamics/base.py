"""Base parameters: the combinations of inertial (and friction) parameters the data can fix.

Many inertial parameters never move a recorded torque (a body's mass along a joint's axis) or move it
only in fixed combinations with others.  A QR decomposition with column pivoting of the regressor W
(rows: samples × fitted joints, columns: parameters) orders the columns by how much new direction each
adds; the first r (r the numerical rank) are the independent columns, and every other column is their
combination: W_dep = W_ind·K.  The base parameters are β = θ_ind + K·θ_dep, so that W θ = W_ind β for any
θ: what least squares identifies (Gautier's numerical method, `scipy.linalg.qr(pivoting=True)`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sl

RANK_TOL = 1e-8  # |R_kk| / |R_00| below this: the column adds nothing the data can see


@dataclass(frozen=True)
class BaseSet:
    """independent (r,) and dependent column indices (sorted), K (r, n_dep): W_dep = W_ind K."""

    independent: np.ndarray
    dependent: np.ndarray
    K: np.ndarray

    @property
    def rank(self) -> int:
        return int(self.independent.size)

    def beta(self, theta: np.ndarray) -> np.ndarray:
        """Base parameters β (r,) of full parameters θ (n,)."""
        theta = np.asarray(theta, float)
        return theta[self.independent] + self.K @ theta[self.dependent]

    def combination(self, names: list[str], k: int, tol: float = 1e-9) -> str:
        """Base parameter k as text: 'a + 0.5·b − c'."""
        parts = [names[self.independent[k]]]
        for d, f in zip(self.dependent, self.K[k]):
            if abs(f) > tol:
                parts.append(f"{'−' if f < 0 else '+'} {abs(f):.4g}·{names[d]}")
        return " ".join(parts)


def column_scale(W: np.ndarray) -> np.ndarray:
    """Each column's RMS (1 where zero): columns of kg and kg·m² differ by orders of magnitude."""
    s = np.sqrt(np.mean(np.asarray(W) ** 2, axis=0))
    return np.where(s > 0, s, 1.0)


def base_set(W: np.ndarray, tol: float = RANK_TOL) -> BaseSet:
    """The base-parameter reduction of regressor W (N, n) by pivoted QR of its column-scaled copy."""
    W = np.asarray(W, float)
    s = column_scale(W)
    _, R, P = sl.qr(W / s, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    r = int(np.sum(d > tol * d[0])) if d.size and d[0] > 0 else 0
    ind, dep = P[:r], P[r:]
    # W_dep = W_ind K  ⇔  (scaled) R11 K̃ = R12, K = diag(1/s_ind) K̃ diag(s_dep)
    Kt = sl.solve_triangular(R[:r, :r], R[:r, r:]) if dep.size else np.zeros((r, 0))
    K = Kt / s[ind][:, None] * s[dep][None, :]
    order = np.argsort(ind)
    dorder = np.argsort(dep)
    return BaseSet(ind[order], dep[dorder], K[order][:, dorder])


def condition_number(W: np.ndarray) -> float:
    """2-norm condition number of the column-scaled regressor W (N, r)."""
    return float(np.linalg.cond(np.asarray(W) / column_scale(W)))
