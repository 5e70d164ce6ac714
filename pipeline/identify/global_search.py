"""Global search inside parameter bounds: quasi-random multistart + bounded local refinement.

Used when a system has no trustworthy initial guess beyond its parameter bounds (seed 001).
`multistart` samples the box with a scrambled Sobol sequence, evaluates a *batched* cost
(one vectorised call for all samples), and refines the best few distinct samples with
`scipy.optimize.least_squares` (trust-region reflective, inside the bounds).

`similarity_batch` is the closed-form (Umeyama 1991) least-squares similarity transform
used to eliminate linear-in-structure parameters (variable projection).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import qmc


def similarity_batch(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Best s·R·a + t ≈ b for C candidate point sets A (C,n,3) against B (n,3).

    Returns scale s (C,), rotation R (C,3,3), translation t (C,3) and the sum of squared
    residuals (C,) — all in closed form (Umeyama), no loop over candidates.
    """
    A = np.asarray(A, float)
    n = A.shape[1]
    mu_a = A.mean(axis=1)
    mu_b = B.mean(axis=0)
    Ac = A - mu_a[:, None, :]
    Bc = B - mu_b
    var_a = np.einsum("cni,cni->c", Ac, Ac) / n
    var_b = float(np.sum(Bc**2) / n)
    S = np.einsum("ni,cnj->cij", Bc, Ac) / n  # cov(b, a)
    U, d, Vt = np.linalg.svd(S)
    sign = np.sign(np.linalg.det(U @ Vt))
    sign[sign == 0] = 1.0
    D = np.ones((A.shape[0], 3))
    D[:, 2] = sign
    R = U @ (D[:, :, None] * Vt)
    trace = np.sum(d * D, axis=1)
    safe = np.where(var_a > 0, var_a, 1.0)
    s = np.where(var_a > 0, trace / safe, 0.0)
    t = mu_b - s[:, None] * np.einsum("cij,cj->ci", R, mu_a)
    cost = n * np.clip(var_b - trace**2 / safe, 0.0, None)
    cost = np.where(var_a > 0, cost, n * var_b)
    return s, R, t, cost


@dataclass
class SearchResult:
    """Outcome of `multistart`: best point, its cost, and every refined start."""

    z: np.ndarray
    cost: float
    starts: np.ndarray  # (K, d) refined starting points
    finals: np.ndarray  # (K, d) where each ended
    costs: np.ndarray  # (K,) final costs (sum of squares)
    n_samples: int


def multistart(batch_residuals: Callable[[np.ndarray], np.ndarray], lower: np.ndarray, upper: np.ndarray,
               n_samples: int = 1024, n_refine: int = 4, seed: int = 0, max_nfev: int = 60,
               chunk: int = 512) -> SearchResult:
    """Global minimum of ½|r(z)|² inside [lower, upper] (see module docstring).

    `batch_residuals(Z)` maps many points (C,d) to residuals (C,m) in one vectorised call
    (rows with NaN are invalid points).  The refinement's forward-difference Jacobian is one
    such call too.
    """
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    d = lower.size
    width = upper - lower
    m = int(2 ** np.ceil(np.log2(max(n_samples, 2))))
    Z = qmc.scale(qmc.Sobol(d, scramble=True, seed=seed).random(m), lower, upper)
    c = np.concatenate([np.sum(batch_residuals(Z[i:i + chunk]) ** 2, axis=1) for i in range(0, m, chunk)])
    c = np.where(np.isfinite(c), c, np.inf)
    order = np.argsort(c)
    chosen: list[int] = []  # distinct starts: > 5 % of the box width apart
    for i in order:
        if not np.isfinite(c[i]):
            break
        if all(np.max(np.abs(Z[i] - Z[j]) / width) > 0.05 for j in chosen):
            chosen.append(int(i))
        if len(chosen) >= n_refine:
            break
    if not chosen:
        raise ValueError("global search: no valid sample inside the bounds")
    h = 1e-7 * width

    def fun(z: np.ndarray) -> np.ndarray:
        r = batch_residuals(z[None])[0]
        return np.where(np.isfinite(r), r, 1.0)

    def jac(z: np.ndarray) -> np.ndarray:
        step = np.where(z + h <= upper, h, -h)
        R = batch_residuals(np.vstack([z, z + np.diag(step)]))
        R = np.where(np.isfinite(R), R, 1.0)
        return ((R[1:] - R[0]) / step[:, None]).T

    starts = Z[chosen]
    finals, costs = [], []
    for z0 in starts:
        sol = least_squares(fun, z0, jac=jac, bounds=(lower, upper), method="trf", x_scale=width,
                            max_nfev=max_nfev, xtol=1e-10, ftol=1e-12, gtol=1e-12)
        finals.append(sol.x)
        costs.append(float(np.sum(sol.fun**2)))
    finals_a, costs_a = np.array(finals), np.array(costs)
    best = int(np.argmin(costs_a))
    # polish the winner: flat valleys (weak directions) need more iterations than the screening
    sol = least_squares(fun, finals_a[best], jac=jac, bounds=(lower, upper), method="trf", x_scale=width,
                        max_nfev=10 * max_nfev, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    if np.sum(sol.fun**2) <= costs_a[best]:
        finals_a[best], costs_a[best] = sol.x, float(np.sum(sol.fun**2))
    return SearchResult(z=finals_a[best], cost=float(costs_a[best]), starts=starts, finals=finals_a,
                        costs=costs_a, n_samples=m)
