"""Predicted accuracy of the calibrated model's points (functional core).

The error of the calibrated point at a configuration has two parts (a "consider" analysis):

* the fitted parameters' covariance Σ_f = σ²(J_fᵀJ_f)⁻¹ propagated through the point
  Jacobian: Jp_f Σ_f Jp_fᵀ;
* the fixed parameters' prior: an error δ of the fixed parameters shifts the measurements by
  J_x δ, which the fit absorbs as far as it can (the free estimates move by −J_f⁺J_x δ); what is
  left moves the point by G δ with G = Jp_x − Jp_f·J_f⁺J_x.  Its covariance is G diag(σ_prior²) Gᵀ,
  or G (Σ + μμᵀ) Gᵀ with δ conditioned on the run's residuals (`condition.fixed_moment`).
  A fixed parameter the fit absorbs exactly (J1.θ ≡ base.rz) contributes nothing; one no
  measurement sees (base.x without an x-facing face) contributes its full effect.

All lengths in m; points and their 3×3 covariances in the model's point frame (jig /
workcell / robot base).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import chdtri  # χ² quantile without importing scipy.stats (≈ 0.5 s)

RCOND = 1e-12  # relative singular-value cut-off of the pseudo-inverse (as least_squares.covariance)


@dataclass(frozen=True)
class PointAccuracy:
    """Per point: 3×3 covariances (n,3,3) m² of the fitted and the fixed (prior) parts."""

    cov_fit: np.ndarray
    cov_prior: np.ndarray

    @property
    def cov(self) -> np.ndarray:
        return self.cov_fit + self.cov_prior

    @property
    def sigma(self) -> np.ndarray:
        """RMS 3-D error (1σ), sqrt(trace Σ), (n,) m."""
        return np.sqrt(np.clip(np.trace(self.cov, axis1=1, axis2=2), 0, None))

    @property
    def sigma_fit(self) -> np.ndarray:
        return np.sqrt(np.clip(np.trace(self.cov_fit, axis1=1, axis2=2), 0, None))

    @property
    def sigma_prior(self) -> np.ndarray:
        return np.sqrt(np.clip(np.trace(self.cov_prior, axis1=1, axis2=2), 0, None))

    @property
    def bound95(self) -> np.ndarray:
        return norm_quantile(self.cov, 0.95)


def pinv(J: np.ndarray) -> np.ndarray:
    """Pseudo-inverse with the same cut-off as the fit's covariance."""
    if J.size == 0:
        return np.zeros(J.shape[::-1])
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    s_inv = np.where(s > s[0] * RCOND, 1.0 / np.where(s > 0, s, 1.0), 0.0) if s.size and s[0] > 0 else np.zeros_like(s)
    return (Vt.T * s_inv) @ U.T


def absorption(Jm: np.ndarray, free: np.ndarray) -> np.ndarray:
    """A = J_f⁺ J_x (free × fixed): how the free estimates move per unit fixed-parameter error."""
    return pinv(Jm[:, free]) @ Jm[:, ~free]


def _moment(free: np.ndarray, prior_sigma: np.ndarray, moment: np.ndarray | None) -> np.ndarray:
    """Second moment (X,X) of the fixed parameters' error: `moment` (`condition.fixed_moment`) or diag σ_prior²."""
    return np.diag(prior_sigma[~free] ** 2) if moment is None else np.asarray(moment, float)


def predict(Jp: np.ndarray, free: np.ndarray, cov_free: np.ndarray, prior_sigma: np.ndarray,
            A: np.ndarray, moment: np.ndarray | None = None) -> PointAccuracy:
    """Point covariances (see module docstring).  Jp (n,3,P) at the estimate; cov_free
    (F,F) m-based SI; prior_sigma (P,); A from `absorption`; `moment` (X,X): the fixed
    parameters' error second moment given the data (`condition.fixed_moment`), default diag σ_prior²."""
    Jf, Jx = Jp[:, :, free], Jp[:, :, ~free]
    cov_fit = np.einsum("nip,pq,njq->nij", Jf, cov_free, Jf)
    G = Jx - np.einsum("nip,pk->nik", Jf, A)
    cov_prior = np.einsum("nik,kl,njl->nij", G, _moment(free, prior_sigma, moment), G)
    return PointAccuracy(cov_fit, cov_prior)


