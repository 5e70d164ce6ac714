"""Honest intervals of the diagnosis's refit (`pipeline.diagnose.confirm`): CR2 cluster-robust
standard errors with Bell–McCaffrey degrees of freedom, the shared-error sandwich's dof, and the
t-based 95 % interval a finding reports."""

from __future__ import annotations

import numpy as np
from scipy import stats

from pipeline.diagnose import confirm


def test_cr2_dof_of_a_balanced_mean_is_clusters_minus_one_and_widens_the_interval():
    """The mean of G balanced clusters: CR2 is the t-test on the cluster means, exactly G − 1 dof."""
    G, m = 8, 5
    cl = np.repeat(np.arange(G), m)
    A = np.ones((G * m, 1))
    r = np.random.default_rng(0).normal(size=G * m)
    r -= r.mean()
    std, dof = confirm.cluster_robust_std(A, r, cl)
    assert abs(dof[0] - (G - 1)) < 1e-9
    # the CR2 variance of a balanced mean is the between-cluster variance of the means / G
    means = r.reshape(G, m).mean(axis=1)
    assert abs(std[0] - means.std(ddof=1) / np.sqrt(G)) < 1e-12
    lo, hi = confirm.t_interval(1.0, std[0], dof[0])
    assert abs((hi - lo) / 2 / std[0] - stats.t.ppf(0.975, G - 1)) < 1e-12  # 2.36, not 1.96
    assert confirm.t_interval(1.0, 0.1, np.inf) == [1.0 - 0.1 * stats.norm.ppf(0.975), 1.0 + 0.1 * stats.norm.ppf(0.975)]


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
        std, dof = confirm.cluster_robust_std(A, e - A @ b, cl)
        lo, hi = confirm.t_interval(b[1], std[1], dof[1])
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
    _, _, nu0 = confirm.shared_error_covariance(A, r, Z, 0.0)
    assert np.allclose(nu0, n - p)
    cov, sig, nu = confirm.shared_error_covariance(A, r, Z, 0.3)
    v_sig = sig**2 * np.diag(np.linalg.pinv(A.T @ A))
    assert np.all(nu > n - p) and np.allclose(nu, (n - p) * (np.diag(cov) / v_sig) ** 2)
