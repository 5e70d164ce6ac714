"""The run's held-out error against the accuracy it states (`accuracy.holdout`), and the error a
configuration's measurements share (`accuracy.noise`): on linear least-squares problems generated and
solved here with numpy (σ̂ from the residuals, k-fold refits by lstsq), then on the bundled scanner."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.accuracy import assess, noise
from pipeline.accuracy.holdout import consistency
from pipeline.identify.least_squares import kfold_indices


def _problem(rng, m=60, p=8, k=1, scale=None):
    """(A, y) with y = Aθ + noise of per-row scale `scale` (m·k,), or 1e-3 everywhere."""
    A = rng.normal(size=(m * k, p)) * rng.uniform(0.2, 2, p)
    s = np.full(m * k, 1e-3) if scale is None else scale
    return A, A @ rng.normal(size=p) + rng.normal(size=m * k) * s


def _cv(A, y, folds, k=1):
    """In-sample residuals and k-fold held-out residuals (refits by lstsq), per measurement (m, k)."""
    est, *_ = np.linalg.lstsq(A, y, rcond=None)
    e = A @ est - y
    h = np.zeros_like(y)
    rows = lambda f: np.concatenate([np.arange(i * k, i * k + k) for i in f])  # noqa: E731
    for f in folds:
        r = rows(f)
        keep = np.setdiff1d(np.arange(y.size), r)
        et, *_ = np.linalg.lstsq(A[keep], y[keep], rcond=None)
        h[r] = A[r] @ et - y[r]
    return e.reshape(-1, k), h.reshape(-1, k)


def test_consistent_data_are_flagged_at_the_stated_rate():
    """Independent Gaussian noise of one σ: the 99 % test flags about 1 % of 300 problems (binomial
    3σ: at most 3 %), and the predicted held-out RMS matches the observed on average."""
    rng = np.random.default_rng(0)
    flagged, ratios = 0, []
    for _ in range(300):
        A, y = _problem(rng)
        folds = kfold_indices(60, 5, int(rng.integers(1000)))
        e, h = _cv(A, y, folds)
        c = consistency(A, e, h, folds, 1, n_samples=400)
        flagged += not c["consistent"]
        ratios.append(c["ratio"])
    assert flagged / 300 <= 0.03, flagged
    assert abs(np.mean(ratios) - 1) < 0.05


def test_noise_that_grows_with_leverage_is_flagged_and_inflates_by_the_ratio():
    """Noise 10× larger on the measurements the fit leans on most (high leverage): σ̂ from the residuals
    understates the parameters' error and the held-out error shows it — in most problems (against 1 %
    when the noise is as stated)."""
    rng = np.random.default_rng(1)
    flagged = 0
    for t in range(40):
        A = rng.normal(size=(60, 8))
        A[:6] *= 4  # a few far-out configurations
        lev = np.einsum("ij,ji->i", A, np.linalg.pinv(A))
        s = np.where(lev > np.quantile(lev, 0.85), 1e-2, 1e-3)
        y = A @ rng.normal(size=8) + rng.normal(size=60) * s
        folds = kfold_indices(60, 5, t)
        e, h = _cv(A, y, folds)
        c = consistency(A, e, h, folds, 1, n_samples=400)
        flagged += not c["consistent"]
        if not c["consistent"]:
            assert c["inflation"] == pytest.approx(np.sqrt(c["ratio"])) and c["inflation"] > 1
    assert flagged >= 18, flagged


def test_a_configurations_shared_error_in_the_covariance_matches_monte_carlo():
    """Five measurements per configuration share one offset (τ) on top of their own noise (σ_w): the
    empirical covariance of the least-squares estimates is the sandwich J⁺ΩJ⁺ᵀ, not σ²(JᵀJ)⁻¹."""
    rng = np.random.default_rng(2)
    groups = np.repeat(np.arange(8), 5)
    m, k, p, sw, tau = 40, 3, 6, 1e-4, 3e-4
    # measurements of one configuration see the parameters alike (their Jacobian rows are close)
    A = (rng.normal(size=(8, k, p))[groups] + 0.3 * rng.normal(size=(m, k, p))).reshape(m * k, p)
    B = noise.shared_matrix(groups, k)
    trials = 20_000
    shared = rng.normal(0, tau, (trials, 8, k))[:, groups, :].reshape(trials, -1)
    y = shared + rng.normal(0, sw, (trials, m * k))
    est = y @ np.linalg.pinv(A).T
    emp = est.T @ est / trials
    model = noise.sandwich(A, sw, tau, B)
    assert abs(np.trace(emp) / np.trace(model) - 1) < 0.03
    naive = (sw**2 + tau**2) * np.linalg.inv(A.T @ A)
    assert np.trace(emp) / np.trace(naive) > 1.5  # the shared part does not average out
    # and the moments recover σ_w and τ from one campaign's residuals (many configurations)
    U = np.linalg.svd(A, full_matrices=False)[0]
    e = y[0] - A @ est[0]
    got = noise.estimate(U, e.reshape(m, k), groups, k)
    assert got["sigma_w_m"] == pytest.approx(sw, rel=0.3) and got["tau_m"] == pytest.approx(tau, rel=0.5)


def test_an_inconsistent_holdout_blocks_pass_and_inflates_every_stated_figure():
    rng = np.random.default_rng(3)
    P, free = 6, np.ones(6, bool)
    Jm = rng.normal(size=(30, P))
    Jp = rng.normal(size=(30, 3, P)) * 1e-3
    base = dict(names=[f"p{i}" for i in range(P)], free=free, cov_free=np.eye(P) * 1e-8, prior_sigma=np.ones(P),
                Jm=Jm, Jp_meas=Jp, points_map=np.zeros((30, 3)), Jp_map=Jp, Jp_map_uncal=Jp, residual_dim=1)
    ok = assess.assess(assess.Inputs(**base))
    bad_ho = {"consistent": False, "inflation": 1.5, "ratio": 2.25, "p_value": 1e-4, "holdout_rms_m": 3e-4,
              "predicted_holdout_rms_m": 2e-4}
    bad = assess.assess(assess.Inputs(**base, holdout=bad_ho))
    assert ok["status"] == "pass" and bad["status"] == "warn"
    assert "held-out error contradicts the stated accuracy" in bad["reason"] and "×1.50" in bad["reason"]
    assert bad["map_rms_1sigma_m"] == pytest.approx(1.5 * ok["map_rms_1sigma_m"])
    assert np.allclose(bad["map"]["bound95_m"], 1.5 * np.asarray(ok["map"]["bound95_m"]))
    tol = assess.assess(assess.Inputs(**base, holdout=bad_ho), tolerance_m=1.2 * ok["map_max_bound95_m"])
    assert tol["status"] == "fail"  # the inflated bound no longer meets a tolerance the stated one met


def test_bundled_scanner_is_not_pass_and_names_the_held_out_error(tmp_path):
    """The scanner recording: held-out 0.166 mm where σ̂, the pose repeatability and the design predict
    0.135 mm — the stated accuracy is inflated and the status is warn (figures unchanged)."""
    from pathlib import Path

    from pipeline.calibrate import calibrate

    doc = calibrate(Path(__file__).resolve().parents[1] / "recordings" / "scorbot-scanner.mcap", tmp_path)
    acc = doc["accuracy"]
    assert doc["rms_after_m"] == pytest.approx(1.1359e-4, rel=0.05)
    assert doc["status"] == "warn" and "held-out error contradicts" in acc["reason"]
    ho = acc["holdout_check"]
    assert ho["p_value"] < 0.01 and ho["holdout_rms_m"] == pytest.approx(doc["holdout_rms_m"], rel=1e-6)
    assert acc["shared_error"]["tau_m"] == pytest.approx(2e-4 / 3) and acc["shared_error"]["tau_source"] == "stated"
