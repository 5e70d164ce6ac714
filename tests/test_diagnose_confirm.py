"""Honest intervals of the diagnosis's refit (`pipeline.diagnose.inference.augmented`): CR2 cluster-robust
standard errors with Bell–McCaffrey degrees of freedom, the shared-error sandwich's dof, and the
t-based 95 % interval a finding reports."""

from __future__ import annotations

import numpy as np
from scipy import stats

from pipeline.diagnose.inference import augmented


def test_cr2_dof_of_a_balanced_mean_is_clusters_minus_one_and_widens_the_interval():
    """The mean of G balanced clusters: CR2 is the t-test on the cluster means, exactly G − 1 dof."""
    G, m = 8, 5
    cl = np.repeat(np.arange(G), m)
    A = np.ones((G * m, 1))
    r = np.random.default_rng(0).normal(size=G * m)
    r -= r.mean()
    std, dof = augmented.cluster_robust_std(A, r, cl)
    assert abs(dof[0] - (G - 1)) < 1e-9
    # the CR2 variance of a balanced mean is the between-cluster variance of the means / G
    means = r.reshape(G, m).mean(axis=1)
    assert abs(std[0] - means.std(ddof=1) / np.sqrt(G)) < 1e-12
    lo, hi = augmented.t_interval(1.0, std[0], dof[0])
    assert abs((hi - lo) / 2 / std[0] - stats.t.ppf(0.975, G - 1)) < 1e-12  # 2.36, not 1.96
    assert augmented.t_interval(1.0, 0.1, np.inf) == [1.0 - 0.1 * stats.norm.ppf(0.975), 1.0 + 0.1 * stats.norm.ppf(0.975)]


def test_cr2_t_interval_covers_with_few_clusters_where_the_normal_interval_does_not():
    """A slope carried by 10 pose-clustered groups of 5 (a pose error shared by its rows, as in the
    scanner): over 600 simulated campaigns the t-interval with Bell–McCaffrey dof covers ≈ 95 %,
    ±1.96 std under-covers (the CR2 variance from 10 clusters is itself noisy)."""
    rng = np.random.default_rng(3)
    G, m = 10, 5
    cl = np.repeat(np.arange(G), m)
    x_pose = rng.normal(size=G)
    x = np.repeat(x_pose, m) + 0.3 * rng.normal(size=G * m)
    A = np.column_stack([np.ones(G * m), x])
    P = np.linalg.pinv(A)
    t_in, z_in, dofs = [], [], []
    for _ in range(600):
        e = np.repeat(rng.normal(size=G), m) + 0.5 * rng.normal(size=G * m)
        b = P @ e  # truth 0
        std, dof = augmented.cluster_robust_std(A, e - A @ b, cl)
        lo, hi = augmented.t_interval(b[1], std[1], dof[1])
        t_in.append(lo <= 0 <= hi)
        z_in.append(abs(b[1]) <= 1.96 * std[1])
        dofs.append(dof[1])
    assert 2 < np.median(dofs) < G - 1
    assert np.mean(t_in) >= 0.93
    assert np.mean(z_in) < np.mean(t_in) - 0.02


def test_shared_error_dof_is_the_residual_dof_without_group_errors_and_more_with_them():
    rng = np.random.default_rng(1)
    n, p, g = 60, 3, 6
    A = rng.normal(size=(n, p))
    Z = (rng.integers(0, g, n)[:, None] == np.arange(g)[None, :]).astype(float)
    r = rng.normal(size=n)
    r -= A @ np.linalg.lstsq(A, r, rcond=None)[0]
    _, _, nu0 = augmented.shared_error_covariance(A, r, Z, 0.0)
    assert np.allclose(nu0, n - p)
    cov, sig, nu = augmented.shared_error_covariance(A, r, Z, 0.3)
    v_sig = sig**2 * np.diag(np.linalg.pinv(A.T @ A))
    assert np.all(nu > n - p) and np.allclose(nu, (n - p) * (np.diag(cov) / v_sig) ** 2)


def test_cr2_under_a_working_covariance_is_unbiased_and_its_dof_counts_the_noisy_clusters():
    """Rows of 3-D points whose noise is rank 2 and of very unequal size (the scanner: pixel noise
    through ∂P/∂pixel), two of 12 clusters much noisier: with the noise shape as working
    covariance the CR2 variance is unbiased (Monte Carlo mean / exact sandwich ≈ 1), its dof
    reflects that few clusters carry the variance (far below the i.i.d.-working dof) and the t
    interval covers ≥ 93 %; with identity blocks it is the i.i.d.-working CR2 itself."""
    rng = np.random.default_rng(7)
    G, m, k, p = 12, 4, 3, 3
    n = G * m
    cl = np.repeat(np.arange(G), m * k)
    size = np.repeat(np.where(np.arange(G) < 2, 6.0, 0.5), m)
    A = rng.normal(size=(n * k, p))
    N = rng.normal(size=(n, k, 2)) * size[:, None, None]  # rank 2, unequal sizes
    C = np.einsum("nic,njc->nij", N, N)
    P = np.linalg.pinv(A)
    H = A @ P
    Om = np.zeros((n * k, n * k))
    for i in range(n):
        Om[k * i:k * i + k, k * i:k * i + k] = C[i]
    true_var = np.diag(P @ Om @ P.T)
    v_w, cov_w, dof_w, dof_iid = [], [], [], []
    for _ in range(300):
        e = np.einsum("nic,nc->ni", N, rng.normal(size=(n, 2))).ravel()
        b, r = P @ e, e - H @ e  # truth 0
        s_w, d_w = augmented.cluster_robust_std(A, r, cl, C)
        d_i = augmented.cluster_robust_std(A, r, cl)[1]
        v_w.append(s_w**2)
        cov_w.append([abs(b[j]) <= stats.t.ppf(0.975, d_w[j]) * s_w[j] for j in range(p)])
        dof_w.append(d_w)
        dof_iid.append(d_i)
    assert np.all(np.abs(np.mean(v_w, axis=0) / true_var - 1) < 0.1)
    assert np.all(np.median(dof_w, axis=0) < 0.5 * np.median(dof_iid, axis=0))
    assert np.all(np.mean(cov_w, axis=0) >= 0.93)
    r = rng.normal(size=n * k)
    r -= H @ r
    s_eye, d_eye = augmented.cluster_robust_std(A, r, cl, np.broadcast_to(np.eye(k), (n, k, k)))
    s0, d0 = augmented.cluster_robust_std(A, r, cl)
    assert np.allclose(s_eye, s0, rtol=1e-8) and np.allclose(d_eye, d0, rtol=1e-6)
