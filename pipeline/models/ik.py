"""Batched numerical inverse kinematics for serial arms (damped Gauss–Newton, multi-start).

Used by the simulator the way a robot controller uses its nominal model: to turn a desired
tool pose into joint angles.  Pure numpy over a batch of targets.
"""

from __future__ import annotations

import numpy as np

from pipeline.models import serial_arm


def _pose_error(x: np.ndarray, q: np.ndarray, p_t: np.ndarray, R_t: np.ndarray) -> np.ndarray:
    R, p = serial_arm.forward(x, q)
    E = np.einsum("nji,njk->nik", R_t, R)  # R_tᵀ R
    w = 0.5 * np.stack([E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0], E[:, 1, 0] - E[:, 0, 1]], axis=1)
    return np.concatenate([p - p_t, 0.3 * w], axis=1)  # 0.3 m per rad: weight orientation like a lever


def pose_jacobian(x: np.ndarray, q: np.ndarray, h: float = 1e-7) -> np.ndarray:
    """d(tip position, tool rotation vector)/dq by central differences: (N, 6, n_joints)."""
    n, nj = q.shape
    R0, _ = serial_arm.forward(x, q)
    J = np.empty((n, 6, nj))
    for k in range(nj):
        dq = np.zeros(nj)
        dq[k] = h
        Rp, pp = serial_arm.forward(x, q + dq)
        Rm, pm = serial_arm.forward(x, q - dq)
        J[:, :3, k] = (pp - pm) / (2 * h)
        dR = np.einsum("nji,njk->nik", R0, Rp - Rm) / (2 * h)  # R0ᵀ dR: skew of body rate
        J[:, 3:, k] = np.einsum("nij,nj->ni", R0, np.stack([dR[:, 2, 1], dR[:, 0, 2], dR[:, 1, 0]], axis=1))
    return J


def solve(x: np.ndarray, p_t: np.ndarray, R_t: np.ndarray, seeds: np.ndarray, lower: np.ndarray,
          upper: np.ndarray, iters: int = 60, tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles reaching each target pose (p_t (N,3) m, R_t (N,3,3)) from the first of
    `seeds` (S, n_joints) that converges within limits.  Returns q (N, n_joints) and ok (N,)."""
    N, S = p_t.shape[0], seeds.shape[0]
    nj = seeds.shape[1]
    q = np.repeat(seeds[None], N, axis=0).reshape(N * S, nj)
    P = np.repeat(p_t, S, axis=0)
    Rt = np.repeat(R_t, S, axis=0)
    lam = 1e-4
    active = np.arange(N * S)
    for _ in range(iters):  # damped Gauss–Newton, only on rows not yet converged
        qa = q[active]
        e = _pose_error(x, qa, P[active], Rt[active])
        J = pose_jacobian(x, qa)
        J[:, 3:] *= 0.3
        JtJ = np.einsum("nik,nil->nkl", J, J) + lam * np.eye(nj)
        step = np.linalg.solve(JtJ, np.einsum("nik,ni->nk", J, e)[..., None])[..., 0]
        step = np.clip(step, -0.3, 0.3)
        q[active] = (qa - step + np.pi) % (2 * np.pi) - np.pi
        active = active[np.max(np.abs(step), axis=1) >= tol]
        if active.size == 0:
            break
    err = np.linalg.norm(_pose_error(x, q, P, Rt), axis=1)
    good = (err < 1e-9) & np.all((q >= lower) & (q <= upper), axis=1)
    good = good.reshape(N, S)
    q = q.reshape(N, S, nj)
    first = np.argmax(good, axis=1)
    ok = good.any(axis=1)
    return q[np.arange(N), first], ok
