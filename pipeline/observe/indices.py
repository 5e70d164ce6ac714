"""Observability of an identification Jacobian (pure numpy).

The Jacobian J (m rows × L parameters) is column-scaled to unit norm first (Hollerbach &
Wampler 1996), so the indices do not depend on the parameters' units.  With σ1 ≥ … ≥ σL
its singular values:

- O1 = (σ1·σ2·…·σL)^(1/L) / √m          Borm & Menq 1991 (D-optimality per measurement row)
- O2 = σL / σ1                          Driels & Pathre 1990 (inverse condition number)
- O3 = σL                               Nahvi, Hollerbach & Hayward 1994 (minimum singular value)
- O4 = σL² / σ1                         Nahvi & Hollerbach 1996 (noise amplification index)
- O5 = 1 / (1/σ1 + 1/σ2 + … + 1/σL)     Sun & Hollerbach 2008 (A-optimality analogue)
"""

from __future__ import annotations

import numpy as np


def scale_columns(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """J with unit-norm columns, and the norms (zero columns left as they are)."""
    norms = np.linalg.norm(J, axis=0)
    safe = np.where(norms > 0, norms, 1.0)
    return J / safe, norms


def singular_values(J: np.ndarray) -> np.ndarray:
    """Singular values of the column-scaled J, largest first."""
    return np.linalg.svd(scale_columns(J)[0], compute_uv=False)


def indices(s: np.ndarray, m: int) -> dict[str, float]:
    """O1..O5 of singular values `s` (largest first) of an m-row scaled Jacobian; all 0 where the
    Jacobian has no rows, a zero (or non-finite) singular value: nothing is observable then."""
    s = np.sort(np.asarray(s, float))[::-1]
    L = s.size
    if L == 0 or m <= 0 or not np.all(np.isfinite(s)) or s[-1] <= 0:
        return {"O1": 0.0, "O2": 0.0, "O3": 0.0, "O4": 0.0, "O5": 0.0}
    with np.errstate(over="ignore", under="ignore", divide="ignore"):  # subnormal σ: O4, O5 → 0, not a warning
        return {
            "O1": float(np.exp(np.mean(np.log(s))) / np.sqrt(m)),
            "O2": float(s[-1] / s[0]),
            "O3": float(s[-1]),
            "O4": float(s[-1] ** 2 / s[0]),
            "O5": float(1.0 / np.sum(1.0 / s)),
        }


def correlation(cov: np.ndarray) -> np.ndarray:
    """Correlation matrix of a covariance (zero-variance rows → 0, diagonal 1)."""
    d = np.sqrt(np.clip(np.diag(cov), 0, None))
    safe = np.where(d > 0, d, 1.0)
    C = cov / np.outer(safe, safe)
    C[d == 0, :] = 0
    C[:, d == 0] = 0
    np.fill_diagonal(C, 1.0)
    return np.clip(C, -1.0, 1.0)


def point_sigma(Jp: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """3-D 1σ error sqrt(trace(Jp Σ Jpᵀ)) of each predicted point, (n,) m; Jp (n,3,L)."""
    return np.sqrt(np.clip(np.einsum("nip,pq,niq->n", Jp, cov, Jp), 0, None))


def strongest_correlations(C: np.ndarray, names: list[str], top: int = 10) -> list[dict]:
    """The `top` parameter pairs with the largest |correlation|."""
    iu = np.triu_indices_from(C, k=1)
    v = C[iu]
    order = np.argsort(-np.abs(v), kind="stable")[:top]
    return [{"a": names[iu[0][i]], "b": names[iu[1][i]], "r": float(v[i])} for i in order]
