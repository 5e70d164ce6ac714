"""Inverse kinematics of the extended Delta model (seed 003's full model: axis yaw/tilt, unequal
rods): θ (N, 3) rad with P(β, θ) = p (N, 3) m in the base frame {A}, by a damped Newton
(Levenberg–Marquardt) over all targets at once — batched 3×3 solves, no per-target loop.

P(β, θ) is `pipeline.models.delta.full_forward` (Newton on the six rod constraints); dP/dθ is
analytic (`full_theta_jacobian`, implicit function theorem; θ_i and the actuator offset Δθ_i
enter only as their sum, so it equals the Δθ_i columns of `full_jacobian`).  Started from the closed-form β'
inverse of the simplified part of β, a reachable target converges in a few steps.
"""

from __future__ import annotations

import numpy as np

from pipeline.models import delta as dm
from pipeline.models.delta import Delta

THETA_COLUMNS = tuple(12 * leg + dm.LEG_KEYS.index("dtheta1") for leg in range(3))  # Δθ_i in the 36 β


def point_and_jacobian(delta: Delta, beta: np.ndarray, theta: np.ndarray):
    """Platform point P (N, 3) m in {A}, dP/dθ (N, 3, 3) m/rad and ok (N,) (the legs close) of
    the extended model (36 β) at actuator angles θ (N, 3) rad."""
    p, R, ok = dm.full_forward(delta, beta, theta, extended=True)
    return p, dm.full_theta_jacobian(delta, beta, theta, p, R), ok


def solve(delta: Delta, beta: np.ndarray, p: np.ndarray, theta0: np.ndarray, iters: int = 40,
          tol: float = 1e-12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """θ (N, 3) rad minimising |P(β, θ) − p| from θ0; the remaining error (N,) m (inf where the
    start does not close) and dP/dθ (N, 3, 3) at θ.  A row stops once its error is below `tol`
    m, its step below 1e-15 rad, or its damping runs away (no descent: unreachable)."""
    p = np.atleast_2d(np.asarray(p, float))
    theta = np.array(theta0, float, ndmin=2)
    P, J, ok = point_and_jacobian(delta, beta, theta)
    r = P - p
    cost = np.where(ok, np.sum(r**2, axis=1), np.inf)
    lam = np.full(p.shape[0], 1e-6)
    active = ok & (cost > tol**2)
    for _ in range(iters):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        Ja, ra = J[idx], r[idx]
        JtJ = np.einsum("nki,nkj->nij", Ja, Ja)
        scale = np.trace(JtJ, axis1=1, axis2=2) / 3
        A = JtJ + (lam[idx] * scale)[:, None, None] * np.eye(3)
        step = -np.linalg.solve(A, np.einsum("nki,nk->ni", Ja, ra)[..., None])[..., 0]
        trial = theta[idx] + step
        Pt, Jt, okt = point_and_jacobian(delta, beta, trial)
        rt = Pt - p[idx]
        ct = np.sum(rt**2, axis=1)
        acc = okt & np.isfinite(ct) & (ct < cost[idx])
        a = idx[acc]
        theta[a], r[a], J[a], cost[a] = trial[acc], rt[acc], Jt[acc], ct[acc]
        lam[a] = np.maximum(lam[a] / 10, 1e-12)
        lam[idx[~acc]] *= 10
        small = np.max(np.abs(step), axis=1) < 1e-15
        active[idx[(acc & (ct <= tol**2)) | small]] = False
        active[lam > 1e6] = False
    return np.angle(np.exp(1j * theta)), np.sqrt(cost), J
