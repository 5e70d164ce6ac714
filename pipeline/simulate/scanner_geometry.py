"""Geometry of the laser-stripe scanner on an arm (pure numpy, SI): the camera's pose from the
joints, the laser plane's trace on the floor, the projection of base-frame points to pixels, and
the minimum-norm Newton solver the operator and the servo use to move the arm (seed 001)."""

from __future__ import annotations

import numpy as np

from pipeline.models import camera as cam
from pipeline.models import serial_arm


def camera_pose(xa: np.ndarray, s: np.ndarray, q: np.ndarray, dT=None):
    """Camera rotation (N,3,3) and centre (N,3) in {B} for joint angles q (N,5)."""
    R_f, t_f = serial_arm.forward(xa, q)
    if dT is not None:
        dR, dt = dT
        R_f, t_f = dR @ R_f, t_f + dt
    R_he = cam.hand_eye_rotation(s[cam.I_W], s[cam.I_PHI], s[cam.I_PSI])
    return R_f @ R_he, t_f + np.einsum("nij,j->ni", R_f, s[cam.I_TX:cam.I_TZ + 1])


def floor_line(R_c: np.ndarray, C: np.ndarray, s: np.ndarray, z0: float):
    """Laser plane ∩ floor: a point (N,3) and unit direction (N,3); NaN where parallel."""
    n_c, d_c = cam.laser_plane(s)
    n = R_c @ n_c  # (N,3) plane normal in {B}
    d = d_c + np.einsum("ni,ni->n", n, C)
    direc = np.cross(n, [0.0, 0.0, 1.0])
    nd = np.linalg.norm(direc, axis=1, keepdims=True)
    direc = direc / np.where(nd > 1e-9, nd, np.nan)
    # point on the floor: minimise |p| subject to n·p = d, p_z = z0 (2-D in x,y)
    nxy = n[:, :2]
    rhs = d - n[:, 2] * z0
    pxy = nxy * (rhs / np.sum(nxy**2, axis=1))[:, None]
    return np.concatenate([pxy, np.full((len(C), 1), z0)], axis=1), direc


def project(R_c: np.ndarray, C: np.ndarray, s: np.ndarray, X: np.ndarray,
             fx: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (N,2) of base-frame points X (N,3) seen by cameras (R_c, C); and depth z_C.
    With `fx` (`scorbot_scanner.effect_values`), the true lens also has k2 and tangential (p1, p2) terms."""
    p_c = np.einsum("nji,nj->ni", R_c, X - C)
    if fx is None or not (fx["k2"] or fx["p1"] or fx["p2"]):
        return cam.project(s, p_c), p_c[:, 2]
    from pipeline.diagnose.library.lens import lens_excess

    x, y, z = p_c[:, 0], p_c[:, 1], p_c[:, 2]
    u, v = s[cam.I_F] * y / z, s[cam.I_F] * x / z  # ideal sensor coordinates
    ut, vt = cam.distort(u, v, s[cam.I_K])
    with np.errstate(over="ignore", invalid="ignore"):  # far outside the image it may diverge: dropped as unseen
        for _ in range(20):  # solve U_k(ũ, ṽ) + Δ(ũ, ṽ) = (u, v) for the distorted coordinates
            du, dv = lens_excess(ut, vt, fx["k2"], fx["p1"], fx["p2"])
            ut, vt = cam.distort(u - du, v - dv, s[cam.I_K])
    return np.stack([ut / s[cam.I_SU] + s[cam.I_U0], vt / s[cam.I_SV] + s[cam.I_V0]], axis=1), z


def stripe_normal(px: np.ndarray) -> np.ndarray:
    """Unit normal (2,) across the stripe through pixels px (M,2), +V side (V for one pixel)."""
    from pipeline.diagnose.library.lens import stripe_normal

    return stripe_normal(px)


def newton(fun, q0: np.ndarray, iters: int = 40, h: float = 1e-7) -> np.ndarray:
    """Minimum-norm damped Newton on fun(q) = 0; `fun` maps a batch (B,d) to (B,m), so the
    central-difference Jacobian is one call."""
    q = q0.copy()
    E = np.eye(q.size) * h
    for _ in range(iters):
        F = fun(np.vstack([q, q + E, q - E]))
        r = F[0]
        J = ((F[1:q.size + 1] - F[q.size + 1:]) / (2 * h)).T
        step = np.clip(np.linalg.lstsq(J, r, rcond=None)[0], -0.2, 0.2)
        q = q - step
        if np.max(np.abs(step)) < 1e-12:
            break
    return q
