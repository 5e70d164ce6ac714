"""Pose-clustered inference: random-effects whitening, noise components and the physical
(parametric) model of the cluster errors (docs/guide/diagnose.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.special
import scipy.stats

from pipeline.diagnose.inference.projection import orthonormal, project_out


# ----- pose-clustered inference -------------------------------------------------------------
@dataclass
class Whitener:
    """Block-diagonal W = σ_w·Σ^{-1/2} of a random-effects error model per cluster (pose):
    r_g = Z_g u_g + e_g, u_g ~ (0, Ψ), e_g ~ (0, σ_w² I), Σ_g = σ_w² I + Z_g Ψ Z_gᵀ.

    Applying W to residuals, Jacobians and signatures turns the correlated rows of a pose into
    rows with variance σ_w² that are (to the estimate of Ψ) independent, so the grouped F tests
    and the minimum detectable sizes hold: a pose-level signature (inside span Z_g) is tested
    against the between-pose variance σ_w² + Z Ψ Zᵀ, a within-pose one against σ_w²."""

    blocks: list[tuple[np.ndarray, np.ndarray]]  # (row indices, W_g)
    sigma_within: float  # σ_w, m
    psi: np.ndarray  # (p, p) between-cluster covariance of u, units of Z's columns
    n_clusters: int
    pre: object = None  # a per-measurement noise-shape whitener applied first (or None)
    n_effective: int = 0  # residual dimensions that carry noise (structural zeros excluded)

    def __call__(self, A: np.ndarray) -> np.ndarray:
        A = np.asarray(A, float)
        if self.pre is not None:
            A = self.pre(A)
        out = A.copy()
        for rows, W in self.blocks:
            out[rows] = W @ A[rows]
        return out


@dataclass
class NoiseModel:
    """Within-cluster noise of `noise_components`: variance per source (+ isotropic, last) and
    the number of residual dimensions each cluster's rows really span (`effective_rows`)."""

    variances: np.ndarray
    effective_rows: dict


def noise_components(r: np.ndarray, Z: np.ndarray, cluster: np.ndarray, sources: list[np.ndarray],
                     void_tol: float = 1e-8) -> NoiseModel:
    """Variance components of the within-cluster noise, by moments.  Each measurement's k rows get
    Σ_i = Σ_j s_j N_ij N_ijᵀ + s_iso I (N_j (n, k, c_j) a noise source's map to the residual, e.g. a
    pixel error through ∂P/∂pixel).  Per cluster g, what neither the sources nor the cluster basis
    Z_g reach (the complement of span[blockdiag N_i, Z_g]) can only hold isotropic noise: s_iso is
    its mean square.  When that is nil (a structural zero: the scanner's reconstructed points all
    lie in the laser plane, so the off-plane residuals of a pose's collinear corners are affine
    along the line, i.e. rigid, whatever the parameters) those dimensions carry neither noise nor
    signal and must not count as residual degrees of freedom: `effective_rows[g]` is the rank of
    span[blockdiag N_i, Z_g] then (all rows otherwise).  The source variances s_j are the
    least-squares fit of every entry of e_g e_gᵀ (e_g = P_g r_g, P_g = I − Z_g Z_g⁺) to
    P_g Σ_g P_g (unbiased moments), clipped ≥ 0."""
    r = np.asarray(r, float)
    Z = np.asarray(Z, float)
    n, k = sources[0].shape[:2]
    srcs = [np.asarray(N, float) for N in sources]
    blocks = [np.einsum("nic,njc->nij", N, N) for N in srcs]
    meas = np.arange(n * k) // k
    X, y, eff = [], [], {}
    ss_void, dim_void, ss_all = 0.0, 0, 0.0
    per = []
    for c in np.unique(cluster):
        rows = np.flatnonzero(cluster == c)
        Zg = Z[rows]
        Pg = np.eye(rows.size) - Zg @ np.linalg.pinv(Zg, rcond=1e-9)
        ms, loc = np.unique(meas[rows], return_inverse=True)
        Nb = np.zeros((rows.size, sum(N.shape[2] for N in srcs) * ms.size))
        col = 0
        for N in srcs:
            for a, m in enumerate(ms):
                Nb[loc == a, col:col + N.shape[2]] = N[m]
                col += N.shape[2]
        span = np.hstack([Nb, Zg])
        nrm = np.linalg.norm(span, axis=0)
        span = span[:, nrm > 0] / nrm[nrm > 0]
        U, sv, _ = np.linalg.svd(span, full_matrices=True)
        rk = int(np.sum(sv > void_tol * sv[0])) if sv.size else 0
        Vvoid = U[:, rk:]
        ss_void += float(np.sum((Vvoid.T @ r[rows]) ** 2))
        dim_void += Vvoid.shape[1]
        ss_all += float(r[rows] @ r[rows])
        eff[c] = (rk, rows.size)
        e = Pg @ r[rows]
        cols = []
        for B in blocks:
            Bg = np.zeros((rows.size, rows.size))
            for a, m in enumerate(ms):
                ix = np.flatnonzero(loc == a)
                Bg[np.ix_(ix, ix)] = B[m]
            cols.append((Pg @ Bg @ Pg).ravel())
        per.append((Pg, e))
        X.append(np.stack(cols, axis=1))
        y.append(np.outer(e, e).ravel())
    s_iso = ss_void / dim_void if dim_void else 0.0
    X, y = np.vstack(X), np.concatenate(y)
    y = y - s_iso * np.concatenate([(Pg @ Pg).ravel() for Pg, _ in per])
    sc = np.sqrt(np.sum(X**2, axis=0))
    sc[sc == 0] = 1.0
    sj, *_ = np.linalg.lstsq(X / sc, y, rcond=None)
    sj = np.clip(sj / sc, 0.0, None)
    # void dims hold nothing (relative to the typical source variance): structural zeros
    structural = dim_void > 0 and s_iso <= 1e-10 * ss_all / r.size
    return NoiseModel(np.append(sj, s_iso), {c: (rk if structural else m) for c, (rk, m) in eff.items()})


