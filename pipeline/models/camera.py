"""Camera, laser-stripe triangulation and hand-eye model of seed 001 (Lee, Yoon, Kang 2004).

Pixel (U, V) → distorted sensor coordinates (eq. 4, s = pixel pitch, m/px)::

    ũ = s_u (U − u0),   ṽ = s_v (V − v0)                      (m on the sensor)

→ ideal (undistorted) sensor coordinates with one radial term (eqs. 2–3)::

    u = ũ (1 + k r²),   v = ṽ (1 + k r²),   r² = ũ² + ṽ²        (k in 1/m²)

→ a point of the laser plane in the camera frame {C} (eqs. 5–6, 12)::

    p_C = ρ [v, u, f],   ρ = b / (v + f tan θ)

(the laser sits b along +x_C, tilted by θ: its plane is x + z tan θ = b) → the robot base
frame {B} through the flange pose and the hand-eye transform (eqs. 8–10, 13)::

    P = T_flange(q) · T_hand_eye · p_C,   R_he = Rz(w) Ry(φ) Rz(ψ),   t_he = (tx, ty, tz)

Eq. 10's matrix is the ZYZ Euler product written out (two of its printed entries carry
sign/letter typos; Rz·Ry·Rz is the matrix whose other seven entries it prints).

Scanner parameter vector (eq. 14), SI units::

    f, s_u, s_v, u0, v0, k, b, theta, w, phi, psi, tx, ty, tz
    m, m/px, m/px, px, px, 1/m², m, rad, rad, rad, rad, m, m, m

All functions are pure numpy, vectorised over points.
"""

from __future__ import annotations

import numpy as np

from pipeline.camera.projection import radial_division, radial_division_inverse
from pipeline.models.transforms import rot

SCANNER_NAMES = ("f", "s_u", "s_v", "u0", "v0", "k", "b", "theta", "w", "phi", "psi", "tx", "ty", "tz")
SCANNER_UNITS = ("m", "m/px", "m/px", "px", "px", "1/m^2", "m", "rad", "rad", "rad", "rad", "m", "m", "m")
N_SCANNER = len(SCANNER_NAMES)
I_F, I_SU, I_SV, I_U0, I_V0, I_K, I_B, I_TH, I_W, I_PHI, I_PSI, I_TX, I_TY, I_TZ = range(N_SCANNER)


def hand_eye_rotation(w: float, phi: float, psi: float) -> np.ndarray:
    """R_he = Rz(w)·Ry(φ)·Rz(ψ) (eq. 10), (3,3): camera axes in the flange frame."""
    return rot("z", w) @ rot("y", phi) @ rot("z", psi)


def zyz_angles(R: np.ndarray) -> tuple[float, float, float]:
    """(w, φ, ψ) with Rz(w)Ry(φ)Rz(ψ) = R, choosing |w| ≤ π/2 (the branch near identity)."""
    phi = float(np.arccos(np.clip(R[2, 2], -1.0, 1.0)))
    if np.sin(phi) < 1e-9:  # gimbal lock: only w + ψ is defined; split it evenly
        s = float(np.arctan2(R[1, 0], R[0, 0]))
        return s / 2, phi, s / 2
    w = float(np.arctan2(R[1, 2], R[0, 2]))
    psi = float(np.arctan2(R[2, 1], -R[2, 0]))
    if abs(w) > np.pi / 2:  # the other branch: (w+π, −φ, ψ+π)
        w, phi, psi = w - np.sign(w) * np.pi, -phi, psi - np.sign(psi) * np.pi
    return w, phi, psi


