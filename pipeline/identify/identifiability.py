"""Which parameters a campaign can identify: pivoted QR of the column-scaled Jacobian.

The columns of the identification Jacobian are scaled to unit norm (Hollerbach & Wampler),
so the test does not depend on units.  Pivoted QR orders the columns by how much new
information each adds; a column whose remaining norm |R_kk| falls below
``RANK_TOL`` is a (numerically) linear combination of the columns before it and is
fixed at its nominal value.  Seed 000 does the same by dropping small pivots (its eq. 57).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

RANK_TOL = 1e-3  # smallest remaining norm of a kept unit-norm column (noise gain ≤ 1000×)
ZERO_TOL = 1e-12  # a column this small (relative to the largest) has no effect at all


@dataclass(frozen=True)
class Identifiability:
    """Outcome of the rank test: free/fixed parameters and why each fixed one is fixed."""

    free: np.ndarray  # bool mask over parameters
    reasons: dict[int, str]  # parameter index -> reason it is fixed
    pivots: np.ndarray  # |R_kk| / |R_00| in pivot order
    order: np.ndarray  # pivot order (parameter indices)


def triangular_factor(J: np.ndarray, block: int = 8192) -> np.ndarray:
    """R (p, p) of J = Q·R for a tall J (m, p), by blocks of rows (tall-skinny QR: the R of
    each block, stacked, factored again — the same R up to row signs).  A single Householder
    QR of a J larger than the cache rereads all of it per column; by blocks the cost stays
    linear in m."""
    m, p = J.shape
    if m <= 2 * block:
        return scipy.linalg.qr(J, mode="r")[0][:p]
    Rs = [scipy.linalg.qr(J[i:i + block], mode="r")[0][:p] for i in range(0, m, block)]
    return scipy.linalg.qr(np.vstack(Rs), mode="r")[0][:p]


def analyse(J: np.ndarray, names: list[str], fixed: np.ndarray | None = None,
            priority: np.ndarray | None = None, tol: float = RANK_TOL) -> Identifiability:
    """Rank-revealing analysis of J (m, p).

    `fixed` marks parameters fixed by the user.  `priority` (int, lower first) decides
    which member of a dependent group is kept: columns are pivoted level by level, each
    level against what the earlier levels already span (e.g. D-H terms before Hayati's β).
    Columns are unit-norm, so `tol` is the smallest remaining norm a kept column may have.
    """
    m, p = J.shape
    if m > p:
        # J = Q·R: R has J's column norms and linear dependencies, at p×p instead of m×p
        J = triangular_factor(J)
        m = p
    fixed = np.zeros(p, bool) if fixed is None else np.asarray(fixed, bool)
    priority = np.zeros(p, int) if priority is None else np.asarray(priority, int)
    norms = np.linalg.norm(J, axis=0)
    biggest = norms.max() if p else 1.0
    reasons: dict[int, str] = {int(i): "fixed by the user" for i in np.flatnonzero(fixed)}
    zero = (norms <= ZERO_TOL * biggest) & ~fixed
    for i in np.flatnonzero(zero):
        reasons[int(i)] = "no effect on any measurement (zero Jacobian column)"
    safe = np.where(norms > 0, norms, 1.0)
    Js = J / safe
    basis = np.zeros((m, 0))
    free = np.zeros(p, bool)
    order: list[int] = []
    pivots: list[float] = []
    dropped: list[int] = []
    for level in np.unique(priority):
        cand = np.flatnonzero((priority == level) & ~fixed & ~zero)
        if cand.size == 0:
            continue
        rest = Js[:, cand] - basis @ (basis.T @ Js[:, cand])
        Q, R, piv = scipy.linalg.qr(rest, mode="economic", pivoting=True)
        diag = np.abs(np.diag(R))
        k = int(np.sum(diag > tol)) if diag.size else 0
        # pivoted QR has non-increasing |R_kk|: the first k columns are the kept ones
        kept = cand[piv[:k]]
        free[kept] = True
        basis = np.hstack([basis, Q[:, :k]])
        order += [int(i) for i in cand[piv]]
        pivots += [float(d) for d in diag] + [0.0] * (cand.size - diag.size)
        dropped += [int(i) for i in cand[piv[k:]]]
    for i, text in zip(dropped, combinations(J, names, dropped, free)):
        reasons[i] = "dependent: " + text
    return Identifiability(free=free, reasons=reasons, pivots=np.array(pivots), order=np.array(order, int))


def combinations(J: np.ndarray, names: list[str], dropped: list[int], free: np.ndarray, top: int = 3) -> list[str]:
    """`combination` of every dropped column, from one least-squares solve with many right-hand sides."""
    if not dropped:
        return []
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    F = np.flatnonzero(free)
    coefs, *_ = np.linalg.lstsq(J[:, F] / norms[F], J[:, dropped] / norms[dropped], rcond=None)
    out = []
    for k, i in enumerate(dropped):
        coef = coefs[:, k]
        best = np.argsort(-np.abs(coef))[:top]
        terms = " ".join(f"{coef[b]:+.2f}·{names[F[b]]}" for b in best if abs(coef[b]) > 1e-3)
        out.append(f"{names[i]} ≈ {terms or '0'}")
    return out


def combination(J: np.ndarray, names: list[str], i: int, free: np.ndarray, top: int = 3) -> str:
    """Express column i as a combination of the free columns (unit-norm scaled), naming the
    largest contributors, e.g. ``J1.theta_offset ≈ +1.00·base.rz``."""
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    F = np.flatnonzero(free)
    coef, *_ = np.linalg.lstsq(J[:, F] / norms[F], J[:, i] / norms[i], rcond=None)
    best = np.argsort(-np.abs(coef))[:top]
    terms = " ".join(f"{coef[b]:+.2f}·{names[F[b]]}" for b in best if abs(coef[b]) > 1e-3)
    return f"{names[i]} ≈ {terms or '0'}"
