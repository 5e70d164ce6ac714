"""Does the run's own held-out error agree with the accuracy it states?  (functional core)

The fit states σ̂ (residual 1σ) and the parameters' covariance σ̂²(JᵀJ)⁻¹.  For a linear(ised)
model those predict the held-out residuals of a k-fold cross-validation exactly: the residuals
r_F of fold F, predicted by a fit on the other folds, are (I − H_FF)⁻¹ e_F with H = J(JᵀJ)⁻¹Jᵀ the
hat matrix and e the in-sample residuals, so E|r_F|² = σ² tr (I − H_FF)⁻¹.  A fold whose removal
leaves a high-leverage design (all of a face, a placement, the end of a joint's range) is
expected to predict badly, and is not held against the model: this is the leverage-aware
comparison of cross-validation with the design.

Test statistic: R = Σ|held-out|² / (σ̂² Σ_F tr (I − H_FF)⁻¹), ≈ 1 when the model and its σ̂
describe the data.  Its null distribution (Gaussian noise through the same design, folds and σ̂
estimate) is sampled: e = (I − H)ε, ε ~ N(0, I), R* computed the same way; the run is
inconsistent when R exceeds the 99 % quantile of R* (p < 0.01).  Then every stated 1σ and bound
is multiplied by √R (the held-out error is the arbiter) and the status cannot be `pass`.

Folds whose removal takes a direction of the parameters out of the training data entirely
(leverage 1: the refit cannot predict them at all) are left out of the statistic.
"""

from __future__ import annotations

import numpy as np

P_LIMIT = 0.01
N_SAMPLES = 2000
LEVERAGE_MAX = 1 - 1e-6


def basis(Jf: np.ndarray) -> np.ndarray:
    """Orthonormal basis (m, r) of the column space of Jf (relative cut-off 1e-10)."""
    if Jf.size == 0:
        return np.zeros((Jf.shape[0], 0))
    U, s, _ = np.linalg.svd(Jf, full_matrices=False)
    return U[:, s > s[0] * 1e-10] if s.size and s[0] > 0 else np.zeros((Jf.shape[0], 0))