def sensor_coords(px: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distorted sensor coordinates ũ, ṽ (m) of pixels px (n,2) = (U, V) (eq. 4)."""
    return s[I_SU] * (px[:, 0] - s[I_U0]), s[I_SV] * (px[:, 1] - s[I_V0])


def undistort(ut: np.ndarray, vt: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray]:
    """Ideal sensor coordinates u, v (m) from distorted ones (eqs. 2–3, one term): the
    generic camera's radial-division variant (`pipeline.camera.projection`)."""
    return radial_division(ut, vt, k)


def distort(u: np.ndarray, v: np.ndarray, k: float, iters: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of `undistort`: solve r̃(1 + k r̃²) = r for r̃ (Newton; monotone for k ≥ 0)."""
    return radial_division_inverse(u, v, k, iters)


def camera_points(s: np.ndarray, px: np.ndarray) -> np.ndarray:
    """Laser-plane points p_C (n,3) m in the camera frame for stripe pixels px (n,2) (eqs. 2–6)."""
    ut, vt = sensor_coords(px, s)
    u, v = undistort(ut, vt, s[I_K])
    rho = s[I_B] / (v + s[I_F] * np.tan(s[I_TH]))
    return rho[:, None] * np.stack([v, u, np.full_like(u, s[I_F])], axis=1)


def camera_points_jacobian(s: np.ndarray, px: np.ndarray, excess=None) -> tuple[np.ndarray, np.ndarray]:
    """p_C (n,3) and d p_C / d(f, s_u, s_v, u0, v0, k, b, θ), (n,3,8), analytic.  `excess`
    (Δu (n,), Δv (n,), ∂(Δu, Δv)/∂(ũ, ṽ) (n,2,2)): further lens terms added to the ideal
    coordinates, u = ũ(1 + k r²) + Δu (m; a lens richer than eq. 2's, e.g. the diagnosis's
    k2 and tangential terms); None: eq. 2 alone."""
    f, su, sv, u0, v0, k, b, th = s[:8]
    ut, vt = sensor_coords(px, s)
    r2 = ut**2 + vt**2
    g = 1.0 + k * r2
    u, v = ut * g, vt * g
    if excess is not None:
        u, v = u + excess[0], v + excess[1]
    t = np.tan(th)
    den = v + f * t
    rho = b / den
    n = px.shape[0]
    U = np.stack([v, u, np.full(n, f)], axis=1)  # direction [v, u, f]
    p = rho[:, None] * U
    # d(u, v) / d(ũ, ṽ) and / dk
    du_dut, du_dvt = g + 2 * k * ut**2, 2 * k * ut * vt
    dv_dut, dv_dvt = 2 * k * ut * vt, g + 2 * k * vt**2
    if excess is not None:
        dD = excess[2]
        du_dut, du_dvt = du_dut + dD[:, 0, 0], du_dvt + dD[:, 0, 1]
        dv_dut, dv_dvt = dv_dut + dD[:, 1, 0], dv_dvt + dD[:, 1, 1]
    # ũ depends on s_u, u0; ṽ on s_v, v0
    dut = {1: px[:, 0] - u0, 3: np.full(n, -su)}
    dvt = {2: px[:, 1] - v0, 4: np.full(n, -sv)}
    du = np.zeros((n, 8))
    dv = np.zeros((n, 8))
    for j, d in dut.items():
        du[:, j] += du_dut * d
        dv[:, j] += dv_dut * d
    for j, d in dvt.items():
        du[:, j] += du_dvt * d
        dv[:, j] += dv_dvt * d
    du[:, 5], dv[:, 5] = ut * r2, vt * r2
    # p = ρ U with ρ = b/den:  dp = ρ dU − (ρ/den) U dden + (U/den) db
    dU = np.zeros((n, 3, 8))
    dU[:, 0] = dv
    dU[:, 1] = du
    dU[:, 2, 0] = 1.0
    dden = dv.copy()
    dden[:, 0] += t
    dden[:, 7] += f / np.cos(th) ** 2
    J = rho[:, None, None] * dU - (rho / den)[:, None, None] * U[:, :, None] * dden[:, None, :]
    J[:, :, 6] += U / den[:, None]
    return p, J


def camera_to_flange(s: np.ndarray, p_c: np.ndarray) -> np.ndarray:
    """Points (n,3) from the camera frame into the flange frame (eq. 8)."""
    R = hand_eye_rotation(s[I_W], s[I_PHI], s[I_PSI])
    return p_c @ R.T + s[I_TX:I_TZ + 1]


def hand_eye_jacobian(s: np.ndarray, p_c: np.ndarray) -> np.ndarray:
    """d p_F / d(w, φ, ψ, tx, ty, tz) at fixed p_C, (n,3,6), in the flange frame."""
    w, phi, psi = s[I_W], s[I_PHI], s[I_PSI]
    R = hand_eye_rotation(w, phi, psi)
    q = p_c @ R.T  # R p_C
    a_w = np.array([0.0, 0.0, 1.0])
    a_phi = rot("z", w) @ np.array([0.0, 1.0, 0.0])
    a_psi = R[:, 2]
    n = p_c.shape[0]
    J = np.zeros((n, 3, 6))
    J[:, :, 0] = np.cross(a_w, q)
    J[:, :, 1] = np.cross(a_phi, q)
    J[:, :, 2] = np.cross(a_psi, q)
    J[:, :, 3:] = np.eye(3)
    return J


def project(s: np.ndarray, p_c: np.ndarray) -> np.ndarray:
    """Pixels (n,2) = (U, V) of camera-frame points p_C (n,3) (inverse of eqs. 1–4)."""
    x, y, z = p_c[:, 0], p_c[:, 1], p_c[:, 2]
    u, v = s[I_F] * y / z, s[I_F] * x / z  # eq. 5: x = ρ v, y = ρ u, z = ρ f
    ut, vt = distort(u, v, s[I_K])
    return np.stack([ut / s[I_SU] + s[I_U0], vt / s[I_SV] + s[I_V0]], axis=1)


def laser_plane(s: np.ndarray) -> tuple[np.ndarray, float]:
    """Laser plane in the camera frame as (unit normal n, offset d): n·p = d (m)."""
    n = np.array([1.0, 0.0, np.tan(s[I_TH])])
    scale = np.linalg.norm(n)
    return n / scale, float(s[I_B] / scale)
