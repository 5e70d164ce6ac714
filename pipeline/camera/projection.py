"""Camera projection: OpenCV's pinhole model with its distortion terms, and OpenCV's fisheye
(equidistant) model, as pure numpy functions of (intrinsics, points in the camera frame).

Camera frame: x right, y down, z along the optical axis (OpenCV's).  Points (n,3) in m; pixels
(n,2) = (u, v) in px, the centre of the top-left pixel at (0, 0).

Intrinsics vector ``k`` (SI / px):

* ``pinhole``: ``fx, fy, cx, cy`` (px) then the distortion coefficients in OpenCV's order,
  ``k1, k2, p1, p2[, k3[, k4, k5, k6]]`` (4, 5 or 8 terms; dimensionless).  With ``x' = X/Z``,
  ``y' = Y/Z``, ``r² = x'² + y'²``::

      radial = (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)
      x'' = x' radial + 2 p1 x'y' + p2 (r² + 2x'²)
      y'' = y' radial + p1 (r² + 2y'²) + 2 p2 x'y'
      u = fx x'' + cx,  v = fy y'' + cy

* ``fisheye``: ``fx, fy, cx, cy, k1, k2, k3, k4`` (`cv2.fisheye`, skew 0)::

      r = sqrt(x'² + y'²),  θ = atan(r),  θd = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)
      u = fx (θd / r) x' + cx,  v = fy (θd / r) y' + cy

`project` returns the pixels and, on request, the analytic Jacobians d uv / d k (n,2,len k) and
d uv / d P (n,2,3).  `radial_division` is the one-term radial *undistortion* variant (distorted
→ ideal coordinates) used by the seed-001 laser-stripe scanner (`pipeline.models.camera`).
"""

from __future__ import annotations

import numpy as np

PINHOLE, FISHEYE = "pinhole", "fisheye"
MODELS = (PINHOLE, FISHEYE)
PINHOLE_TERMS = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
FISHEYE_TERMS = ("k1", "k2", "k3", "k4")
N_DIST = {PINHOLE: (4, 5, 8), FISHEYE: (4,)}


def intrinsic_names(model: str, n_dist: int) -> list[str]:
    """Names of the intrinsics vector of `model` with `n_dist` distortion terms."""
    if model not in MODELS or n_dist not in N_DIST[model]:
        raise ValueError(f"camera model {model!r} with {n_dist} distortion terms: expected "
                         + "; ".join(f"{m} with {'/'.join(map(str, N_DIST[m]))}" for m in MODELS))
    terms = PINHOLE_TERMS if model == PINHOLE else FISHEYE_TERMS
    return ["fx", "fy", "cx", "cy", *terms[:n_dist]]


def intrinsic_units(model: str, n_dist: int) -> list[str]:
    return ["px"] * 4 + [""] * n_dist


def camera_matrix(k: np.ndarray) -> np.ndarray:
    """The 3×3 OpenCV camera matrix of an intrinsics vector."""
    return np.array([[k[0], 0.0, k[2]], [0.0, k[1], k[3]], [0.0, 0.0, 1.0]])


def _normalised(P: np.ndarray):
    P = np.asarray(P, float)
    z = P[:, 2]
    return P[:, 0] / z, P[:, 1] / z, z