def _covariance_and_scale(sources: list[np.ndarray], variances: np.ndarray, floor: float) -> tuple[np.ndarray, float]:
    """(Σ (n, k, k) of `measurement_covariance`, the median largest eigenvalue before the floor)."""
    n, k = sources[0].shape[:2]
    C = np.zeros((n, k, k))
    for N, v in zip(sources, variances):
        N = np.asarray(N, float)
        C += v * np.einsum("nic,njc->nij", N, N)
    lam_med = float(np.median(np.linalg.eigvalsh(C + variances[-1] * np.eye(k))[:, -1]))
    C += max(variances[-1], floor * lam_med) * np.eye(k)
    return C, lam_med


def measurement_covariance(sources: list[np.ndarray], variances: np.ndarray, floor: float = 1e-3) -> np.ndarray:
    """Each measurement's noise covariance (n, k, k) m²: Σ_i = Σ_j s_j N_ij N_ijᵀ + s_iso I
    (`noise_components`), the isotropic part at least `floor` × the median largest eigenvalue
    (a guard for directions no source reaches; as in `measurement_whitener`)."""
    return _covariance_and_scale(sources, variances, floor)[0]


def measurement_whitener(sources: list[np.ndarray], variances: np.ndarray, floor: float = 1e-3):
    """Row map (nk, c) → (nk, c) that whitens each measurement's k residual rows by its noise
    covariance Σ_i = Σ_j s_j N_ij N_ijᵀ + s_iso I (`noise_components`).  `floor` (relative to the
    median largest eigenvalue of Σ_i) only guards directions no source reaches against a zero
    variance estimate; the output keeps the residual's units (scaled by √median λ_max)."""
    n, k = sources[0].shape[:2]
    C, lam_med = _covariance_and_scale(sources, variances, floor)
    w, V = np.linalg.eigh(C)
    T = np.einsum("nij,nj,nkj->nik", V, np.sqrt(lam_med) / np.sqrt(w), V)

    def apply(A: np.ndarray) -> np.ndarray:
        A = np.asarray(A, float)
        return np.einsum("nij,njc->nic", T, A.reshape(n, k, -1)).reshape(A.shape)
    return apply


