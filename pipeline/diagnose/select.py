"""Which candidate effects the campaign can see, and which ones the data ask for.

Linear algebra at the geometric solution (Frisch–Waugh–Lovell): with Q an orthonormal basis
of the free geometric Jacobian columns, a candidate's *projected signature* S⊥ = (I − QQᵀ)S
is what of it the geometry cannot absorb, and the residual r is already ⊥ Q at the optimum.

- `gate`: absorbed fraction 1 − ‖S⊥‖²/‖S‖², minimum detectable size along the candidate's
  weakest direction, (z₁₋α/(2m) + z₀.₈)·σ/s_min(S⊥) (+ its immaterial tolerance), and
  confounding with other candidates; a candidate whose detectable size is beyond what is
  physically plausible is `not_identifiable`.
- `forward_select`: grouped F tests, one candidate block at a time, each against the
  geometry and the blocks already accepted; Holm's step-down thresholds α/(m − j).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.special
import scipy.stats

from pipeline.diagnose.effects import Effect

POWER_Z = scipy.stats.norm.ppf(0.8)  # 80 % power
RANK_REL = 1e-6  # a projected column this small relative to its original is gone
CONFOUND = 0.95  # share of a projected signature another candidate explains → confounded


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


@dataclass
class Gate:
    """Detectability of one candidate in this campaign."""

    effect: Effect
    absorbed_fraction: float  # share of ‖S‖² the geometry absorbs
    min_detectable: float  # along the weakest direction, units of the parameters
    identifiable: bool
    absorbed_by: str
    reason: str
    projected: np.ndarray  # S⊥ against geometry (and confounders when they are what hides it)


def _explained(Sp: np.ndarray, Qo: np.ndarray) -> float:
    """Share of ‖Sp‖² (columns unit-scaled) in span(Qo)."""
    n = np.linalg.norm(Sp, axis=0)
    if not np.any(n > 0) or Qo.shape[1] == 0:
        return 0.0
    U = Sp[:, n > 0] / n[n > 0]
    return float(np.sum((Qo.T @ U) ** 2) / np.sum(U**2))


def absorbing_parameters(S: np.ndarray, Jf: np.ndarray, names: list[str], top: int = 3) -> str:
    """The free geometric parameters that best reproduce signature S (first column), named."""
    if Jf.shape[1] == 0:
        return "nothing"
    norms = np.linalg.norm(Jf, axis=0)
    norms[norms == 0] = 1
    s = S[:, 0] / max(np.linalg.norm(S[:, 0]), 1e-300)
    coef, *_ = np.linalg.lstsq(Jf / norms, s, rcond=None)
    best = np.argsort(-np.abs(coef))[:top]
    return " + ".join(names[b] for b in best if abs(coef[b]) > 1e-3) or "nothing"


def gate(effects: list[Effect], S: list[np.ndarray], Jf: np.ndarray, free_names: list[str], sigma: float,
         alpha: float = 0.01) -> list[Gate]:
    """Detectability of every candidate (module docstring); `S[i]` is effect i's signature (n, k)."""
    Q = orthonormal(Jf)
    m = len(effects)
    z = scipy.stats.norm.ppf(1 - alpha / (2 * m)) + POWER_Z
    proj = [project_out(s, Q) for s in S]
    basis = [orthonormal(p) for p in proj]
    order = np.argsort([e.priority for e in effects], kind="stable")
    gates: list[Gate | None] = [None] * m
    kept: list[int] = []
    for i in order:
        e, s, sp = effects[i], S[i], proj[i]
        tot = float(np.sum(s**2))
        absorbed = 1.0 - float(np.sum(sp**2)) / tot if tot > 0 else 1.0
        absorbed_by = absorbing_parameters(s, Jf, free_names) if tot > 0 else "nothing (no effect on these measurements)"
        hide = sp
        conf_label = ""
        # explicit confounders: the union of all candidates of the named kinds
        group = [j for j in range(m) if effects[j].name in e.confounders]
        if group:
            Qg = orthonormal(np.hstack([proj[j] for j in group]))
            share = _explained(sp, Qg)
            if share > 0.5:  # what the confounders leave is what can be detected
                hide = project_out(sp, Qg)
                conf_label = " + ".join(sorted({effects[j].name for j in group}))
                if share > CONFOUND:
                    hide = np.zeros_like(sp)
        # pairwise: an earlier (simpler) identifiable candidate that reproduces this one
        for j in kept:
            if _explained(sp, basis[j]) > CONFOUND:
                hide = np.zeros_like(sp)
                conf_label = effects[j].label
                break
        if tot == 0 or not np.any(hide):  # absorbed, or confounded beyond CONFOUND
            smin = 0.0
        else:
            sv = np.linalg.svd(hide, compute_uv=False)
            smin = float(sv[-1]) if sv.size == e.k else 0.0
            if smin < RANK_REL * np.sqrt(tot):
                smin = 0.0
        if e.data.get("blocked"):  # the library knows this campaign cannot expose it
            smin = 0.0
            conf_label = e.data.get("absorbed_by", "")
        mds = np.inf if smin == 0 else z * sigma / smin + e.tolerance
        ok = bool(np.isfinite(mds) and mds <= e.plausible)
        if conf_label:
            absorbed_by = f"{absorbed_by} with {conf_label}"
        if ok:
            reason = ""
            kept.append(i)
        elif e.data.get("blocked"):
            reason = e.data["blocked"]
        elif tot == 0:
            reason = "no effect on these measurements"
        elif conf_label:
            reason = f"indistinguishable from {conf_label} in this campaign"
        elif smin == 0:
            reason = f"fully absorbed by the geometry ({absorbed_by})"
        else:
            reason = (f"smallest detectable size {mds:.3g} {e.units[0]} exceeds the plausible {e.plausible:.3g} "
                      f"{e.units[0]} ({absorbed * 100:.1f} % absorbed by the geometry)")
        gates[i] = Gate(e, absorbed, float(mds), ok, absorbed_by, reason, sp)
    return gates  # type: ignore[return-value]


