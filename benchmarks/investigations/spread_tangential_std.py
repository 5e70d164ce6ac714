"""Offline comparison of std estimators of p1, p2 on the refit problems dumped by spread_tangential_dump.py.
usage: PYTHONPATH=. python benchmarks/investigations/spread_tangential_std.py DIR [GLOB]
Estimators (same OLS estimate): CR2 + Bell–McCaffrey dof (the diagnosis before), i.i.d. σ(AᵀA)⁻¹ (normal), CR2 with a
working covariance Φ (Bell & McCaffrey's bias-reduced linearisation: unbiased when Φ is right) + BM dof under Φ, with
Φ = the per-measurement noise model (pixel noise through ∂P/∂pixel, print error along the stripe, isotropic;
`select.noise_components`) alone ('wCR2') and plus the pose random effects ZΨZᵀ ('wCR2+re')."""
import glob
import sys

import numpy as np
from scipy import stats

from pipeline.diagnose.inference import augmented
from pipeline.diagnose.inference.clustered import noise_components


def working_cov(r, cl, src, Z, with_re, corner_id=None):
    n = src[0].shape[0]
    Zf = Z.reshape(n * 3, -1)
    nm = noise_components(r, Zf, cl, src)
    C = sum(v * np.einsum("nic,njc->nij", N, N) for N, v in zip(src, nm.variances))
    C = C + nm.variances[-1] * np.eye(3)
    Phi = np.zeros((n * 3, n * 3))
    for i in range(n):
        Phi[3 * i:3 * i + 3, 3 * i:3 * i + 3] = C[i]
    if with_re:
        U, V = [], []
        for g in np.unique(cl):
            rows = np.flatnonzero(cl == g)
            Zp = np.linalg.pinv(Zf[rows], rcond=1e-9)
            U.append(Zp @ r[rows])
            V.append(Zp @ Phi[np.ix_(rows, rows)] @ Zp.T)
        U = np.array(U)
        psi = U.T @ U / len(U) - np.mean(V, axis=0)
        w, Q = np.linalg.eigh(0.5 * (psi + psi.T))
        psi = (Q * np.clip(w, 0, None)) @ Q.T
        for g in np.unique(cl):
            rows = np.flatnonzero(cl == g)
            Phi[np.ix_(rows, rows)] += Zf[rows] @ psi @ Zf[rows].T
    if corner_id is not None:  # the printed corner's error is shared by every measurement of that corner
        d = src[1][:, :, 0]
        for c in np.unique(corner_id):
            m = np.flatnonzero(corner_id == c)
            for i in m:
                for j in m:
                    if i != j:
                        Phi[3 * i:3 * i + 3, 3 * j:3 * j + 3] += nm.variances[1] * np.outer(d[i], d[j]) * (d[i] @ d[j])
    return Phi


def psd_power(S, p, tol=1e-10):
    w, Q = np.linalg.eigh(0.5 * (S + S.T))
    keep = w > tol * max(w.max(), 1e-300)
    return (Q[:, keep] * w[keep] ** p) @ Q[:, keep].T


def _scaled_hat(A):
    """(column norms, unit-scaled X, (XᵀX)⁺, I − H) of design A."""
    cn = np.linalg.norm(A, axis=0)
    cn[cn == 0] = 1
    X = A / cn
    M = np.linalg.pinv(X.T @ X)
    return cn, X, M, np.eye(X.shape[0]) - X @ M @ X.T


def wcr2(A, r, cl, Phi):
    """CR2 with working covariance Phi (N,N), block-diagonal by cluster; BM dof under Phi."""
    cn, X, M, IH = _scaled_hat(A)
    N, p = X.shape
    ids = np.unique(cl)
    sc = np.zeros((len(ids), p))
    Cg = []  # c_g for all parameters: (N, p)
    for a, g in enumerate(ids):
        rows = np.flatnonzero(cl == g)
        Pg = Phi[np.ix_(rows, rows)]
        Ph = psd_power(Pg, 0.5)
        E = IH[rows] @ Phi @ IH[rows].T
        Ag = Ph @ psd_power(Ph @ E @ Ph, -0.5) @ Ph
        sc[a] = X[rows].T @ Ag @ r[rows]
        Cg.append(IH[rows].T @ Ag @ X[rows] @ M)
    V = M @ sc.T @ sc @ M
    dof = np.zeros(p)
    for j in range(p):
        c = np.stack([C[:, j] for C in Cg], axis=1)  # (N, G)
        K = c.T @ Phi @ c
        dof[j] = np.trace(K) ** 2 / np.sum(K * K)
    return np.sqrt(np.clip(np.diag(V), 0, None)) / cn, dof


