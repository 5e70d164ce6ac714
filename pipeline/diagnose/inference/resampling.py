"""Resampling of a diagnosis: grouped cross-validation on time blocks (`time_blocks`, `holdout`, `rms`)
and the bootstrap selection frequency (`bootstrap_frequency`).  Both use the model linearised at the
full-data solution, exact to first order and a few small least squares each; residuals in m,
flattened measurement-major."""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.inference.projection import orthonormal, project_out
from pipeline.diagnose.inference.candidate_gram import Design
from pipeline.diagnose.inference.stepwise import forward_select, select_design
from pipeline.identify.least_squares import kfold_indices
from pipeline.progress import step


HOLDOUT_OVER_SIGMA_MAX = 3.0  # a held-out RMS above this many in-sample σ: the campaign cannot predict itself


def design_folds(n: int, k: int, s, time_s: np.ndarray, table: dict,
                 Jf: np.ndarray) -> tuple[list[np.ndarray], int, list[int]]:
    """(folds of the flattened residual rows, measurements moved, measurements in no fold): time blocks
    of `s.block` in `s.folds` seeded folds, repaired so every training set keeps every face, placement,
    joint range and parameter direction of the linearised geometry `Jf`; a measurement that alone
    carries a direction is in no test fold (`identify.folds.design_folds`; its held-out error is NaN)."""
    from pipeline.identify.folds import design_folds as repaired, expand

    blocks = time_blocks(time_s, s.block)
    base = kfold_indices(n, s.folds, s.seed, blocks)
    folds = repaired(n, s.folds, s.seed, blocks, table, Jf, k)
    alone = np.setdiff1d(np.arange(n), np.concatenate(folds))
    moved = int(sum(np.setdiff1d(f, b).size for f, b in zip(folds, base)))
    return expand(folds, k), moved, [int(i) for i in alone]


EXTRAPOLATED = 0.95  # own leverage above this in the selected model: a held-out prediction there is an extrapolation


def without_extrapolated(folds: list[np.ndarray], A: np.ndarray, n: int, k: int,
                         limit: float = EXTRAPOLATED) -> tuple[list[np.ndarray], list[int]]:
    """(folds, measurements taken out of them): a measurement whose own leverage in design A (the geometry and the
    selected effects, rows measurement-major) exceeds `limit` carries a direction of that model nearly alone — held
    out, its error is its residual over 1 − h (×20 and more), a figure of the design's extrapolation, not a test of
    the model — so it stays in every training set and out of the held-out figures (as `design_folds` does above
    0.99 for the geometry alone)."""
    from pipeline.diagnose.inference.projection import orthonormal

    U = orthonormal(A).reshape(n, k, -1)
    lev = np.linalg.norm(U, ord=2, axis=(1, 2)) ** 2 if k > 1 else np.sum(U[:, 0, :] ** 2, axis=1)
    out = np.flatnonzero(lev > limit)
    if not out.size:
        return folds, []
    rows = (out[:, None] * k + np.arange(k)).ravel()
    return [np.setdiff1d(f, rows) for f in folds], [int(i) for i in out]


def holdout_over_insample(before_cv: np.ndarray, after_cv: np.ndarray, sigma: float, sigma_after: float) -> dict:
    """The held-out RMS over the in-sample σ, geometry alone and final model; `flagged` above
    `HOLDOUT_OVER_SIGMA_MAX` (a good design predicts its left-out measurements within ≈ 1.1–1.5 σ)."""
    before = rms(before_cv) / sigma if sigma > 0 else float("nan")
    after = rms(after_cv) / sigma_after if sigma_after > 0 else float("nan")
    worst = max(v for v in (before, after, 0.0) if np.isfinite(v))
    return {"geometry": float(before), "final": float(after), "limit": HOLDOUT_OVER_SIGMA_MAX,
            "flagged": bool(worst > HOLDOUT_OVER_SIGMA_MAX)}


def time_blocks(t: np.ndarray, size: int = 5) -> np.ndarray:
    """Group label of each measurement: consecutive blocks of about `size` in time order that never split
    the measurements of one instant (a camera image's corners, a scanner pose's stripe points): each run of
    equal times is labelled by the count of measurements before it // `size` (for distinct times: blocks
    of exactly `size`)."""
    t = np.asarray(t)
    order = np.argsort(t, kind="stable")
    ts = t[order]
    start = np.r_[True, ts[1:] != ts[:-1]] if ts.size else np.zeros(0, bool)
    first = np.maximum.accumulate(np.where(start, np.arange(ts.size), 0))  # the index where each row's run starts
    g = np.empty(order.size, int)
    g[order] = first // size
    return g


PUSH_THROUGH_MIN = 1e-8  # a fold whose rows carry a direction of A this nearly alone is refitted as such


