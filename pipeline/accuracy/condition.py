"""What this run's data say about the parameters held at nominal (functional core).

The consider analysis (`propagate`) charges every parameter held at nominal its full prior σ.
That is right for a parameter no measurement sees (its column lies in the fitted parameters'
span: the fit absorbs it, or it is zero), but not for one the data do see and that the model
choice held at nominal because freeing it did not predict held-out data better (a joint's
scale or coupling on an imported URDF robot, a link length the shrinkage left at nominal):
had it been off by its prior σ, the residuals would show it.  Charging the full prior then
states an accuracy many times worse than new sessions measure.

Linearised: the fit's residuals are r = M J_x δx + M ε, M = I − H_f the projection off the
fitted parameters' columns, δx ~ N(0, S) the held-at-nominal parameters' error (S = diag σ_prior²)
and ε ~ N(0, σ² I).  Given r, δx ~ N(μ, Σ) with

    Σ = (S⁻¹ + J_xᵀ M J_x / σ²)⁻¹,   μ = Σ J_xᵀ M r / σ².

The calibrated model keeps δx at nominal, so its expected squared point error given the data
uses the second moment Σ + μμᵀ in place of S.  Averaged over calibrations this second moment is
S again (E_r[Σ + μμᵀ] = S), so the stated accuracy stays honest where the prior is right and
follows the data where the prior is too wide.  σ² is the fit's σ̂² (residual mean square, which
also carries what the held-at-nominal parameters leave: conservative).  All in SI, the residuals'
unit for J and r.

An estimate shrunk toward nominal (`identify.shrinkage`) is the same question for every parameter at
once: the penalty μ² Σ ((x − x_nominal)/σ_prior)² at the scale μ the data chose acts like a prior
σ̂/μ·σ_prior, which is far narrower than the stated prior when μ is large (little taught, the robot
kept near nominal), and its posterior σ̂²(JᵀJ + μ²W²)⁻¹ then claims the robot is known to that width.
Under the stated prior S instead, given the data the parameters are N(x̂_S, C_S) with
C_S = σ²(JᵀJ + σ²S⁻¹)⁻¹ and x̂_S one Gauss–Newton step from the shrunk estimate x̂ with that prior
(σ the noise estimated from the residuals at x̂_S, not the shrunk fit's σ̂, which carries the robot's error),
so the shrunk estimate's error has the second moment C_S + (x̂ − x̂_S)(x̂ − x̂_S)ᵀ (`shrunk_moment`):
again S on average over calibrations where S is right, and following the data where S is too wide.
"""

from __future__ import annotations

import numpy as np

from pipeline.accuracy.holdout import basis

MIN_DOF = 10  # residual degrees of freedom below which σ̂² is too uncertain to condition on: the prior stands


def fixed_moment(Jm: np.ndarray, free: np.ndarray, prior_sigma: np.ndarray,
                 residuals: np.ndarray) -> np.ndarray | None:
    """Second moment (n_fixed, n_fixed) of the held-at-nominal parameters' error given the run's data
    (module docstring).  Jm (m·k, P) measurement Jacobian at the estimate over all parameters, residuals
    (m·k,) in-sample at the estimate.  None (the prior, diag σ_prior², unchanged) where nothing is held at
    nominal or the data carry fewer than `MIN_DOF` residual degrees of freedom: the identity that keeps the
    statement honest on average holds for a known σ²; from a handful of residuals σ̂² may be small by chance
    and the conditioning would then claim what the data cannot support (thin data keeps its prior)."""
    free = np.asarray(free, bool)
    s = np.asarray(prior_sigma, float)[~free]
    e = np.asarray(residuals, float).reshape(-1)
    Jm = np.asarray(Jm, float)
    if s.size == 0 or not np.all(np.isfinite(e)) or e.size != Jm.shape[0]:
        return None
    U = basis(Jm[:, free])
    dof = e.size - U.shape[1]
    Me = e - U @ (U.T @ e)
    s2 = float(Me @ Me) / dof if dof >= MIN_DOF else 0.0
    if s2 <= 0:
        return None
    Jx = Jm[:, ~free]
    K = (Jx - U @ (U.T @ Jx)) * s / np.sqrt(s2)  # scaled: δx = s ⊙ z, z ~ N(0, I)
    w, V = np.linalg.eigh(K.T @ K)
    Sz = (V / (1.0 + np.clip(w, 0, None))) @ V.T  # (I + KᵀK)⁻¹
    mz = Sz @ (K.T @ Me) / np.sqrt(s2)
    return (Sz + np.outer(mz, mz)) * np.outer(s, s)


def shrunk_moment(J: np.ndarray, r: np.ndarray, offset: np.ndarray, inv_prior: np.ndarray,
                  sigma: float, rounds: int = 2) -> np.ndarray:
    """Second moment (p, p) of a shrunk estimate's error given the run's data under the stated prior
    (module docstring).  J (m·k, p) measurement Jacobian of the estimated parameters at the estimate, r (m·k,)
    its residuals there (model − measured), `offset` (p,) the estimate less the prior's centre (nominal; a
    registration parameter's registration-only estimate), `inv_prior` (p,) 1/σ_prior (1/m, 1/rad, …; 0: no
    prior), `sigma` the fit's σ̂ (the residuals' unit).  A strong shrinkage leaves the robot's own error in its
    residuals, so its σ̂ overstates the noise, and a σ̂ too large acts as a prior too narrow (by 6–8 % in the
    mean-square error stated, Monte Carlo on linear problems): σ is re-estimated `rounds` times from the residuals
    at the stated prior's estimate, |r_S|² / (m·k − dof_S)."""
    J, r = np.asarray(J, float), np.asarray(r, float).reshape(-1)
    offset, inv_prior, s = np.asarray(offset, float), np.asarray(inv_prior, float), float(sigma)
    JtJ = J.T @ J
    for i in range(rounds + 1):
        lam = s * inv_prior
        Ci = np.linalg.pinv(JtJ + np.diag(lam**2), rcond=1e-12, hermitian=True)
        step = Ci @ (J.T @ r + lam**2 * offset)  # x̂ − x̂_S, linearised at x̂
        if i == rounds:
            break
        r_s = r - J @ step
        dof = float(np.trace(Ci @ JtJ))
        s = float(np.sqrt(r_s @ r_s / max(r.size - dof, 1.0)))
    return s**2 * Ci + np.outer(step, step)