def cluster_whitener(r: np.ndarray, Z: np.ndarray, cluster: np.ndarray, n_fitted: int = 0,
                     pre=None, effective_rows: dict | None = None) -> Whitener | None:
    """Estimate the random-effects model of `Whitener` from residuals r (N,) ⊥ the fitted design,
    with Z (N, p) the random-effect columns of each row (a pose's rigid motion, say) and
    `cluster` (N,) the cluster of each row; None when no cluster holds more rows than Z has
    columns (nothing to separate: every row is its own measurement).

    Moments: per cluster û_g = Z_g⁺ r_g; σ_w² = Σ‖r_g − Z_g û_g‖² / Σ(m_g − rank Z_g); Ψ =
    mean(û_g û_gᵀ) − σ_w² mean((Z_gᵀZ_g)⁺), inflated by the share of the between-cluster degrees
    of freedom the fit (`n_fitted` parameters) used, and clipped to positive semi-definite."""
    r = np.asarray(r, float)
    Z = np.asarray(Z, float)
    if pre is not None:
        r, Z = pre(r[:, None])[:, 0], pre(Z)
    p = Z.shape[1]
    ids = np.unique(cluster)
    members = [np.flatnonzero(cluster == c) for c in ids]
    if not any(m.size > p for m in members):
        return None
    U, V, ss_w, dof_w, dof_b = [], [], 0.0, 0, 0
    pinvs = []
    for c, rows in zip(ids, members):
        Zg = Z[rows]
        Zp = np.linalg.pinv(Zg, rcond=1e-9)
        rk = int(np.linalg.matrix_rank(Zg, tol=1e-9 * max(np.abs(Zg).max(), 1e-300)))
        u = Zp @ r[rows]
        e = r[rows] - Zg @ u
        ss_w += float(e @ e)
        dof_w += (effective_rows[c] if effective_rows is not None else rows.size) - rk
        dof_b += rk
        U.append(u)
        V.append(Zp @ Zp.T)
        pinvs.append(Zp)
    if dof_w < 1:
        return None
    s2 = ss_w / dof_w
    U = np.array(U)
    infl = dof_b / max(dof_b - n_fitted, 1) if n_fitted < dof_b else 1.0
    psi = infl * (U.T @ U) / len(ids) - s2 * np.mean(V, axis=0)
    w, Vec = np.linalg.eigh(0.5 * (psi + psi.T))
    psi = (Vec * np.clip(w, 0, None)) @ Vec.T
    blocks = []
    for rows in members:
        Zg = Z[rows]
        Sg = np.eye(rows.size) + Zg @ psi @ Zg.T / s2
        w, Vec = np.linalg.eigh(Sg)
        blocks.append((rows, (Vec / np.sqrt(np.clip(w, 1e-12, None))) @ Vec.T))
    n_eff = sum(effective_rows.values()) if effective_rows is not None else Z.shape[0]
    return Whitener(blocks, float(np.sqrt(s2)), psi, len(ids), pre, int(n_eff))


# ----- parametric (physical) model of the cluster errors ---------------------------------------
@dataclass
class PhysicalModel:
    """Null model of a clustered residual with a physical cluster error: each measurement's k rows
    carry the independent noise of `sources` (Σ_i = Σ_j s_j N_ij N_ijᵀ + s_iso I, `variances` as
    `noise_components`), and cluster g's rows B_g e_g, e_g ~ N(0, diag θ) with θ constant within
    each column group of `groups` (for the scanner's repeatability: δt and δω of the flange, each
    isotropic, and the encoders' δq).  `draw` simulates residuals from it (for a parametric
    bootstrap; with a finite `scale_dof` the variances' common scale is drawn per draw)."""

    sources: list[np.ndarray]
    variances: np.ndarray
    B: np.ndarray  # (nk, p) how a cluster's error reaches each row
    groups: list[np.ndarray]  # column indices of B sharing one variance
    theta: np.ndarray  # (len(groups),) variance of each group's components
    cluster: np.ndarray  # (nk,) cluster of each row
    scale_dof: float = np.inf  # θ's common scale drawn as χ²_ν/ν per draw (its estimation error); ∞: fixed

    def column_variances(self) -> np.ndarray:
        v = np.zeros(self.B.shape[1])
        for g, t in zip(self.groups, self.theta):
            v[g] = t
        return v

    def draw(self, n_draw: int, seed: int = 0) -> np.ndarray:
        """Residual draws (nk, n_draw) from the model (Gaussian)."""
        rng = np.random.default_rng(seed)
        n, k = self.sources[0].shape[:2]
        out = np.sqrt(self.variances[-1]) * rng.standard_normal((n, k, n_draw))
        for N, v in zip(self.sources, self.variances):
            out += np.sqrt(v) * np.einsum("nkc,ncb->nkb", np.asarray(N, float), rng.standard_normal((n, N.shape[2], n_draw)))
        out = out.reshape(n * k, n_draw)
        ids, inv = np.unique(self.cluster, return_inverse=True)
        e = rng.standard_normal((ids.size, self.B.shape[1], n_draw)) * np.sqrt(self.column_variances())[None, :, None]
        if np.isfinite(self.scale_dof):
            e *= np.sqrt(rng.chisquare(self.scale_dof, n_draw) / self.scale_dof)[None, None, :]
        return out + np.einsum("rp,rpb->rb", self.B, e[inv])