def field_scale(Jp: np.ndarray, free: np.ndarray, cov_free: np.ndarray, prior_sigma: np.ndarray, A: np.ndarray,
                bound: np.ndarray, q_points: float = 0.95, q_runs: float = 0.99, n_samples: int = 2000,
                max_points: int = 300, seed: int = 0, moment: np.ndarray | None = None) -> float:
    """Factor ≥ 1 on the per-point bounds so that, in a fraction `q_runs` of calibrations, at least
    `q_points` of the map's points lie within them.  One calibration's errors at all points come from
    the same parameter error (fitted δf ~ N(0, Σ_f), fixed δx ~ N(0, diag σ_prior²) less what the fit
    absorbs), so a per-point 95 % bound alone is exceeded at most points in an unlucky calibration:
    sampled here, (n_samples) calibrations over at most `max_points` map points."""
    n = Jp.shape[0]
    if n == 0:
        return 1.0
    idx = np.unique(np.linspace(0, n - 1, min(n, max_points)).astype(int))
    Jf, G = Jp[idx][:, :, free], Jp[idx][:, :, ~free] - np.einsum("nip,pk->nik", Jp[idx][:, :, free], A)
    rng = np.random.default_rng(seed)
    w, V = np.linalg.eigh(np.asarray(cov_free, float)) if Jf.shape[2] else (np.zeros(0), np.zeros((0, 0)))
    Lf = V * np.sqrt(np.clip(w, 0, None))
    df = rng.standard_normal((n_samples, Lf.shape[1])) @ Lf.T
    if moment is None:
        dx = rng.standard_normal((n_samples, G.shape[2])) * prior_sigma[~free]
    else:
        wx, Vx = np.linalg.eigh(np.asarray(moment, float))
        dx = rng.standard_normal((n_samples, wx.size)) @ (Vx * np.sqrt(np.clip(wx, 0, None))).T
    e = np.einsum("nip,sp->sni", Jf, df) + np.einsum("nik,sk->sni", G, dx)
    b = np.asarray(bound, float)[idx]
    ratio = np.linalg.norm(e, axis=2) / np.where(b > 0, b, np.inf)
    per_run = np.quantile(ratio, q_points, axis=1)
    return float(max(1.0, np.quantile(per_run, q_runs)))


def fixed_contributions(Jp: np.ndarray, free: np.ndarray, prior_sigma: np.ndarray, A: np.ndarray,
                        moment: np.ndarray | None = None) -> np.ndarray:
    """RMS over points of each fixed parameter's unabsorbed 3-D effect, (n_fixed,) m (its own
    second moment, `moment`'s diagonal where given)."""
    G = Jp[:, :, ~free] - np.einsum("nip,pk->nik", Jp[:, :, free], A)
    return np.sqrt(np.mean(np.sum(G**2, axis=1), axis=0) * np.diag(_moment(free, prior_sigma, moment)))


def uncalibrated(Jp: np.ndarray, prior_sigma: np.ndarray) -> np.ndarray:
    """Predicted 3-D 1σ error of the uncalibrated model, (n,) m: every parameter at its prior."""
    return np.sqrt(np.einsum("nip,p->n", Jp**2, prior_sigma**2))


def uncalibrated_cov(Jp: np.ndarray, prior_sigma: np.ndarray) -> np.ndarray:
    """3×3 covariance (n,3,3) m² of the uncalibrated model's point: every parameter at its prior."""
    return np.einsum("nip,p,njp->nij", Jp, prior_sigma**2, Jp)


def norm_quantile(cov: np.ndarray, q: float) -> np.ndarray:
    """q-quantile of |e| for e ~ N(0, Σ) per point, (n,) m: |e|² = Σ λ_i χ²₁ approximated by
    c·χ²_ν with matching mean and variance (Satterthwaite): c = Σλ²/Σλ, ν = (Σλ)²/Σλ²."""
    lam = np.clip(np.linalg.eigvalsh(cov), 0, None)
    s1, s2 = lam.sum(axis=1), (lam**2).sum(axis=1)
    ok = s2 > 0
    c = np.where(ok, s2 / np.where(ok, s1, 1), 0.0)
    nu = np.where(ok, s1**2 / np.where(ok, s2, 1), 1.0)
    return np.sqrt(c * chdtri(nu, 1.0 - q))