def _point_jac(P: np.ndarray, z: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """d (x', y') / d P, (n,2,3)."""
    n = P.shape[0]
    J = np.zeros((n, 2, 3))
    J[:, 0, 0] = 1 / z
    J[:, 1, 1] = 1 / z
    J[:, 0, 2] = -x / z
    J[:, 1, 2] = -y / z
    return J


def _pinhole(k: np.ndarray, x: np.ndarray, y: np.ndarray, jac: bool):
    """Distorted normalised coordinates (x'', y'') and d/d(x', y') (n,2,2), d/d dist (n,2,nd)."""
    nd = k.size - 4
    d = np.zeros(8)
    d[:nd] = k[4:]
    k1, k2, p1, p2, k3, k4, k5, k6 = d
    r2 = x * x + y * y
    r4, r6 = r2 * r2, r2 * r2 * r2
    N = 1 + k1 * r2 + k2 * r4 + k3 * r6
    D = 1 + k4 * r2 + k5 * r4 + k6 * r6
    rad = N / D
    xy = x * y
    xd = x * rad + 2 * p1 * xy + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * xy
    if not jac:
        return xd, yd, None, None
    drad = ((k1 + 2 * k2 * r2 + 3 * k3 * r4) * D - N * (k4 + 2 * k5 * r2 + 3 * k6 * r4)) / (D * D)  # d rad / d r²
    Jx = np.empty((x.size, 2, 2))
    Jx[:, 0, 0] = rad + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x
    Jx[:, 0, 1] = 2 * xy * drad + 2 * p1 * x + 2 * p2 * y
    Jx[:, 1, 0] = 2 * xy * drad + 2 * p1 * x + 2 * p2 * y
    Jx[:, 1, 1] = rad + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x
    Jd = np.empty((x.size, 2, 8))
    for j, rp in ((0, r2), (1, r4), (4, r6)):  # k1, k2, k3
        Jd[:, 0, j], Jd[:, 1, j] = x * rp / D, y * rp / D
    for j, rp in ((5, r2), (6, r4), (7, r6)):  # k4, k5, k6
        Jd[:, 0, j], Jd[:, 1, j] = -x * N * rp / (D * D), -y * N * rp / (D * D)
    Jd[:, 0, 2], Jd[:, 1, 2] = 2 * xy, r2 + 2 * y * y  # p1
    Jd[:, 0, 3], Jd[:, 1, 3] = r2 + 2 * x * x, 2 * xy  # p2
    return xd, yd, Jx, Jd[:, :, :nd]


def _fisheye(k: np.ndarray, x: np.ndarray, y: np.ndarray, jac: bool):
    """As `_pinhole` for the equidistant model (θd / r → 1 on the axis)."""
    k1, k2, k3, k4 = k[4:8]
    r = np.sqrt(x * x + y * y)
    th = np.arctan(r)
    t2 = th * th
    poly = 1 + k1 * t2 + k2 * t2**2 + k3 * t2**3 + k4 * t2**4
    thd = th * poly
    small = r < 1e-8
    rs = np.where(small, 1.0, r)
    s = np.where(small, 1.0, thd / rs)  # θd / r
    xd, yd = s * x, s * y
    if not jac:
        return xd, yd, None, None
    dthd = 1 + 3 * k1 * t2 + 5 * k2 * t2**2 + 7 * k3 * t2**3 + 9 * k4 * t2**4  # d θd / d θ
    ds_r = np.where(small, 2 * (k1 - 1 / 3), (dthd / (1 + rs * rs) * rs - thd) / rs**3)  # (d s / d r) / r
    Jx = np.empty((x.size, 2, 2))
    Jx[:, 0, 0] = s + x * x * ds_r
    Jx[:, 0, 1] = x * y * ds_r
    Jx[:, 1, 0] = x * y * ds_r
    Jx[:, 1, 1] = s + y * y * ds_r
    Jd = np.empty((x.size, 2, 4))
    for j in range(4):
        g = np.where(small, 0.0, th ** (2 * j + 3) / rs)  # d s / d k_j
        Jd[:, 0, j], Jd[:, 1, j] = g * x, g * y
    return xd, yd, Jx, Jd


def project(k: np.ndarray, P: np.ndarray, model: str = PINHOLE, jac: bool = False):
    """Pixels (n,2) of camera-frame points P (n,3) m.  With `jac`: also d uv / d k (n,2,len k)
    and d uv / d P (n,2,3) per px/m."""
    k = np.asarray(k, float)
    x, y, z = _normalised(P)
    xd, yd, Jx, Jd = (_pinhole if model == PINHOLE else _fisheye)(k, x, y, jac)
    uv = np.stack([k[0] * xd + k[2], k[1] * yd + k[3]], axis=1)
    if not jac:
        return uv
    n = x.size
    Jk = np.zeros((n, 2, k.size))
    Jk[:, 0, 0], Jk[:, 1, 1] = xd, yd
    Jk[:, 0, 2], Jk[:, 1, 3] = 1.0, 1.0
    f = np.array([k[0], k[1]])[None, :, None]
    Jk[:, :, 4:] = f * Jd
    JP = (f * Jx) @ _point_jac(np.asarray(P, float), z, x, y)
    return uv, Jk, JP


def radial_division(ut: np.ndarray, vt: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray]:
    """One-term radial *undistortion* (distorted → ideal sensor coordinates, same unit as the
    inputs): u = ũ (1 + k r̃²), v = ṽ (1 + k r̃²), r̃² = ũ² + ṽ² — the inverse direction of
    OpenCV's model, as seed 001 (Lee, Yoon, Kang 2004, eqs. 2–3) writes its lens."""
    g = 1.0 + k * (ut**2 + vt**2)
    return ut * g, vt * g


def radial_division_inverse(u: np.ndarray, v: np.ndarray, k: float, iters: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of `radial_division`: solve r̃(1 + k r̃²) = r for r̃ (Newton; monotone for k ≥ 0)."""
    r = np.hypot(u, v)
    rt = r.copy()
    for _ in range(iters):
        step = (rt * (1 + k * rt**2) - r) / (1 + 3 * k * rt**2)
        rt = rt - step
        if np.all(np.abs(step) <= 1e-15 * np.maximum(r, 1e-12)):
            break
    scale = np.divide(rt, r, out=np.ones_like(r), where=r > 0)
    return u * scale, v * scale
