"""Cross-validation folds that respect the campaign's design (stratified, leverage-aware).

A seeded k-fold split of time blocks (`kfold_indices`) can, in a campaign with few
contacts on a face, put every contact of that face in one fold: the fit on the other folds then
cannot see that face, a parameter (or a combination of parameters) is unidentifiable there, and
the held-out error of that fold measures the design, not the model.  The same holds for a
placement, a payload, a session or a disjoint range of one joint's angle (a second station).

`design_folds` starts from that seeded split and repairs it only where it loses part of the
design, so a split that already keeps everything represented is returned unchanged:

1. strata (`design_strata`): each categorical column of the table that names a part of the design
   (`face`, `session`, `placement`, `payload_kg`) and, per joint, the disjoint ranges of its angle
   (sorted angles split where the gap exceeds a tenth of the joint's span and 0.05 rad); a stratum
   of ≥ 2 groups (time blocks, poses) whose members all fall in one fold has every other group moved to
   the other folds (round robin, seeded), so every training set holds part of every stratum (a stratum
   inside one group — one pose's corners — cannot be split without splitting the group, and is left);
2. leverage (with the linearised design J, rows measurement-major): a fold F whose removal leaves
   a direction of the parameters with less than `LEVERAGE_SHARE` of its information outside F
   (largest eigenvalue of H_FF = U_F U_Fᵀ above 1 − `LEVERAGE_SHARE`, U an orthonormal basis of J's
   columns) gives up the group of the measurement that carries most of that direction to the fold where
   it weighs least (unless that group alone carries it: no split of the groups can help).

Both repairs are bounded (a few passes); folds are returned as sorted measurement indices.  With
`design`, a measurement that alone carries a direction (its own leverage — the largest eigenvalue of its
rows' block of the hat matrix, h_ii for one row — above 1 − `LEVERAGE_SHARE`: no fit without it can predict it, its held-out error would be its residual over
1 − h_ii) is in no test fold: it stays in every training set and out of the held-out figure
(`unpredictable`).
"""

from __future__ import annotations

import numpy as np


STRATA_COLUMNS = ("face", "session", "placement", "payload_kg")
RANGE_GAP_SHARE = 0.1  # a gap in a joint's sorted angles above this share of its span (and GAP_MIN) splits ranges
RANGE_GAP_MIN_RAD = 0.05
LEVERAGE_SHARE = 0.01  # a fold must leave at least this share of every parameter direction's information
MAX_PASSES = 4


def kfold_indices(n: int, k: int, seed: int = 0, groups: np.ndarray | None = None) -> list[np.ndarray]:
    """Test-index sets of a seeded k-fold split; rows that share a group stay together."""
    rng = np.random.default_rng(seed)
    g = np.arange(n) if groups is None else np.asarray(groups)
    uniq = np.unique(g)
    perm = rng.permutation(uniq)
    fold_of_group = {u: i % k for i, u in enumerate(perm)}
    fold = np.array([fold_of_group[v] for v in g])
    return [np.flatnonzero(fold == i) for i in range(k)]


def design_strata(data: dict, n: int) -> list[np.ndarray]:
    """Label arrays (n,) of the parts of the design a fold must not take whole (module docstring)."""
    out = []
    for key in STRATA_COLUMNS:
        if key in data and np.ndim(data[key]) == 1 and len(data[key]) == n:
            lab = np.asarray(data[key]).astype(str)
            if np.unique(lab).size > 1:
                out.append(lab)
    q = data.get("joint_positions") if hasattr(data, "get") else None
    if q is not None and np.ndim(q) == 2 and len(q) == n:
        for col in np.asarray(q, float).T:
            lab = joint_ranges(col)
            if lab.max() > 0:
                out.append(lab.astype(str))
    return out


def joint_ranges(q: np.ndarray) -> np.ndarray:
    """Disjoint range index (n,) of one joint's angles (rad): split where a gap between sorted angles
    exceeds max(RANGE_GAP_SHARE · span, RANGE_GAP_MIN_RAD)."""
    q = np.asarray(q, float)
    if q.size < 2 or not np.all(np.isfinite(q)):
        return np.zeros(q.size, int)
    order = np.argsort(q, kind="stable")
    s = q[order]
    gap = max(RANGE_GAP_SHARE * (s[-1] - s[0]), RANGE_GAP_MIN_RAD)
    lab = np.empty(q.size, int)
    lab[order] = np.r_[0, np.cumsum(np.diff(s) > gap)]
    return lab