def _cluster_gram(Bj: np.ndarray, cluster: np.ndarray) -> np.ndarray:
    """Block-diagonal Σ_g B_gj B_gjᵀ (nk, nk): the covariance of one group of cluster errors per unit θ."""
    return (Bj @ Bj.T) * (cluster[:, None] == cluster[None, :])


def _block_columns(Bj: np.ndarray, cluster: np.ndarray) -> np.ndarray:
    """(nk, G·c): cluster g's rows of Bj (nk, c) in its own c columns, so that Σ_g B_gj B_gjᵀ = out outᵀ."""
    ids, inv = np.unique(cluster, return_inverse=True)
    c = Bj.shape[1]
    out = np.zeros((Bj.shape[0], ids.size * c))
    cols = inv[:, None] * c + np.arange(c)[None]
    np.put_along_axis(out, cols, Bj, axis=1)
    return out


def physical_components(r: np.ndarray, A: np.ndarray, B: np.ndarray, groups: list[np.ndarray],
                        cluster: np.ndarray, sigma2: float, pre=None, iterations: int = 40,
                        information: bool = False):
    """Variances θ (one per column group of B) of the cluster errors by REML, from residual r of
    design A (both unwhitened; on the `pre`-whitened problem, in which the measurement noise is
    σ_w² = `sigma2` per row, held fixed): V = σ_w² I + Σ_j θ_j V_j, V_j = Σ_g B_gj B_gjᵀ,
    P = V⁻¹ − V⁻¹Q(QᵀV⁻¹Q)⁻¹QᵀV⁻¹ (Q spans A, so the fit's share of the between-cluster dimensions
    is accounted for); score_j = ½(rᵀPV_jPr − tr PV_j), information ½ tr(PV_jPV_k).  Started
    from the moment estimate (E eᵀV_je, e = (I − QQᵀ)r, solved by non-negative least squares),
    then projected Fisher scoring: variances at the bound θ = 0 whose score points below it are
    held there (the step is solved for the others only), and the step is halved until the
    restricted likelihood rises.  The plain step (all variances, clipped) oscillated between two
    states when mechanisms overlap (5 variances, a localised bump in the residual) and could stop
    at θ = 0.  REML rather than moments: when several mechanisms overlap, the moments weight the
    directions only one of them reaches poorly and misplace the variance.  With `information`,
    returns (θ, the REML information matrix ½ tr(PV_jPV_k) at θ)."""
    if pre is not None:
        r, A, B = pre(np.asarray(r, float)[:, None])[:, 0], pre(A), pre(B)
    Q = orthonormal(A)
    e = project_out(r[:, None], Q)[:, 0]
    Bb = [_block_columns(B[:, g], cluster) for g in groups]
    PB = [project_out(b, Q) for b in Bb]
    y = np.array([np.sum((b.T @ e) ** 2) for b in Bb])
    c0 = np.array([sigma2 * np.sum(b * pb) for b, pb in zip(Bb, PB)])
    G = np.array([[np.sum((b.T @ pl) ** 2) for pl in PB] for b in Bb])
    theta, _ = scipy.optimize.nnls(G, y - c0)
    n = r.size

    def fit(th):
        """(restricted log-likelihood up to a constant, P r, [P B_j])."""
        V = sigma2 * np.eye(n) + sum(t * (b @ b.T) for t, b in zip(th, Bb))
        c = scipy.linalg.cho_factor(V)
        ViQ = scipy.linalg.cho_solve(c, Q)
        cq = scipy.linalg.cho_factor(Q.T @ ViQ)
        Vir = scipy.linalg.cho_solve(c, r)
        Pr = Vir - ViQ @ scipy.linalg.cho_solve(cq, ViQ.T @ r)
        ll = -(np.sum(np.log(np.diag(c[0]))) + np.sum(np.log(np.diag(cq[0])))) - 0.5 * float(r @ Pr)
        return ll, Pr, c, ViQ, cq

    ll, Pr, c, ViQ, cq = fit(theta)
    for _ in range(iterations):
        PBb = [scipy.linalg.cho_solve(c, b) - ViQ @ scipy.linalg.cho_solve(cq, ViQ.T @ b) for b in Bb]
        score = np.array([0.5 * (np.sum((b.T @ Pr) ** 2) - np.sum(b * pb)) for b, pb in zip(Bb, PBb)])
        info = np.array([[0.5 * np.sum((bj.T @ pk) ** 2) for pk in PBb] for bj in Bb])
        free = (theta > 0) | (score > 0)
        step = np.zeros_like(theta)
        if free.any():
            step[free] = np.linalg.lstsq(info[np.ix_(free, free)], score[free], rcond=None)[0]
        scale = max(float(np.max(theta)), 1e-300)
        for _half in range(30):
            new = np.clip(theta + step, 0.0, None)
            out = fit(new)
            if out[0] >= ll - 1e-12 * abs(ll):
                break
            step = 0.5 * step
        else:
            break
        done = np.allclose(new, theta, rtol=1e-4, atol=1e-6 * scale)
        theta, (ll, Pr, c, ViQ, cq) = new, out
        if done:
            break
    if not information:
        return theta
    PBb = [scipy.linalg.cho_solve(c, b) - ViQ @ scipy.linalg.cho_solve(cq, ViQ.T @ b) for b in Bb]
    return theta, np.array([[0.5 * np.sum((bj.T @ pk) ** 2) for pk in PBb] for bj in Bb])


