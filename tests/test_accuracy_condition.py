"""The parameters held at nominal, conditioned on the run's data (`pipeline.accuracy.condition`),
checked by Monte Carlo on independent linear problems (numpy least squares, no robocal fit):
* averaged over calibrations the conditioned second moment is the prior (E[Σ + μμᵀ] = S), and the
  stated point error is then the true one (honest where the prior is right);
* with a prior 10× wider than the truth the stated error follows the data, not the prior;
* a held-at-nominal column the fitted ones absorb exactly, or no measurement sees, keeps its prior;
* an estimate shrunk toward nominal (`shrunk_moment`): averaged over calibrations its stated second moment is
  its true mean-square error whatever scale the shrinkage chose (σ re-estimated at the prior's scale: the
  shrunk fit's σ̂ carries the robot's error), where the posterior at that scale understates a strong
  shrinkage's error; at the prior's own scale, σ given, the two are one."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from pipeline.accuracy import propagate as P
from pipeline.accuracy.condition import fixed_moment, shrunk_moment


def _problem(rng, m=60, nf=4, nx=3):
    J = rng.standard_normal((m, nf + nx))
    Jp = rng.standard_normal((20, 3, nf + nx))  # point Jacobians at 20 new configurations
    free = np.r_[np.ones(nf, bool), np.zeros(nx, bool)]
    return J, Jp, free


def _runs(J, Jp, free, prior, truth_sigma, noise, n, rng):
    """(stated mean-square point error, true mean-square point error) per calibration."""
    A = P.absorption(J, free)
    Jf = J[:, free]
    stated, true = [], []
    for _ in range(n):
        d = np.zeros(J.shape[1])
        d[~free] = rng.standard_normal((~free).sum()) * truth_sigma
        y = J @ d + noise * rng.standard_normal(J.shape[0])
        df, *_ = np.linalg.lstsq(Jf, y, rcond=None)  # fitted correction of the free parameters
        e = y - Jf @ df
        err = np.einsum("nip,p->ni", Jp[:, :, free], df - d[free]) - np.einsum("nik,k->ni", Jp[:, :, ~free], d[~free])
        s2 = e @ e / (J.shape[0] - Jf.shape[1])
        cov = s2 * np.linalg.inv(Jf.T @ Jf)
        pred = P.predict(Jp, free, cov, prior, A, fixed_moment(J, free, prior, e))
        stated.append(np.mean(pred.sigma**2))
        true.append(np.mean(np.sum(err**2, axis=1)))
    return np.array(stated), np.array(true)


def test_honest_where_the_prior_is_right():
    rng = np.random.default_rng(1)
    J, Jp, free = _problem(rng)
    prior = np.r_[np.ones(4), np.full(3, 0.05)]
    stated, true = _runs(J, Jp, free, prior, 0.05, 0.1, 3000, rng)
    assert 0.9 < np.mean(true) / np.mean(stated) < 1.1


def test_a_too_wide_prior_follows_the_data():
    rng = np.random.default_rng(2)
    J, Jp, free = _problem(rng)
    prior = np.r_[np.ones(4), np.full(3, 0.5)]  # 10× the truth's spread
    stated, true = _runs(J, Jp, free, prior, 0.05, 0.1, 1000, rng)
    A = P.absorption(J, free)
    unconditioned = np.mean(P.predict(Jp, free, np.zeros((4, 4)), prior, A).sigma ** 2)
    assert np.mean(stated) < 0.2 * unconditioned  # the full prior would state ≥ 5× the error
    assert 0.6 < np.mean(true) / np.mean(stated) < 1.5


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.floats(1e-3, 10.0))
def test_unseen_or_absorbed_columns_keep_their_prior(seed, scale):
    rng = np.random.default_rng(seed)
    J, _, free = _problem(rng, m=30, nf=3, nx=2)
    J[:, 3] = J[:, :3] @ rng.standard_normal(3)  # absorbed exactly by the fitted columns
    J[:, 4] = 0.0  # seen by no measurement
    prior = np.r_[np.ones(3), scale, 2 * scale]
    e = rng.standard_normal(30)
    M = fixed_moment(J, free, prior, e)
    assert fixed_moment(J, free, prior, np.zeros(30)) is None  # no residual: nothing learnt, the prior unchanged
    assert np.allclose(M, np.diag([scale**2, 4 * scale**2]), rtol=1e-6, atol=1e-12 * scale**2)


def test_thin_data_keeps_its_prior():
    """From fewer than MIN_DOF residual degrees of freedom σ̂² may be small by chance: no conditioning (the
    prior stands); from MIN_DOF on, a seen column is conditioned."""
    from pipeline.accuracy.condition import MIN_DOF

    rng = np.random.default_rng(5)
    prior = np.r_[np.ones(3), 0.5, 0.5]
    for m, conditioned in ((3 + MIN_DOF - 1, False), (3 + MIN_DOF, True)):
        J, _, free = _problem(rng, m=m, nf=3, nx=2)
        M = fixed_moment(J, free, prior, 1e-3 * rng.standard_normal(m))
        assert (M is not None) == conditioned, m
        if conditioned:
            assert np.trace(M) < 0.5 * 2 * 0.25  # a 1 mm residual scatter rules out most of the 0.5 prior


def _shrunk_runs(g: float, n: int, seed: int):
    """Linear calibrations (2 unpenalised registration-like parameters, 5 with prior σ 0.05, truth drawn from
    that prior, noise 0.1) shrunk at g× the prior's own scale: (true, stated, posterior-at-scale) mean-square
    point errors at 20 new configurations, per calibration."""
    rng = np.random.default_rng(seed)
    J, Jp, _ = _problem(rng, m=60, nf=2, nx=5)
    inv_prior = np.r_[0.0, 0.0, np.full(5, 1 / 0.05)]
    out = []
    for _ in range(n):
        d = np.r_[rng.standard_normal(2), 0.05 * rng.standard_normal(5)]
        y = J @ d + 0.1 * rng.standard_normal(60)
        lam_mu = g * 0.1 * inv_prior  # the penalty at the chosen scale
        A = J.T @ J + np.diag(lam_mu**2)
        x = np.linalg.solve(A, J.T @ y)
        r = J @ x - y  # residuals (model − measured), J their Jacobian
        dof = np.trace(np.linalg.solve(A, J.T @ J))
        sigma = np.sqrt(r @ r / (60 - dof))
        M = shrunk_moment(J, r, x, inv_prior, sigma)
        post = sigma**2 * np.linalg.inv(A)
        err = np.einsum("nip,p->ni", Jp, x - d)
        out.append([np.mean(np.sum(err**2, axis=1)), *(np.mean(np.einsum("nip,pq,niq->n", Jp, C, Jp)) for C in (M, post))])
    return np.array(out).T


def test_a_shrunk_estimate_states_its_true_error_at_any_scale():
    for g, understated in ((10.0, True), (0.3, False)):  # ten times the prior's scale (strong), a third of it
        true, stated, post = _shrunk_runs(g, 2000, 3)
        assert 0.93 < np.mean(true) / np.mean(stated) < 1.07, g
        if understated:  # the posterior at the chosen scale claims the robot is known ~10× better than the prior
            assert np.mean(true) / np.mean(post) > 2.0


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 10_000))
def test_at_the_priors_own_scale_the_moment_is_the_posterior(seed):
    rng = np.random.default_rng(seed)
    J, _, _ = _problem(rng, m=40, nf=2, nx=3)
    inv_prior = np.r_[0.0, 0.0, rng.uniform(1, 100, 3)]
    y, sigma = rng.standard_normal(40), float(rng.uniform(0.01, 1))
    A = J.T @ J + np.diag((sigma * inv_prior) ** 2)
    x = np.linalg.solve(A, J.T @ y)  # the MAP estimate under the stated prior: no step left
    M = shrunk_moment(J, J @ x - y, x, inv_prior, sigma, rounds=0)  # σ as given
    assert np.allclose(M, sigma**2 * np.linalg.inv(A), rtol=1e-8, atol=1e-14)
