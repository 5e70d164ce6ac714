"""The 95 % bound on one calibration's RMS error over many points (`propagate.rms_bound`): its
distribution against brute-force sampling, and its coverage on linear least-squares problems
generated and solved independently (numpy lstsq, σ estimated from the residuals)."""

from __future__ import annotations

import numpy as np

from pipeline.accuracy.propagate import rms_bound, rms_samples


def test_rms_distribution_matches_brute_force_sampling():
    rng = np.random.default_rng(0)
    Jp = rng.normal(size=(200, 3, 6)) * np.array([1, 1, 1, 0.3, 0.1, 0.01])
    A = rng.normal(size=(6, 6))
    cov = A @ A.T * 1e-8
    d = rng.multivariate_normal(np.zeros(6), cov, 20_000)
    brute = np.sqrt(np.mean(np.einsum("nip,sp->sni", Jp, d) ** 2, axis=(1,)).sum(axis=1))
    ours = rms_samples(Jp, cov)
    for q in (0.05, 0.5, 0.95):
        assert abs(np.quantile(ours, q) / np.quantile(brute, q) - 1) < 0.03
    # the predicted RMS (sqrt of the mean trace of Jp Σ Jpᵀ) is the root mean square of the distribution
    pred = np.sqrt(np.einsum("nip,pq,niq->", Jp, cov, Jp) / 200)
    assert abs(np.sqrt(np.mean(ours**2)) / pred - 1) < 0.02


def test_the_95_bound_covers_95_percent_of_independent_calibrations():
    """y = A θ + N(0, σ²), θ̂ by least squares, Σ = σ̂²(AᵀA)⁻¹ with σ̂ from 20 residual dof; the
    RMS over 300 points of Jp (θ̂ − θ) is within the bound in 95 % of 600 problems (binomial 3σ:
    91.8–97.5 %); within the 1σ prediction alone only about half the time."""
    rng = np.random.default_rng(1)
    m, p = 26, 6
    within = within_pred = 0
    trials = 600
    Jp = rng.normal(size=(300, 3, p))
    for t in range(trials):
        A = rng.normal(size=(m, p)) * rng.uniform(0.1, 2, p)
        theta = rng.normal(size=p)
        y = A @ theta + rng.normal(0, 1e-3, m)
        est, *_ = np.linalg.lstsq(A, y, rcond=None)
        s2 = np.sum((y - A @ est) ** 2) / (m - p)
        cov = s2 * np.linalg.inv(A.T @ A)
        true = np.sqrt(np.mean(np.sum(np.einsum("nip,p->ni", Jp, est - theta) ** 2, axis=1)))
        within += true <= rms_bound(Jp, cov, 0.95, m - p)
        within_pred += true <= np.sqrt(np.einsum("nip,pq,niq->", Jp, cov, Jp) / 300)
    assert 0.918 <= within / trials <= 0.975, within / trials
    assert within_pred / trials < 0.8


def test_fixture_covariance_matches_the_spread_of_estimates_with_shared_face_errors():
    """Linear problems whose measurements on one face share an offset uniform in ±tol: the empirical
    covariance of the least-squares estimates is σ²(AᵀA)⁻¹ + fixture_covariance, not the first alone."""
    from pipeline.accuracy.propagate import fixture_covariance

    rng = np.random.default_rng(2)
    m, p, tol, sigma = 70, 5, 2e-5, 1e-5
    A = rng.normal(size=(m, p))
    labels = np.array([f"face{i % 7}" for i in range(m)])
    D = (labels[:, None] == np.unique(labels)[None]).astype(float)
    trials = 20_000
    y = rng.uniform(-tol, tol, (trials, 7)) @ D.T + rng.normal(0, sigma, (trials, m))  # θ = 0
    est = y @ np.linalg.pinv(A).T
    emp = est.T @ est / trials
    noise_only = sigma**2 * np.linalg.inv(A.T @ A)
    model = noise_only + fixture_covariance(A, labels, 1, tol)
    assert abs(np.trace(emp) / np.trace(model) - 1) < 0.04
    assert np.trace(emp) / np.trace(noise_only) > 1.3  # the face errors matter here
    assert np.abs(emp - model).max() < 0.1 * np.abs(model).max()