def physical_whitener(model: PhysicalModel, sigma2: float, pre=None, n_effective: int = 0) -> Whitener:
    """`Whitener` of a `PhysicalModel`: per cluster Σ_g = σ_w² I + B_g diag θ B_gᵀ on the `pre`-whitened
    rows (each cluster's own covariance, from the physical map B_g — not one Ψ for all clusters)."""
    B = model.B if pre is None else pre(model.B)
    cv = model.column_variances()
    blocks = []
    ids = np.unique(model.cluster)
    for c in ids:
        rows = np.flatnonzero(model.cluster == c)
        Bg = B[rows]
        Sg = np.eye(rows.size) + (Bg * cv) @ Bg.T / sigma2
        w, Vec = np.linalg.eigh(Sg)
        blocks.append((rows, (Vec / np.sqrt(np.clip(w, 1e-12, None))) @ Vec.T))
    return Whitener(blocks, float(np.sqrt(sigma2)), np.diag(cv), ids.size, pre, int(n_effective))


def sign_flip_elimination(W: Whitener, r: np.ndarray, Jw: np.ndarray, S: list[np.ndarray], accepted: list[int],
                          cluster: np.ndarray, m: int, alpha: float, draws: int,
                          seed: int) -> tuple[list[int], dict, list[int]]:
    """Backward elimination of the accepted blocks under the restricted wild cluster bootstrap
    (`sign_flips.cluster_sign_flip_p`, whitened problem): while Holm's step-down over a family of m
    does not reject every block given the others, drop the least significant.  Returns (kept,
    {kept block: Holm-adjusted p}, dropped blocks)."""
    from pipeline.diagnose.inference.sign_flips import cluster_sign_flip_p

    rw = W(r)
    Sw = {i: W(S[i]) for i in accepted}
    A, dropped = list(accepted), []
    while A:
        p = cluster_sign_flip_p(rw, [Sw[i] for i in A], Jw, cluster, draws, seed)
        order = np.argsort(p, kind="stable")
        adj = np.maximum.accumulate(np.minimum(1.0, p[order] * (m - np.arange(len(A)))))
        if np.all(adj <= alpha):
            return A, {A[o]: float(a) for o, a in zip(order, adj)}, dropped
        dropped.append(A.pop(int(np.argmax(p))))
    return A, {}, dropped