def measured_directions(Jm: np.ndarray, Jp: np.ndarray, residual_dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Which directions of the point the measurements fix: each measurement's residuals are
    D_i·(point) to first order, D_i = Jm_i Jp_i⁺ (k×3); M = mean D_iᵀD_i.  Returns the
    eigenvalues (ascending, relative to the largest) and eigenvectors (columns) of M."""
    n = Jp.shape[0]
    Jmi = Jm.reshape(n, residual_dim, -1)
    D = np.einsum("nkp,npj->nkj", Jmi, np.linalg.pinv(Jp, rcond=1e-9))
    M = np.einsum("nki,nkj->ij", D, D) / max(n, 1)
    w, V = np.linalg.eigh(M)
    return w / max(w[-1], 1e-300), V


def rms_samples(Jp: np.ndarray, cov: np.ndarray, dof: int | None = None, n_samples: int = 20_000,
                seed: int = 0) -> np.ndarray:
    """The distribution of one calibration's RMS 3-D error over a set of points, m (n_samples,).

    The error at point i is Jp_i δθ with the same δθ ~ N(0, Σ) at every point, so RMS² over the
    points is δθᵀ M δθ, M = mean Jp_iᵀJp_i: a generalized χ², Σ λ_k χ²₁ with λ the eigenvalues of
    Σ^½ M Σ^½ — few effective degrees of freedom, so one calibration's RMS spreads widely around
    the predicted sqrt(Σλ).  With `dof` (measurements − free parameters of the fit), Σ ∝ σ̂² is
    also scaled by dof/χ²_dof: the uncertainty of the σ estimate.  Jp (n,3,p) over the free
    parameters, cov (p,p)."""
    M = np.einsum("nip,niq->pq", Jp, Jp) / max(Jp.shape[0], 1)
    w, V = np.linalg.eigh(cov)
    L = V * np.sqrt(np.clip(w, 0, None))
    lam = np.clip(np.linalg.eigvalsh(L.T @ M @ L), 0, None)
    rng = np.random.default_rng(seed)
    ms = rng.standard_normal((n_samples, lam.size)) ** 2 @ lam
    if dof:
        ms = ms * dof / rng.chisquare(dof, n_samples)
    return np.sqrt(ms)


def rms_bound(Jp: np.ndarray, cov: np.ndarray, confidence: float = 0.95, dof: int | None = None) -> float:
    """Upper bound, at `confidence`, on one calibration's RMS 3-D error over the points, m
    (quantile of `rms_samples`)."""
    return float(np.quantile(rms_samples(Jp, cov, dof), confidence))


def fixture_covariance(J_free: np.ndarray, labels: np.ndarray, residual_dim: int, tolerance_m: float) -> np.ndarray:
    """Covariance of the free parameters (p,p) from a fixture's machining error: each face (label)
    is off its drawing by f_k, uniform within ±`tolerance_m` (σ = tol/√3), the same for every
    measurement on it — an error the fit's σ̂²(JᵀJ)⁻¹ cannot see (it is not independent between
    measurements).  It moves the estimate by J⁺ D f (D: measurement rows × faces, one-hot), hence
    σ_f² (J⁺D)(J⁺D)ᵀ.  J_free (m·k, p) residual Jacobian over the free parameters, labels (m,)."""
    labels = np.asarray(labels).astype(str)
    faces, idx = np.unique(labels, return_inverse=True)
    D = np.zeros((labels.size, faces.size))
    D[np.arange(labels.size), idx] = 1.0
    D = np.repeat(D, residual_dim, axis=0)  # every residual row of a measurement on its face
    PD = pinv(J_free) @ D
    return (tolerance_m**2 / 3.0) * PD @ PD.T


def modulo_rigid(points: np.ndarray, Jp: np.ndarray) -> np.ndarray:
    """Point Jacobians (n,3,P) less their part that moves all n points as one rigid body: the error of
    the points relative to each other, for measurements that fix no frame (coincidences: the sockets'
    unknown positions take up any common rigid motion, and no such measurement can see or test it).
    points (n,3) m: where the Jacobians are evaluated."""
    n = Jp.shape[0]
    if n < 3:
        return Jp
    c = np.asarray(points, float) - np.mean(points, axis=0)
    R = np.zeros((n, 3, 6))
    R[:, :, :3] = np.eye(3)
    for k in range(3):  # rotation about axis k moves point p by e_k × p
        R[:, :, 3 + k] = np.cross(np.eye(3)[k], c)
    Q, _ = np.linalg.qr(R.reshape(3 * n, 6))
    J = Jp.reshape(3 * n, -1)
    return (J - Q @ (Q.T @ J)).reshape(Jp.shape)
