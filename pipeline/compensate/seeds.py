"""Starts for the nominal controller's inverse kinematics of a large program: a k-d tree
(`scipy.spatial.cKDTree`) of nominal IK solutions, so the vectorised Newton/LM of every other
target starts next to its answer, on the same branch.

Anchors: every `stride`-th target without a hint is solved by the controller's rule
(`ik.multistart`: the seeds in turn, the first converged within limits).  Every other
target starts from the solution of its nearest anchor in pose space (position, and the
rotation matrix scaled by `LEVER_M/√2`, so that a distance reads as lever-weighted pose error);
its solution (at most `near_iters` Newton/LM steps) is accepted when it converged within limits and stayed on the anchor's branch
(no joint moved more than `branch_step_rad` from the start, and for a 6 × 6 Jacobian the same
sign of det J); else the next nearest anchor is tried (`neighbours` in all).  The rest (few, mostly
unreachable or singular targets) fall back to the multistart rule, so the result is the rule's
answer wherever a neighbour's branch does not reach.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from pipeline.compensate import ik as S


def features(p: np.ndarray, R: np.ndarray | None) -> np.ndarray:
    """Pose features (N, 3 or 12), m: position and lever-scaled rotation matrix."""
    if R is None:
        return np.asarray(p, float)
    return np.concatenate([p, (S.LEVER_M / np.sqrt(2)) * R.reshape(-1, 9)], axis=1)


def _wrap(q: np.ndarray) -> np.ndarray:
    return (q + np.pi) % (2 * np.pi) - np.pi


def nominal_ik(kin: S.Kinematics, x: np.ndarray, p_t: np.ndarray, R_t: np.ndarray | None, seeds: np.ndarray,
               options: S.IKOptions = S.IKOptions(), hint: np.ndarray | None = None, stride: int = 32,
               min_rows: int = 256, branch_step_rad: float = 1.5,
               neighbours: int = 2, near_iters: int = 15) -> tuple[np.ndarray, np.ndarray]:
    """The nominal controller's solutions (q (N, n), ok (N,)): rows with a finite hint from it
    (as `multistart`), the others by nearest-anchor starts (module docstring)."""
    n = p_t.shape[0]
    hinted = np.zeros(n, bool) if hint is None else np.all(np.isfinite(hint), axis=1)
    free = np.flatnonzero(~hinted)
    if free.size < min_rows:
        return S.multistart(kin, x, p_t, R_t, seeds, options, hint)
    q = np.full((n, kin.n_joints), np.nan)
    ok = np.zeros(n, bool)

    def rows(idx):
        return p_t[idx], None if R_t is None else R_t[idx]

    if hinted.any():
        h = np.flatnonzero(hinted)
        q[h], ok[h] = S.multistart(kin, x, *rows(h), seeds, options, hint[h])
    anchors = free[::stride]
    q[anchors], ok[anchors] = S.multistart(kin, x, *rows(anchors), seeds, options)
    solved = anchors[ok[anchors]]
    rest = np.setdiff1d(free, anchors)
    if solved.size == 0:
        q[rest], ok[rest] = S.multistart(kin, x, *rows(rest), seeds, options)
        return q, ok
    near_options = replace(options, iters=min(options.iters, near_iters))  # a near start converges in a few
    tree = cKDTree(features(*rows(solved)))
    near = tree.query(features(*rows(rest)), k=min(neighbours, solved.size))[1].reshape(rest.size, -1)
    back = rest
    for k in range(near.shape[1]):  # the nearest anchor's solution, then the next nearest for rows that failed
        q0 = q[solved[near[rest.searchsorted(back), k]]]
        qs, err = S.solve(kin, x, *rows(back), q0, near_options)
        qs = _wrap(qs)
        good = ((err <= 1e-9) & np.all((qs >= kin.lower) & (qs <= kin.upper), axis=1)
                & (np.abs(_wrap(qs - q0)).max(axis=1) <= branch_step_rad))
        if R_t is not None and kin.n_joints == 6 and good.any():
            g = np.flatnonzero(good)
            J = kin.pose_jacobian(x, np.concatenate([qs[g], q0[g]]))[2]
            d = np.sign(np.linalg.det(J))
            good[g] &= d[: g.size] == d[g.size:]
        q[back[good]], ok[back[good]] = qs[good], True
        back = back[~good]
        if back.size == 0:
            break
    if back.size:
        q[back], ok[back] = S.multistart(kin, x, *rows(back), seeds, options)
    return q, ok
