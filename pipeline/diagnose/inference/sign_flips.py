"""Sign-flip checks for pose-clustered campaigns: the restricted wild cluster bootstrap of a
block's grouped F (`wild_cluster_p`) and of each finding given the others (`cluster_sign_flip_p`),
the reference that assumes nothing about the error within a cluster (`stepwise` module docstring)."""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.inference.projection import orthonormal, project_out


def wild_cluster_p(res: np.ndarray, QA: np.ndarray, bases: list[np.ndarray], cluster: np.ndarray,
                   n_boot: int = 2999, seed: int = 0) -> np.ndarray:
    """p-value of each block's grouped F against a design by the restricted wild cluster bootstrap:
    the residual r̂ of the design (orthonormal QA; r̂ ⊥ QA, the null model) with each cluster's rows
    times one random sign (Rademacher), re-projected ⊥ QA; `bases` orthonormal (⊥ QA) columns of
    each block.  Each cluster keeps its own error covariance, whatever it is: no estimate of it
    enters the reference (Cameron, Gelbach & Miller 2008) — valid so long as the clusters are
    independent and their errors symmetric.  A draw's RSS is ‖r̂‖² − ‖QAᵀD_s r̂‖² and a block's
    gain ‖QbᵀD_s r̂‖²; Qᵀ D_s r̂ = C s with C the per-cluster contributions (columns × clusters),
    so every draw is algebra in the number of clusters.  Statistic gain/(RSS − gain) (F up to its
    dof); p = (1 + #{T* ≥ T}) / (n_boot + 1), seeded (reproducible)."""
    ids, inv = np.unique(cluster, return_inverse=True)
    Rh = np.asarray(res, float)[:, None] * (inv[:, None] == np.arange(ids.size)[None, :])  # (N, G)
    signs = np.random.default_rng(seed).choice([-1.0, 1.0], size=(ids.size, n_boot))
    rr = float(np.asarray(res, float) @ np.asarray(res, float))
    rss = rr - np.sum((QA.T @ Rh @ signs) ** 2, axis=0)
    p = np.ones(len(bases))
    for b, Qb in enumerate(bases):
        if Qb.shape[1] == 0:
            continue
        Cb = Qb.T @ Rh
        g_obs = float(np.sum(Cb.sum(axis=1) ** 2))
        t_obs = g_obs / max(rr - g_obs, 1e-300)
        g = np.sum((Cb @ signs) ** 2, axis=0)
        p[b] = (1 + np.count_nonzero(g / np.maximum(rss - g, 1e-300) >= t_obs * (1 - 1e-12))) / (n_boot + 1)
    return p


def cluster_sign_flip_p(r: np.ndarray, blocks: list[np.ndarray], base: np.ndarray, cluster: np.ndarray,
                        n_draw: int = 9999, seed: int = 0) -> np.ndarray:
    """p-value of each block (N, k_b) given `base` and the other blocks (the last-in grouped F) by
    the restricted wild cluster bootstrap (`wild_cluster_p`): the check on a selection whose F
    tests assume one model of the error within a cluster (`cluster_whitener`)."""
    p = np.ones(len(blocks))
    for b in range(len(blocks)):
        Q0 = orthonormal(np.hstack([base] + [blocks[c] for c in range(len(blocks)) if c != b]))
        r0 = project_out(np.asarray(r, float)[:, None], Q0)[:, 0]
        p[b] = wild_cluster_p(r0, Q0, [orthonormal(project_out(blocks[b], Q0))], cluster, n_draw, seed)[0]
    return p
