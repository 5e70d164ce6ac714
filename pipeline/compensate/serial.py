"""Compensation of a program of Cartesian targets on a serial chain, with the inverse kinematics of
`pipeline.compensate.ik` (its names are re-exported here).  All poses in the work frame {W} (the jig
frame for the arc welder), m and rad.

Compensation of target (p_t, R_t):
1. the controller's solution: nominal-model IK (from the row's hint, else multi-start seeds,
   first converging within limits — the branch a nominal controller would take; for large
   programs only on anchors, the other targets started at their nearest anchor's solution:
   `pipeline.compensate.seeds`);
2. calibrated-model IK started there (same branch; a jump > `branch_jump_rad` is reported);
3. corrected target (R_c, p_c) = nominal forward kinematics of the calibrated joints: a
   nominal controller's IK of it returns the calibrated joints.
A target the same-branch solve misses (no convergence, or outside the limits) is solved again from
the multistart seeds and EXTRA_SEEDS more spread within the limits (`spread_seeds`); reached within
the limits there it is a branch_change, not unreachable.  A target without a nominal solution gets
the same spread of starts.
Each row gets a status: ok, unreachable (no convergence from any start), singular (smallest singular value of
the lever-scaled 6×n Jacobian, at the nominal or the calibrated solution, below `singular_threshold_m`,
5 mm per rad: 0.1 mm of tool motion costs 20 mrad of joint motion), out_of_limits, branch_change (the
sign of det J differs between the nominal and the calibrated solution: a singularity lies between
them, so the calibrated joints are on another branch) — never clipped silently.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.compensate.ik import (LEVER_M, ChainKinematics, IKOptions, Kinematics, SerialArmKinematics,
                                    sigma_min_of_jacobian, multistart, pose_error, sigma_min, solve)
from pipeline.compensate.seeds import nominal_ik

__all__ = ["LEVER_M", "STATUS", "ChainKinematics", "Compensated", "IKOptions", "Kinematics",
           "SerialArmKinematics", "compensate", "multistart", "pose_error", "sigma_min", "solve"]


STATUS = ("ok", "unreachable", "out_of_limits", "singular", "branch_change")
EXTRA_SEEDS = 64  # starts spread within the limits, tried on a target no given seed reaches


def spread_seeds(kin: Kinematics, seeds: np.ndarray, n: int = EXTRA_SEEDS) -> np.ndarray:
    """The given seeds, then n configurations drawn within the joint limits (±π where none; fixed
    generator): a target the controller's few seeds miss is not called unreachable before these."""
    lo = np.where(np.isfinite(kin.lower), kin.lower, -np.pi)
    hi = np.where(np.isfinite(kin.upper), kin.upper, np.pi)
    more = np.random.default_rng(0).uniform(lo, hi, (n, kin.n_joints))
    return np.vstack([np.asarray(seeds, float).reshape(-1, kin.n_joints), more])


@dataclass
class Compensated:
    """A compensated program (arrays over targets; SI, work frame)."""

    q_nominal: np.ndarray  # (N, n) the nominal controller's solution (NaN where none)
    q: np.ndarray  # (N, n) calibrated-model IK: the joints that reach the target
    status: np.ndarray  # (N,) str, one of STATUS
    p_corrected: np.ndarray  # (N, 3) target to send to a nominal controller, m
    R_corrected: np.ndarray  # (N, 3, 3)
    error_m: np.ndarray  # (N,) calibrated-model pose error left at q (lever-weighted), m
    sigma_min_m: np.ndarray  # (N,) smallest singular value of the lever-scaled Jacobian
    correction_m: np.ndarray  # (N,) |p_corrected − p_t|, m


def compensate(kin: Kinematics, x_nominal: np.ndarray, x_calibrated: np.ndarray, p_t: np.ndarray,
               R_t: np.ndarray | None, seeds: np.ndarray, hint: np.ndarray | None = None,
               options: IKOptions = IKOptions()) -> Compensated:
    """Compensate targets (p_t (N,3), R_t (N,3,3) or None) — see the module docstring."""
    p_t = np.atleast_2d(np.asarray(p_t, float))
    n = p_t.shape[0]

    q_nom, ok_nom = nominal_ik(kin, x_nominal, p_t, R_t, seeds, options, hint)
    q = np.full_like(q_nom, np.nan)
    status = np.full(n, "ok", dtype=object)
    rows = np.flatnonzero(ok_nom)  # calibrated IK from the nominal solution: the same branch
    q[rows], e = solve(kin, x_calibrated, p_t[rows], None if R_t is None else R_t[rows], q_nom[rows], options)
    within = np.all((q[rows] >= kin.lower) & (q[rows] <= kin.upper), axis=1)
    status[rows[e > 1e-9]] = "unreachable"
    status[rows[(e <= 1e-9) & ~within]] = "out_of_limits"
    lost = rows[(e > 1e-9) | ~within]  # the same-branch start missed: a solution within limits may still exist
    if lost.size:
        ql, okl = multistart(kin, x_calibrated, p_t[lost], None if R_t is None else R_t[lost],
                             spread_seeds(kin, seeds), options)
        found = lost[okl]
        q[found], status[found] = ql[okl], "branch_change"  # reached, from another start: not the nominal branch
    rest = np.flatnonzero(~ok_nom)  # no nominal solution within limits: any calibrated one, else why not
    if rest.size:
        qr, okr = multistart(kin, x_calibrated, p_t[rest], None if R_t is None else R_t[rest],
                             spread_seeds(kin, seeds), options)
        q[rest] = qr
        bad = rest[~okr]
        if bad.size:
            qb, eb = solve(kin, x_calibrated, p_t[bad], None if R_t is None else R_t[bad],
                           np.broadcast_to(seeds[0], (bad.size, kin.n_joints)), options)
            q[bad] = qb
            status[bad] = np.where(eb <= 1e-9, "out_of_limits", "unreachable")
    R_c, p_c, J_c = kin.pose_jacobian(x_calibrated, np.nan_to_num(q))  # one walk for error, σ_min, det
    err = np.linalg.norm(pose_error(R_c, p_c, R_t, p_t), axis=1)
    smin = sigma_min_of_jacobian(J_c, R_t is not None)
    J_n = kin.pose_jacobian(x_nominal, np.nan_to_num(q_nom))[2]
    smin = np.minimum(smin, np.where(ok_nom, sigma_min_of_jacobian(J_n, R_t is not None), np.inf))  # near-singular in either model
    if R_t is not None and kin.n_joints == 6:
        det_n = np.linalg.det(J_n)
        det_c = np.linalg.det(J_c)
        status[(status == "ok") & ok_nom & (np.sign(det_n) != np.sign(det_c))] = "branch_change"
    # near a singularity is the cause when the IK also failed or changed branch there
    status[np.isin(status, ("ok", "unreachable", "branch_change")) & (smin < options.singular_threshold_m)] = "singular"
    Rn, pn = kin.pose(x_nominal, np.nan_to_num(q))
    return Compensated(q_nominal=q_nom, q=q, status=status, p_corrected=pn, R_corrected=Rn, error_m=err,
                       sigma_min_m=smin, correction_m=np.linalg.norm(pn - p_t, axis=1))