def design_folds(n: int, k: int, seed: int = 0, groups: np.ndarray | None = None, data: dict | None = None,
                 design: np.ndarray | None = None, rows_per: int = 1) -> list[np.ndarray]:
    """Test-measurement index sets (module docstring): `kfold_indices` repaired so every training set
    keeps every stratum of `data` and, with `design` (n·rows_per, p), every parameter direction."""
    base = kfold_indices(n, k, seed, groups)
    if k < 2 or n < k:
        return base
    fold = np.empty(n, int)
    for i, f in enumerate(base):
        fold[f] = i
    rng = np.random.default_rng(seed + 7919)
    strata = design_strata(data, n) if data is not None else []
    g = np.arange(n) if groups is None else np.unique(np.asarray(groups), return_inverse=True)[1].ravel()
    for _ in range(MAX_PASSES):
        moved = _spread_strata(fold, strata, g, k, rng)
        if design is not None:
            moved |= _spread_leverage(fold, np.asarray(design, float), g, k, rows_per)
        if not moved:
            break
    if design is not None:
        fold[unpredictable(np.asarray(design, float), n, rows_per)] = -1
    return [np.flatnonzero(fold == i) for i in range(k)]


def unpredictable(J: np.ndarray, n: int, rows_per: int = 1) -> np.ndarray:
    """Measurements (indices) whose own leverage in design J (n·rows_per, p) exceeds 1 − LEVERAGE_SHARE
    (largest eigenvalue of its rows' block H_mm of the hat matrix)."""
    return np.flatnonzero(_own_leverage(_basis(J).reshape(n, rows_per, -1)) > 1 - LEVERAGE_SHARE)


def _own_leverage(Um: np.ndarray) -> np.ndarray:
    """Largest eigenvalue (n,) of each measurement's hat block U_m U_mᵀ (Um: (n, rows_per, r))."""
    if not Um.shape[2]:
        return np.zeros(Um.shape[0])
    return np.linalg.eigvalsh(Um @ np.swapaxes(Um, 1, 2))[:, -1]


def _basis(J: np.ndarray) -> np.ndarray:
    U, s, _ = np.linalg.svd(J, full_matrices=False)
    return U[:, s > s[0] * 1e-10] if s.size and s[0] > 0 else np.zeros((J.shape[0], 0))


def expand(folds: list[np.ndarray], rows_per: int) -> list[np.ndarray]:
    """Measurement folds → flattened residual-row folds (measurement-major, `rows_per` rows each)."""
    return [(np.asarray(f, int)[:, None] * rows_per + np.arange(rows_per)[None, :]).ravel() for f in folds]


def _spread_strata(fold: np.ndarray, strata: list[np.ndarray], g: np.ndarray, k: int, rng) -> bool:
    """Move every other group of a stratum held whole by one fold to the other folds (whole groups: a
    stratum inside one group — one pose's corners — cannot be split and is left as it is)."""
    moved = False
    for lab in strata:
        for u in np.unique(lab):
            members = np.flatnonzero(lab == u)
            own = np.unique(g[members])
            if own.size < 2 or np.unique(fold[members]).size > 1:
                continue
            others = np.array([f for f in range(k) if f != fold[members[0]]])
            go = own[1::2]
            dest = others[(rng.integers(others.size) + np.arange(go.size)) % others.size]
            for grp, f in zip(go, dest):
                fold[g == grp] = f
            moved = True
    return moved


def _spread_leverage(fold: np.ndarray, J: np.ndarray, g: np.ndarray, k: int, rows_per: int) -> bool:
    """Move, per offending fold, the group of the measurement carrying most of the direction it takes whole
    (unless that group alone carries it)."""
    U = _basis(J)
    if not U.shape[1]:
        return False
    Um = U.reshape(fold.size, rows_per, -1)
    moved = False
    for f in range(k):
        rows = np.flatnonzero(fold == f)
        if rows.size < 2:
            continue
        UF = Um[rows].reshape(-1, U.shape[1])
        w, V = np.linalg.eigh(UF.T @ UF)
        if w[-1] <= 1 - LEVERAGE_SHARE:
            continue
        carry = np.sum((Um[rows] @ V[:, -1]) ** 2, axis=1)
        grp = g == g[rows[int(np.argmax(carry))]]
        Ug = Um[grp].reshape(-1, U.shape[1])
        if np.linalg.eigvalsh(Ug.T @ Ug)[-1] > 1 - LEVERAGE_SHARE:  # that group alone carries it: no split helps
            continue
        weigh = [np.inf if h == f else float(np.sum((Um[fold == h] @ V[:, -1]) ** 2)) for h in range(k)]
        fold[grp] = int(np.argmin(weigh))
        moved = True
    return moved