def holdout(A: np.ndarray, r: np.ndarray, folds: list[np.ndarray], basis: np.ndarray | None = None) -> np.ndarray:
    """Held-out residuals (n,) of the linearised model r + A·δ: each fold predicted from the others
    (rows in no fold: NaN).  One orthonormal basis U of A's (unit-scaled) columns serves every fold: the fit
    without the rows T predicts them with e_T + U_T(I − U_TᵀU_T)⁻¹U_Tᵀe_T, e = (I − UUᵀ)r (the push-through
    identity, `identify.linear_folds`) — a rank × rank solve per fold; a fold whose rows alone carry a direction
    (I − U_TᵀU_T nearly singular) is refitted on its training rows (least squares, minimum norm).  `basis`: U
    when known (`linear_folds.scaled_basis` of A's columns, e.g. extended from a basis of some of them)."""
    from pipeline.identify.linear_folds import scaled_basis

    out = np.full(r.size, np.nan)
    norms = np.linalg.norm(A, axis=0)
    norms[norms == 0] = 1
    As = A / norms
    U = scaled_basis(As) if basis is None else basis
    e = r + U @ (U.T @ -r)
    eye = np.eye(U.shape[1])
    for test in folds:
        Ut = U[test]
        M = eye - Ut.T @ Ut
        if U.shape[1] and np.linalg.eigvalsh(M)[0] > PUSH_THROUGH_MIN:
            out[test] = e[test] + Ut @ np.linalg.solve(M, Ut.T @ e[test])
            continue
        train = np.setdiff1d(np.arange(r.size), test)
        d, *_ = np.linalg.lstsq(As[train], -r[train], rcond=1e-10)
        out[test] = r[test] + As[test] @ d
    return out


def rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(np.asarray(v) ** 2)))


GRAM_BYTES = 2**27  # the bootstrap's per-group Gram matrices are kept when they fit in this (bytes)
GRAM_REL = 1e-10  # a geometry direction whose resampled weight is below this share of the largest is dropped


def bootstrap_frequency(J: np.ndarray, r: np.ndarray, S: list[np.ndarray], tolerances: list[float],
                        groups: np.ndarray, alpha: float, n_boot: int = 40, seed: int = 0) -> np.ndarray:
    """How often each candidate is selected when the campaign's groups are resampled (n_cand,):
    per resample the same stepwise selection as the diagnosis (`stepwise.forward_select`: greedy
    pass, backward elimination, pair additions) on the resampled, re-projected problem.

    A resample repeats whole groups, so its normal equations are the groups' own summed with their
    multiplicities: with Z = [Q, S, r] (Q an orthonormal basis of the geometry J's columns on every row),
    the Gram matrix ZᵀZ of each group is formed once, and a resample's is their weighted sum; the geometry is
    partialled out by its Schur complement and the selection runs on the candidates' Gram algebra
    (`candidate_gram.Design.of_gram`) — the same tests as on the resampled rows re-projected, at K×K cost per
    resample instead of a QR and a projection of every row.  Where the groups' matrices would not fit in
    `GRAM_BYTES`, each resample's rows are re-projected as such."""
    rng = np.random.default_rng(seed)
    uniq = np.unique(groups)
    members = [np.flatnonzero(groups == u) for u in uniq]
    count = np.zeros(len(S))
    Q = orthonormal(J)
    p_geo = Q.shape[1]
    widths = [s.shape[1] for s in S]
    width = p_geo + sum(widths) + 1
    grams = None
    if S and uniq.size * width**2 * 8 <= GRAM_BYTES:
        grams = np.empty((uniq.size, width, width))
        for u, rows in enumerate(members):
            Z = np.hstack([Q[rows]] + [s[rows] for s in S] + [r[rows, None]])
            grams[u] = Z.T @ Z
        sizes = np.array([m.size for m in members])
    for b in range(n_boot):
        step(f"bootstrap: resample {b + 1} of {n_boot}")
        pick = rng.integers(0, uniq.size, uniq.size)
        if grams is not None:
            w = np.bincount(pick, minlength=uniq.size).astype(float)
            G, g, rr = _partial_geometry(np.tensordot(w, grams, axes=1), p_geo)
            D = Design.of_gram(G, g, rr, widths, tolerances)
            steps = select_design(D, int(w @ sizes) - p_geo, alpha)
        else:
            idx = np.concatenate([members[i] for i in pick])
            Qb = orthonormal(J[idx])
            rb = project_out(r[idx][:, None], Qb)[:, 0]
            steps = forward_select(rb, [project_out(s[idx], Qb) for s in S], idx.size - p_geo, alpha, tolerances)
        for st in steps:
            count[st.index] += 1
    return count / max(n_boot, 1)


def _partial_geometry(M: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(G, g, rr) of the candidates and residual with the first p columns (the geometry) partialled out of the
    Gram matrix M of [geometry, candidates, r]: the Schur complement, the geometry's directions that the rows
    hardly carry (weight below `GRAM_REL` of the largest) left out as a rank-revealing QR of them would."""
    w, V = np.linalg.eigh(M[:p, :p])
    keep = w > GRAM_REL * max(w[-1], 1e-300) if p else np.zeros(0, bool)
    L = (V[:, keep] / np.sqrt(w[keep])).T @ M[:p, p:]
    R = M[p:, p:] - L.T @ L
    return R[:-1, :-1], R[:-1, -1], float(R[-1, -1])
