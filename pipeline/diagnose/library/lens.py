"""The scanner camera's lens terms beyond the model's one-term radial distortion, and the stripe
geometry they are measured across (pure numpy, no diagnosis machinery).

The true lens maps distorted sensor coordinates (ũ, ṽ) (m, on the sensor plane of the camera frame) to
ideal ones as the model's u = ũ(1 + k r̃²) plus Δ(ũ, ṽ): a second radial term k2 (1/m⁴) and the
tangential (decentring) terms p1, p2 (1/m), r̃² = ũ² + ṽ² (`lens_excess`, its Jacobian in (ũ, ṽ)
`lens_excess_jacobian`).  A laser stripe's pixels lie on a line: `stripe_normal` is the unit normal
across it in pixel coordinates, the direction along which a corner's position is measured.
"""

from __future__ import annotations

import numpy as np


def lens_excess(ut: np.ndarray, vt: np.ndarray, k2: float, p1: float, p2: float) -> tuple[np.ndarray, np.ndarray]:
    """Δu, Δv (m): ideal minus one-term-radial sensor coordinates (module docstring)."""
    r2 = ut**2 + vt**2
    return (k2 * r2**2 * ut + 2 * p1 * ut * vt + p2 * (r2 + 2 * ut**2),
            k2 * r2**2 * vt + p1 * (r2 + 2 * vt**2) + 2 * p2 * ut * vt)


def stripe_normal(px: np.ndarray) -> np.ndarray:
    """Unit normal (2,) across the straight stripe through pixels px (M,2), V component ≥ 0;
    (0, 1) for fewer than two pixels."""
    px = np.asarray(px, float)
    if px.shape[0] < 2:
        return np.array([0.0, 1.0])
    _, _, Vt = np.linalg.svd(px - px.mean(axis=0), full_matrices=False)
    d = Vt[0]
    n = np.array([-d[1], d[0]])
    return n if n[1] >= 0 else -n


def stripe_normals(px: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Per-row normal (n,2) across the stripe of each row's pose (from the pose's pixels)."""
    out = np.zeros((px.shape[0], 2))
    for p in np.unique(pose):
        m = pose == p
        out[m] = stripe_normal(px[m])
    return out


def lens_excess_jacobian(ut: np.ndarray, vt: np.ndarray, k2: float, p1: float, p2: float) -> np.ndarray:
    """∂(Δu, Δv)/∂(ũ, ṽ) (n,2,2) of `lens_excess`."""
    r2 = ut**2 + vt**2
    J = np.empty((ut.size, 2, 2))
    J[:, 0, 0] = k2 * (r2**2 + 4 * r2 * ut**2) + 2 * p1 * vt + 6 * p2 * ut
    J[:, 0, 1] = J[:, 1, 0] = 4 * k2 * r2 * ut * vt + 2 * p1 * ut + 2 * p2 * vt
    J[:, 1, 1] = k2 * (r2**2 + 4 * r2 * vt**2) + 6 * p1 * vt + 2 * p2 * ut
    return J
