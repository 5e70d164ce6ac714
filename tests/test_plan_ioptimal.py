"""I-optimal selection (pipeline.plan.ioptimal): the criterion and the swap formulas against
brute force on tiny cases; the exchange never worsens the criterion; greedy + exchange beats
random selections."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pipeline.plan import ioptimal


def tiny(seed: int, k: int, N: int = 12, P: int = 4, T: int = 7):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(N, k, P)) * rng.uniform(0.2, 2.0, P)
    G = rng.normal(size=(T, 3, P))
    info0 = np.diag(rng.uniform(0.05, 0.5, P))
    return A, G, info0


def brute(A, G, info0, idx):
    """mean over evaluation points of tr(G_t Σ G_tᵀ), Σ the posterior covariance: explicit loops."""
    M = info0.copy()
    for j in idx:
        M += A[j].T @ A[j]
    S = np.linalg.inv(M)
    return np.mean([np.trace(g @ S @ g.T) for g in G])


@pytest.mark.parametrize("k", [1, 2, 3])
def test_criterion_matches_brute_force_average_tool_point_variance(k):
    A, G, info0 = tiny(1, k)
    H = ioptimal.eval_matrix(G)
    for idx in ([0, 3, 5], [1, 2, 4, 7, 9], list(range(12))):
        assert ioptimal.criterion(A, np.array(idx), info0, H) == pytest.approx(brute(A, G, info0, idx), rel=1e-10)


@pytest.mark.parametrize("k", [1, 2])
def test_swap_deltas_match_brute_force_for_every_pair(k):
    A, G, info0 = tiny(2, k)
    H = ioptimal.eval_matrix(G)
    sel = np.array([0, 4, 6, 9])
    out = np.setdiff1d(np.arange(A.shape[0]), sel)
    M = info0 + np.einsum("nkp,nkq->pq", A[sel], A[sel])
    d = ioptimal._swap_deltas(A[sel], A[out], np.linalg.inv(M), H)
    base = brute(A, G, info0, sel)
    for a, b in itertools.product(range(sel.size), range(out.size)):
        swapped = sel.copy()
        swapped[a] = out[b]
        assert d[a, b] == pytest.approx(brute(A, G, info0, swapped) - base, rel=1e-8, abs=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_exchange_never_worsens_and_reaches_a_swap_optimum(seed):
    A, G, info0 = tiny(10 + seed, 1, N=30, P=5)
    H = ioptimal.eval_matrix(G)
    rng = np.random.default_rng(seed)
    start = rng.choice(30, 6, replace=False)
    sel, hist = ioptimal.exchange(A, start, info0, H)
    assert np.all(np.diff(hist) < 0)  # every accepted swap lowers I
    assert hist[-1] == pytest.approx(ioptimal.criterion(A, sel, info0, H), rel=1e-9)
    assert len(set(sel.tolist())) == 6
    best = ioptimal.criterion(A, sel, info0, H)  # no single swap improves it any more (brute force)
    for a, b in itertools.product(range(6), np.setdiff1d(np.arange(30), sel)):
        s2 = sel.copy()
        s2[a] = b
        assert ioptimal.criterion(A, s2, info0, H) >= best * (1 - 1e-6)


def test_selection_beats_random_and_matches_exhaustive_on_a_small_case():
    A, G, info0 = tiny(7, 1, N=14, P=4)
    H = ioptimal.eval_matrix(G)
    s = ioptimal.select(A, 5, info0, H)
    assert s.value <= s.greedy_value * (1 + 1e-12)
    every = [ioptimal.criterion(A, np.array(c), info0, H) for c in itertools.combinations(range(14), 5)]
    assert s.value <= np.quantile(every, 0.01)  # within the best 1 % of all 2002 subsets
    assert s.value <= min(every) * 1.05


def test_groups_are_covered_and_stay_covered():
    A, G, info0 = tiny(3, 1, N=40, P=5)
    groups = np.arange(40) % 5
    A[groups == 4] *= 0.01  # a group that I-optimality alone would skip
    s = ioptimal.select(A, 8, info0, ioptimal.eval_matrix(G), groups=groups)
    assert set(groups[s.index].tolist()) == set(range(5))


def test_one_row_swap_formula_equals_the_block_formula():
    A, G, info0 = tiny(4, 1, N=25, P=5)
    H = ioptimal.eval_matrix(G)
    sel, out = np.arange(6), np.arange(6, 25)
    M = info0 + np.einsum("nkp,nkq->pq", A[sel], A[sel])
    S = np.linalg.inv(M)
    fast = ioptimal._swap_deltas_rows(A[sel, 0], A[out, 0], S, H)
    A2 = np.concatenate([A, np.zeros_like(A)], axis=1)  # the same rows as 2-row blocks with a zero row: general path
    slow = ioptimal._swap_deltas(A2[sel], A2[out], S, H)
    np.testing.assert_allclose(fast, slow, rtol=1e-9, atol=1e-15)