def cr2_multiway(A, r, ways):
    """Multiway cluster-robust variance (Cameron, Gelbach & Miller 2011) with CR2 adjustments per way:
    V = Σ_w sign_w Σ_g M X_gᵀ A_g r_g r_gᵀ A_g X_g M, A_g = (I − H)_gg^{-1/2}; `ways` = [(labels (N,), sign)].
    dof per parameter: Satterthwaite of the quadratic form eᵀCe under i.i.d. errors (as Bell–McCaffrey)."""
    cn, X, M, IH = _scaled_hat(A)
    N, p = X.shape
    V = np.zeros((p, p))
    C = np.zeros((p, N, N))
    for labels, sign in ways:
        for g in np.unique(labels):
            rows = np.flatnonzero(labels == g)
            Ag = psd_power(IH[np.ix_(rows, rows)], -0.5, 1e-6)
            s_g = X[rows].T @ Ag @ r[rows]
            V += sign * np.outer(M @ s_g, M @ s_g)
            c = IH[rows].T @ Ag @ X[rows] @ M  # (N, p)
            C += sign * np.einsum("nj,mj->jnm", c, c)
    dof = np.array([np.trace(C[j]) ** 2 / np.sum(C[j] * C[j]) for j in range(p)])
    return np.sqrt(np.clip(np.diag(V), 0, None)) / cn, dof


def main():
    files = sorted(glob.glob(f"{sys.argv[1]}/{sys.argv[2] if len(sys.argv) > 2 else '*.npz'}"))
    res = {k: [] for k in ("CR2", "iid", "wCR2", "wCR2+re", "CR2-2way", "CR2-corner", "model", "model+corner")}
    for fn in files:
        d = np.load(fn)
        A, r, cl = d["A"], d["r"], d["cl"]
        src = [d["src_px"], d["src_print"]]
        s_cr2, dof_cr2 = augmented.cluster_robust_std(A, r, cl)
        unit = d["std"] / s_cr2[-2:]  # physical per fitted unit
        err = d["est"] - d["truth"]
        cn = np.linalg.norm(A, axis=0)
        B = np.linalg.pinv((A / cn).T @ (A / cn)) / np.outer(cn, cn)
        sig = np.sqrt(r @ r / (r.size - A.shape[1]))
        out = {"CR2": (s_cr2[-2:], dof_cr2[-2:]), "iid": (sig * np.sqrt(np.diag(B))[-2:], np.full(2, np.inf))}
        for key, re in (("wCR2", False), ("wCR2+re", True)):
            s, dof = wcr2(A, r, cl, working_cov(r, cl, src, d["Z"], re))
            out[key] = (s[-2:], dof[-2:])
        if "corner" in d.files and len(sys.argv) > 3:  # slow: multiway and corner-shared variants
            _, cid = np.unique(np.round(d["corner"], 7), axis=0, return_inverse=True)
            cc = np.repeat(cid.ravel(), 3)
            meas = np.arange(r.size) // 3
            s, dof = cr2_multiway(A, r, [(cl, 1), (cc, 1), (meas, -1)])
            out["CR2-2way"] = (s[-2:], dof[-2:])
            s, dof = cr2_multiway(A, r, [(cc, 1)])
            out["CR2-corner"] = (s[-2:], dof[-2:])
            cn = np.linalg.norm(A, axis=0)
            X = A / cn
            Mi = np.linalg.pinv(X.T @ X)
            Om = working_cov(r, cl, src, d["Z"], True, cid.ravel())
            V = Mi @ X.T @ Om @ X @ Mi
            out["model+corner"] = (np.sqrt(np.diag(V))[-2:] / cn[-2:], np.full(2, np.inf))
        cn = np.linalg.norm(A, axis=0)
        X = A / cn
        Mi = np.linalg.pinv(X.T @ X)
        V = Mi @ X.T @ working_cov(r, cl, src, d["Z"], True) @ X @ Mi
        out["model"] = (np.sqrt(np.diag(V))[-2:] / cn[-2:], np.full(2, np.inf))
        for k, (s, dof) in out.items():
            res[k].append((err / (s * unit), dof))
    print(f"{len(files)} runs")
    for k, v in res.items():
        if not v:
            continue
        z = np.array([a for a, _ in v])
        dof = np.array([b for _, b in v])
        q = np.where(np.isfinite(dof), stats.t.ppf(0.975, np.where(np.isfinite(dof), dof, 1)), 1.96)
        cov = np.mean(np.abs(z) <= q, axis=0)
        print(f"{k:8s} " + " | ".join(f"p{j + 1}: z mean {z[:, j].mean():+.2f} sd {z[:, j].std(ddof=1):.2f} cover "
                                       f"{cov[j] * 100:.0f} % dof med {np.median(dof[:, j]):.1f}" for j in range(2)))


main()