@dataclass
class Step:
    """One accepted forward-selection step."""

    index: int  # into the candidate list
    statistic: float  # grouped F
    dof: tuple[int, int]
    p_value: float  # raw
    p_holm: float  # Holm-adjusted (monotone)
    gain: float  # RSS reduction, m²


def forward_select(r: np.ndarray, candidates: list[np.ndarray], dof_resid: int, alpha: float = 0.01,
                   tolerances: list[float] | None = None, max_terms: int = 8, n_family: int | None = None,
                   base: np.ndarray | None = None) -> list[Step]:
    """Forward selection by grouped F with Holm's step-down thresholds (module docstring).

    `r` (n,) residuals ⊥ the geometry; `candidates` their projected signatures (n, k_c);
    `dof_resid` = n − free geometric parameters; `tolerances` per candidate (single-parameter
    interval nulls: an estimate within ±tol counts as zero); `base` columns already in the model.
    All candidates are projected at once; each step costs one matrix product and a few k×k solves.
    """
    m = len(candidates) if n_family is None else n_family
    if not candidates:
        return []
    tol = tolerances or [0.0] * len(candidates)
    ks = [c.shape[1] for c in candidates]
    edges = np.concatenate([[0], np.cumsum(ks)])
    C = np.hstack(candidates)
    cn = np.linalg.norm(C, axis=0)
    C = C / np.where(cn > 0, cn, 1.0)  # unit columns: gains and ranks do not depend on units
    B = np.zeros((r.size, 0)) if base is None else orthonormal(base)
    res = project_out(r[:, None], B)[:, 0]
    rss = float(res @ res)
    dof = dof_resid - B.shape[1]
    steps: list[Step] = []
    chosen: set[int] = set()
    p_adj_prev = 0.0
    for j in range(min(max_terms, m)):
        R = project_out(C, B)
        G = R.T @ R
        g = R.T @ res
        best = None
        for c in range(len(candidates)):
            if c in chosen:
                continue
            sl = slice(edges[c], edges[c + 1])
            Gc, gc = G[sl, sl], g[sl]
            w, V = np.linalg.eigh(Gc)
            keep = w > RANK_REL
            kc = int(keep.sum())
            if kc == 0 or dof - kc < 1:
                continue
            proj = (V[:, keep].T @ gc) / np.sqrt(w[keep])
            gain = float(proj @ proj)
            if tol[c] > 0 and kc == 1 and ks[c] == 1:
                theta = abs(float(gc[0])) / float(Gc[0, 0]) / cn[edges[c]]  # parameter units
                shrink = max(theta - tol[c], 0.0) / theta if theta > 0 else 0.0
                gain *= shrink**2
            F = (gain / kc) / (max(rss - gain, 1e-300) / (dof - kc))
            p = float(scipy.special.fdtrc(kc, dof - kc, F))
            if best is None or p < best[0] or (p == best[0] and F > best[1]):
                best = (p, F, c, kc, gain)
        if best is None:
            break
        p, F, c, kc, gain = best
        if p > alpha / (m - j):
            break
        p_adj_prev = max(p_adj_prev, min(1.0, p * (m - j)))
        steps.append(Step(c, float(F), (kc, dof - kc), p, p_adj_prev, gain))
        chosen.add(c)
        Qc = orthonormal(R[:, edges[c]:edges[c + 1]], 1e-6)
        B = np.hstack([B, Qc])
        res = project_out(res[:, None], Qc)[:, 0]
        rss = float(res @ res)
        dof -= kc
    return steps


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


def measurement_whitener(sources: list[np.ndarray], variances: np.ndarray, floor: float = 1e-3):
    """Row map (nk, c) → (nk, c) that whitens each measurement's k residual rows by its noise
    covariance Σ_i = Σ_j s_j N_ij N_ijᵀ + s_iso I (`noise_components`).  `floor` (relative to the
    median largest eigenvalue of Σ_i) only guards directions no source reaches against a zero
    variance estimate; the output keeps the residual's units (scaled by √median λ_max)."""
    n, k = sources[0].shape[:2]
    C = np.zeros((n, k, k))
    for N, v in zip(sources, variances):
        N = np.asarray(N, float)
        C += v * np.einsum("nic,njc->nij", N, N)
    lam_med = float(np.median(np.linalg.eigvalsh(C + variances[-1] * np.eye(k))[:, -1]))
    C += max(variances[-1], floor * lam_med) * np.eye(k)
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
