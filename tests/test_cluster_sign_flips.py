"""The cluster-robust check of the findings (`select.cluster_sign_flip_p`): its G-dimensional
algebra against explicit refits, its size when the error within a cluster has a shape the
F test's working model does not assume, and its power."""

from __future__ import annotations

import numpy as np
import scipy.stats
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.diagnose.inference.sign_flips import cluster_sign_flip_p
from pipeline.diagnose.inference.projection import orthonormal, project_out

G, M = 20, 12  # clusters, rows per cluster


def problem(rng, p_base=4):
    """Rows of G clusters; a base design, a cluster-level block (constant within each cluster's
    own direction) and a within-cluster block; errors with a random low-rank shape per cluster
    (each cluster's own covariance) plus white noise."""
    cluster = np.repeat(np.arange(G), M)
    base = rng.normal(size=(G * M, p_base))
    level = np.repeat(rng.normal(size=(G, 1)), M, axis=0) * rng.normal(1.0, 0.1, size=(G * M, 1))
    within = rng.normal(size=(G * M, 2))
    return cluster, base, level, within


def cluster_error(rng, cluster, scale=4.0):
    """Each cluster's error: a random shift of all its rows (a cluster random effect) whose size
    differs from cluster to cluster, a random direction in its rows (rank 2, anisotropic), and
    unit noise."""
    e = rng.normal(size=cluster.size)
    for g in np.unique(cluster):
        rows = cluster == g
        U = rng.normal(size=(rows.sum(), 2)) * np.array([scale, scale / 3])
        e[rows] += U @ rng.normal(size=2) + 3 * scale * rng.uniform(0.2, 1.0) * rng.normal()
    return e


def brute_force_p(r, blocks, base, cluster, n_draw, seed):
    """The same bootstrap by explicit refits of every draw (slow, obvious)."""
    ids, inv = np.unique(cluster, return_inverse=True)
    signs = np.random.default_rng(seed).choice([-1.0, 1.0], size=(ids.size, n_draw))
    out = []
    for b in range(len(blocks)):
        X0 = np.hstack([base] + [blocks[c] for c in range(len(blocks)) if c != b])
        X1 = np.hstack([X0, blocks[b]])

        def stat(y):
            e0 = y - X0 @ np.linalg.lstsq(X0, y, rcond=None)[0]
            e1 = y - X1 @ np.linalg.lstsq(X1, y, rcond=None)[0]
            return (e0 @ e0 - e1 @ e1) / (e1 @ e1)
        r0 = r - X0 @ np.linalg.lstsq(X0, r, rcond=None)[0]
        t_obs = stat(r)
        t = np.array([stat(r0 * signs[inv, d]) for d in range(n_draw)])
        out.append((1 + np.count_nonzero(t >= t_obs * (1 - 1e-12))) / (n_draw + 1))
    return np.array(out)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(0.0, 0.5))
def test_the_g_dimensional_algebra_equals_explicit_refits(seed, size):
    rng = np.random.default_rng(seed)
    cluster, base, level, within = problem(rng)
    r = cluster_error(rng, cluster) + size * 3 * level[:, 0] + base @ rng.normal(size=base.shape[1])
    fast = cluster_sign_flip_p(r, [level, within], base, cluster, n_draw=199, seed=seed)
    slow = brute_force_p(r, [level, within], base, cluster, 199, seed)
    np.testing.assert_allclose(fast, slow, atol=1.5 / 200)  # a tie at the threshold may count either way


def test_size_holds_where_the_iid_f_test_over_rejects():
    """Null data whose clusters each carry their own anisotropic error: the F test of the
    cluster-level block under i.i.d. errors rejects far too often; the sign flips keep α."""
    n_rep, alpha = 200, 0.05
    rej_flip = rej_f = 0
    for seed in range(n_rep):
        rng = np.random.default_rng(1000 + seed)
        cluster, base, level, within = problem(rng)
        r = cluster_error(rng, cluster)
        rej_flip += cluster_sign_flip_p(r, [level], base, cluster, n_draw=499, seed=seed)[0] <= alpha
        Q0 = orthonormal(base)
        r0 = project_out(r[:, None], Q0)[:, 0]
        q = orthonormal(project_out(level, Q0))
        gain = float((q.T @ r0) @ (q.T @ r0))
        dof = r.size - base.shape[1] - 1
        rej_f += scipy.stats.f.sf(gain / ((r0 @ r0 - gain) / dof), 1, dof) <= alpha
    assert rej_f / n_rep > 0.25  # the working model is wrong: the F test is not to be trusted here
    assert 0.02 <= rej_flip / n_rep <= 0.10  # 200 runs: 0.05 ± 3 sd (0.015)


def test_a_real_block_reaches_the_floor_and_the_others_do_not():
    rng = np.random.default_rng(7)
    cluster, base, level, within = problem(rng)
    r = cluster_error(rng, cluster, scale=1.0) + 2.0 * level[:, 0]
    p = cluster_sign_flip_p(r, [level, within], base, cluster, n_draw=999, seed=0)
    assert p[0] == 1 / 1000
    assert p[1] > 0.01
