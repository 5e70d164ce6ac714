"""The measurement model augmented with the accepted terms, and the honest covariance of its parameters.

`AugmentedModel` is the measurement model with the accepted effects appended (their
parameters after the geometric ones; residual = geometric residual + Σ S_e(x)·θ_e, the
effects being small).  It is a `MeasurementModel`, so the ordinary `identify.fit` refits
geometry and effects together.  `shared_error_covariance` (errors shared within groups, e.g. a jig
face's machining error) and `cluster_robust_std` (CR2, pose clusters) give the parameters' standard
deviations, `t_interval` their intervals.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.linalg
from scipy import stats

from pipeline.diagnose.inference.projection import orthonormal, project_out
from pipeline.diagnose.library.term import Effect, signature
from pipeline.models import serial_arm


@dataclass(frozen=True)
class AugmentedModel:
    """`base` (a measurement model) plus accepted effects.

    `signatures(x, data, effects)` → list of (n, residual_dim, k_e) m/unit per effect at
    geometric parameters x; without it, `base` is a serial-arm touch model (`.arm`) and the
    arc-welder signatures of `pipeline.diagnose.library.term` are used.  With `scaled`, the effect
    parameters are in units of each effect's plausible size (`physical` converts back): a lens
    term in 1/m⁴ moves a point by ~1e-9 m per unit, a column the rank test would otherwise take
    for a zero one (≤ 1e-12 of the largest) and hold at 0.  With `exact(x, θ, data, effects,
    jac)` (θ in the effects' own units) the residual (n, residual_dim) and, with jac, the
    Jacobian (n, residual_dim, n_geom + Σk) come from it instead: a system whose effects are not
    all small enough for the additive term (the scanner's lens terms).  With `frozen` (n, residual_dim,
    Σk_e; m per each effect's own unit) the effect columns are those, held at the geometric solution
    they were computed at, whatever x: S(x)·θ − S(x₀)·θ is of the second order (effect × geometry move),
    the order the additive term already neglects, and a refit then costs what a geometric fit does."""

    base: object
    effects: tuple[Effect, ...]
    signatures: Callable | None = None
    scaled: bool = False
    exact: Callable | None = None
    frozen: np.ndarray | None = None
    _last: dict = field(default_factory=dict, compare=False, repr=False)  # memo of `_S`

    def scales(self) -> np.ndarray:
        """Physical size of one unit of each parameter (1 for the geometry)."""
        eff = [e.plausible if self.scaled else 1.0 for e in self.effects for _ in range(e.k)]
        return np.concatenate([np.ones(self.n_geom), eff])

    def physical(self, z: np.ndarray) -> np.ndarray:
        """Parameters (or their 1σ) in the effects' own units."""
        return np.asarray(z, float) * self.scales()

    @property
    def system(self) -> str:
        return self.base.system

    @property
    def residual_dim(self) -> int:
        return self.base.residual_dim

    @property
    def n_geom(self) -> int:
        return len(self.base.parameter_names())

    def parameter_names(self) -> list[str]:
        return self.base.parameter_names() + [p for e in self.effects for p in e.parameters]

    def parameter_units(self) -> list[str]:
        return self.base.parameter_units() + [u for e in self.effects for u in e.units]

    def nominal(self) -> np.ndarray:
        return np.concatenate([self.base.nominal(), np.zeros(sum(e.k for e in self.effects))])

    def priority(self) -> np.ndarray:
        geo = getattr(self.base, "priority", lambda: np.zeros(self.n_geom, int))()
        return np.concatenate([geo, np.full(sum(e.k for e in self.effects), 3)])

    def _S(self, x: np.ndarray, data) -> np.ndarray:
        """Effect columns (n, residual_dim, Σk_e) at geometric parameters x, per unit of the
        fitted effect parameters (read-only).  The refit asks for residuals and Jacobian at the
        same x: the last x's columns are kept."""
        key = np.asarray(x, float).tobytes()
        last = self._last.get("S")
        if last is not None and last[0] == key and last[1] is data:
            return last[2]
        S = self._S_at(x, data)
        S.setflags(write=False)
        self._last["S"] = (key, data, S)
        return S

    def _S_at(self, x: np.ndarray, data) -> np.ndarray:
        if self.frozen is not None:
            S = np.array(self.frozen, float)
        elif self.signatures is not None:
            cols = self.signatures(x, data, self.effects)
            n = np.asarray(data["joint_positions"]).shape[0]
            S = np.concatenate(cols, axis=2) if cols else np.zeros((n, self.residual_dim, 0))
        else:
            _, Jq = serial_arm.joint_jacobian(x, data["joint_positions"])
            cols = [signature(e, self.base.arm, x, data, Jq) for e in self.effects]
            S = (np.hstack(cols) if cols else np.zeros((len(data["axis"]), 0)))[:, None, :]
        return S * self.scales()[self.n_geom:] if self.scaled else S

    def residuals(self, z: np.ndarray, data) -> np.ndarray:
        x, th = z[: self.n_geom], z[self.n_geom:]
        if self.exact is not None:
            return self.exact(x, self.physical(z)[self.n_geom:], data, self.effects)
        return self.base.residuals(x, data) + np.einsum("nkc,c->nk", self._S(x, data), th)

    def jacobian(self, z: np.ndarray, data) -> np.ndarray:
        x = z[: self.n_geom]
        if self.exact is not None:
            _, J = self.exact(x, self.physical(z)[self.n_geom:], data, self.effects, jac=True)
            return J * self.scales()
        return np.concatenate([self.base.jacobian(x, data), self._S(x, data)], axis=2)

    def points(self, z: np.ndarray, data):
        return self.base.points(z[: self.n_geom], data)

    def describe(self, z: np.ndarray) -> dict:
        d = self.base.describe(z[: self.n_geom])
        th = self.physical(z)[self.n_geom:]
        out, i = [], 0
        for e in self.effects:
            out.append({"effect": e.name, "location": e.location,
                        "parameters": {p: float(v) for p, v in zip(e.parameters, th[i:i + e.k])}})
            i += e.k
        d["effects"] = out
        return d


def shared_error_covariance(A: np.ndarray, r: np.ndarray, Z: np.ndarray,
                            tau2: float) -> tuple[np.ndarray, float, np.ndarray]:
    """Covariance of least-squares parameters when errors are shared within groups.

    Model of the errors: e = ε + Z·u, ε ~ (0, σ²I) per row, u ~ (0, τ²I) per group (e.g. each
    jig face's machining error, τ² known from the jig's tolerance).  The estimator stays ordinary
    least squares; its covariance is the sandwich A⁺(σ²I + τ²ZZᵀ)A⁺ᵀ, with σ² from the residuals
    r (n,) less the part the group errors leave in them: E[rᵀr] = σ²·dof + τ²·tr(ZᵀP⊥Z).
    A (n, p) the free columns at the solution, Z (n, g) 0/1 membership.  Returns (cov (p, p), σ,
    dof (p,)): the Satterthwaite degrees of freedom of each variance, whose σ² part is estimated
    with n − p dof and whose τ² part is known (dof = n − p · (v / v_σ)², ≥ n − p)."""
    Q = orthonormal(A)
    Zp = project_out(Z, Q)
    dof = max(r.size - Q.shape[1], 1)
    sig2 = max(float(r @ r) - tau2 * float(np.sum(Zp * Z)), 0.25 * float(r @ r)) / dof
    Ap = np.linalg.pinv(A)
    AZ = Ap @ Z
    v_sig = sig2 * np.sum(Ap * Ap, axis=1)
    cov = sig2 * Ap @ Ap.T + tau2 * AZ @ AZ.T
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = np.where(v_sig > 0, dof * (np.diag(cov) / v_sig) ** 2, np.inf)
    return cov, float(np.sqrt(sig2)), nu


def _psd_power(S: np.ndarray, p: float, tol: float = 1e-10) -> np.ndarray:
    """S^p of a symmetric positive semi-definite matrix on its range (eigenvalues ≤ tol·max dropped)."""
    w, V = np.linalg.eigh(0.5 * (S + S.T))
    keep = w > tol * max(float(w.max()), 1e-300)
    return (V[:, keep] * w[keep] ** p) @ V[:, keep].T


def cluster_robust_std(A: np.ndarray, r: np.ndarray, cluster: np.ndarray,
                       working: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """1σ of least-squares parameters with design A (N, p) and residuals r (N,) when the errors
    are correlated within clusters, and its degrees of freedom: (std (p,), dof (p,)).

    The CR2 sandwich (Bell & McCaffrey 2002) B (Σ_g A_gᵀ M_g r_g r_gᵀ M_g A_g) B, B = (AᵀA)⁻¹,
    M_g = (I − H_gg)^{-1/2}, H_gg = A_g B A_gᵀ: each cluster's residual is un-shrunk by its own
    leverage, which CR1's single factor G/(G − 1)·(N − 1)/(N − p) does not do with few clusters
    (20 poses: CR1 covered 75–88 %).  Directions a cluster's rows fit exactly (leverage 1: no
    residual) get no weight.  With few clusters the variance estimate is itself noisy (in effect
    a sum of G squared scores, fewer when a parameter is carried by few clusters), so the
    interval is t-based with the Bell–McCaffrey (Satterthwaite) dof of each variance under the
    working model of i.i.d. errors: the estimate of Var θ_j is Σ_g (c_gᵀe)², c_g = (I − H)_{·g} u_g,
    u_g = M_g A_g B e_j, so ν = (tr K)² / ‖K‖²_F with K_gh = c_gᵀc_h = δ_gh u_gᵀu_g − w_gᵀ B w_h,
    w_g = A_gᵀ u_g (no N × N matrix is formed).

    With `working` (n, k, k), each measurement's error covariance up to a common scale (the N
    rows are n measurements of k rows, none split between clusters), both are taken under that
    working model Φ instead of i.i.d. errors (Bell & McCaffrey's bias-reduced linearisation with
    a working covariance): M_g = Φ_g^{1/2}(Φ_g^{1/2} E_g Φ_g^{1/2})^{-1/2}Φ_g^{1/2}, E_g =
    (I − H)_{g·} Φ (I − H)_{g·}ᵀ, so the variance is unbiased when Φ is right, and ν = (tr K)²/‖K‖²_F
    with K_gh = c_gᵀ Φ c_h.  With rows of very unequal noise (the scanner's 3-D points: pixel
    noise through ∂P/∂pixel, rank 2, growing with range) the i.i.d. dof overstates how many
    clusters carry a parameter's variance."""
    if working is not None:
        return _cr2_working(A, r, cluster, np.asarray(working, float))
    ids, inv = np.unique(cluster, return_inverse=True)
    G, p = ids.size, A.shape[1]
    cn = np.linalg.norm(A, axis=0)
    cn[cn == 0] = 1.0
    A = A / cn  # unit columns: parameters in very different units stay resolvable
    Binv = np.linalg.pinv(A.T @ A)
    sc = np.zeros((G, p))
    uu = np.zeros((G, p))  # u_gᵀu_g per parameter
    Wt = np.zeros((G, p, p))  # Wt[g, :, j] = w_g of parameter j
    for g in range(G):
        rows = np.flatnonzero(inv == g)
        Ag = A[rows]
        w, V = np.linalg.eigh(np.eye(rows.size) - Ag @ Binv @ Ag.T)
        keep = w > 1e-6
        Mg = (V[:, keep] / np.sqrt(w[keep])) @ V[:, keep].T
        sc[g] = Ag.T @ (Mg @ r[rows])
        U = Mg @ Ag @ Binv  # (n_g, p): column j is u_g of parameter j
        uu[g] = np.sum(U * U, axis=0)
        Wt[g] = Ag.T @ U
    V = Binv @ (sc.T @ sc) @ Binv
    dof = np.full(p, np.inf)
    for j in range(p):
        Wj = Wt[:, :, j]  # (G, p)
        K = np.diag(uu[:, j]) - Wj @ Binv @ Wj.T
        tr = float(np.trace(K))
        if tr > 0:
            dof[j] = tr**2 / float(np.sum(K * K))
    return np.sqrt(np.clip(np.diag(V), 0, None)) / cn, dof


def _cr2_working(A: np.ndarray, r: np.ndarray, cluster: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`cluster_robust_std` under the working covariance blocks C (n, k, k) (its docstring)."""
    n, k = C.shape[:2]
    N, p = A.shape
    cn = np.linalg.norm(A, axis=0)
    cn[cn == 0] = 1.0
    X = A / cn
    B = np.linalg.pinv(X.T @ X)
    IH = np.eye(N) - X @ B @ X.T

    def phi(Y: np.ndarray) -> np.ndarray:  # Φ·Y for Y (N, c), Φ block-diagonal by measurement
        return np.einsum("nij,njc->nic", C, Y.reshape(n, k, -1)).reshape(Y.shape)

    ids = np.unique(cluster)
    sc = np.zeros((ids.size, p))
    c_all = np.zeros((ids.size, N, p))  # c_g of every parameter
    PhiIH = phi(IH.T)  # Φ (I − H)ᵀ, (N, N)
    for a, g in enumerate(ids):
        rows = np.flatnonzero(cluster == g)
        meas = rows.reshape(-1, k)[:, 0] // k
        Ph = _psd_power(scipy.linalg.block_diag(*C[meas]), 0.5)
        Eg = IH[rows] @ PhiIH[:, rows]
        Mg = Ph @ _psd_power(Ph @ Eg @ Ph, -0.5) @ Ph
        sc[a] = X[rows].T @ (Mg @ r[rows])
        c_all[a] = IH[rows].T @ (Mg @ X[rows] @ B)
    V = B @ (sc.T @ sc) @ B
    dof = np.full(p, np.inf)
    for j in range(p):
        c = c_all[:, :, j].T  # (N, G)
        K = c.T @ phi(c)
        tr = float(np.trace(K))
        if tr > 0:
            dof[j] = tr**2 / float(np.sum(K * K))
    return np.sqrt(np.clip(np.diag(V), 0, None)) / cn, dof


def t_interval(value: float, std: float, dof: float, level: float = 0.95) -> list[float]:
    """Two-sided `level` interval value ± t_{(1+level)/2, dof}·std (the normal quantile at dof = ∞)."""
    q = float(stats.t.ppf(0.5 + level / 2, dof)) if np.isfinite(dof) else float(stats.norm.ppf(0.5 + level / 2))
    return [float(value - q * std), float(value + q * std)]