def _fold_operators(U: np.ndarray, folds: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Per usable fold: (row indices, U_F (I − U_FᵀU_F)⁻¹, tr (I − H_FF)⁻¹)."""
    out = []
    r = U.shape[1]
    for rows in folds:
        if rows.size == 0:
            continue
        UF = U[rows]
        C = UF.T @ UF
        w = np.linalg.eigvalsh(C) if r else np.zeros(0)
        if w.size and w.max() > LEVERAGE_MAX:
            continue
        K = np.linalg.inv(np.eye(r) - C) if r else np.zeros((0, 0))
        out.append((rows, UF @ K, float(rows.size + np.trace(K @ C))))
    return out


def _fold_rows(folds: list[np.ndarray], k: int) -> list[np.ndarray]:
    return [np.concatenate([np.arange(i * k, i * k + k) for i in np.asarray(f, int)]) if len(f) else np.zeros(0, int)
            for f in folds]


def _result(R: float, Rs: np.ndarray, observed: float, predicted: float, s2: float, m_used: int, n_ops: int,
            n_folds: int, extra: dict) -> dict:
    p_value = float((np.sum(Rs >= R) + 1) / (Rs.size + 1))
    q99 = float(np.quantile(Rs, 1 - P_LIMIT))
    return {"ratio": R, "threshold": q99, "p_value": p_value, "consistent": bool(R <= q99),
            "inflation": float(np.sqrt(R)) if R > q99 else 1.0,
            "holdout_rms_m": float(np.sqrt(observed / m_used)),
            "predicted_holdout_rms_m": float(np.sqrt(predicted / m_used)),
            "insample_sigma_m": float(np.sqrt(s2)), "folds_tested": n_ops, "folds": n_folds,
            "test": "R = Σ|held-out|² / its expectation under the fit's noise model, the design and the folds "
                    f"(Σ_F tr(I − H_FF)⁻¹ σ̂² for independent noise), against R's null distribution ({Rs.size} samples "
                    f"of noise through the same design, folds and σ̂ estimate); inconsistent above the "
                    f"{(1 - P_LIMIT) * 100:.0f} % quantile", **extra}


def _shared(U: np.ndarray, e: np.ndarray, h: np.ndarray, rows: list[np.ndarray], groups: np.ndarray, k: int,
            shared: dict, seed: int, n_samples: int, n_folds: int) -> dict | None:
    """The test under Ω = σ_w² I + τ² B (`noise`): dense, every fold's (I − H_FF)⁻¹ explicit."""
    from pipeline.accuracy.noise import solve_moments

    m = e.size
    H = U @ U.T
    M = np.eye(m) - H
    B, T = shared["B"], shared["T"]
    MBM = M @ B @ M
    ops, a, b = [], 0.0, 0.0
    for idx in rows:
        if idx.size == 0:
            continue
        IH = np.eye(idx.size) - H[np.ix_(idx, idx)]
        if np.linalg.eigvalsh(IH).min() < 1 - LEVERAGE_MAX:
            continue
        G = np.linalg.inv(IH)
        a += float(np.trace(G @ M[np.ix_(idx, idx)] @ G.T))
        b += float(np.trace(G @ MBM[np.ix_(idx, idx)] @ G.T))
        ops.append((idx, G))
    if not ops:
        return None
    used = np.concatenate([o[0] for o in ops])
    if not np.all(np.isfinite(h[used])):
        return None
    sw2, t2 = shared["sigma_w_m"] ** 2, shared["tau_m"] ** 2
    observed = float(h[used] @ h[used])
    predicted = sw2 * a + t2 * b
    if predicted <= 0:
        return None
    lam, V = np.linalg.eigh(B)  # B = L Lᵀ: the shared error's square root
    keep = lam > 1e-12 * max(lam.max(), 1e-300)
    Z = V[:, keep] * np.sqrt(lam[keep])
    rng = np.random.default_rng(seed)
    n = int(min(n_samples, max(200, 2e8 // max(m * m, 1))))
    eps = np.sqrt(sw2) * rng.standard_normal((n, m)) + np.sqrt(t2) * rng.standard_normal((n, Z.shape[1])) @ Z.T
    es = eps - (eps @ U) @ U.T
    ee = np.einsum("ij,ij->i", es, es)
    eBe = np.sum((es @ Z) ** 2, axis=1)
    ws, ts = solve_moments(T, ee, eBe)
    ss = np.zeros(n)
    for idx, G in ops:
        rF = es[:, idx] @ G.T
        ss += np.einsum("ij,ij->i", rF, rF)
    Rs = ss / np.maximum(ws * a + ts * b, 1e-300)
    return _result(observed / predicted, Rs, observed, predicted, float(e @ e) / max(m - U.shape[1], 1), used.size,
                   len(ops), n_folds, {"noise_model": {"sigma_w_m": shared["sigma_w_m"], "tau_m": shared["tau_m"],
                                                       "shared_by": "measurements at one configuration"}})


def consistency(Jf: np.ndarray, residuals: np.ndarray, holdout: np.ndarray, folds: list[np.ndarray],
                residual_dim: int, seed: int = 0, n_samples: int = N_SAMPLES, groups: np.ndarray | None = None,
                shared: dict | None = None) -> dict | None:
    """The held-out test (module docstring).  Jf (m·k, p) identification Jacobian over the free
    parameters at the estimate (the rows the fit used), residuals (m, k) in-sample, holdout (m, k)
    held-out residuals of the run's cross-validation, folds: measurement indices of each fold.
    With `groups` and `shared` (`noise.estimate`: measurements at one configuration share an error)
    the expectation and the null are those of Ω = σ_w² I + τ² B.  None when there is nothing to test
    (no folds, no residual degrees of freedom)."""
    k = residual_dim
    e = np.asarray(residuals, float).reshape(-1)
    h = np.asarray(holdout, float).reshape(-1)
    U = basis(np.asarray(Jf, float))
    n_res, r = e.size, U.shape[1]
    dof = n_res - r
    if dof <= 0 or not folds:
        return None
    rows = _fold_rows(folds, k)
    if groups is not None and shared is not None and shared.get("tau_m", 0) > 0:
        return _shared(U, e, h, rows, groups, k, shared, seed, n_samples, len(folds))
    ops = _fold_operators(U, rows)
    if not ops:
        return None
    used = np.concatenate([o[0] for o in ops])
    if not np.all(np.isfinite(h[used])):
        return None
    trace = sum(o[2] for o in ops)
    s2 = float(e @ e) / dof
    if s2 <= 0:
        return None
    observed = float(h[used] @ h[used])
    # null: ε ~ N(0, I) through the same design and folds, σ̂² re-estimated per sample
    rng = np.random.default_rng(seed)
    n = int(min(n_samples, max(200, 2e8 // max(n_res * max(r, 1), 1))))
    eps = rng.standard_normal((n, n_res))
    es = eps - (eps @ U) @ U.T
    s2s = np.einsum("ij,ij->i", es, es) / dof
    ss = np.zeros(n)
    for idx, UK, _ in ops:
        eF = es[:, idx]
        rF = eF + (eF @ U[idx]) @ UK.T
        ss += np.einsum("ij,ij->i", rF, rF)
    Rs = ss / (s2s * trace)
    return _result(observed / (s2 * trace), Rs, observed, s2 * trace, s2, used.size, len(ops), len(folds), {})
