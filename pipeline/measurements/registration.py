"""An instrument's registration: the rigid frame {T} (tracker, camera, CMM) seen from the robot's
base frame {A}, parameters (x, y, z, rz, ry, rx) — m and rad, ᴬR_T = Rz·Ry·Rx (ZYX Euler).

Pure functions: the matrix, its derivatives, the Jacobian of registered points, and the
closed-form least-squares registration (Kabsch, via scipy) that starts every fit.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.models.transforms import rot

AXES = ("x", "y", "z", "rz", "ry", "rx")


def registration_matrix(reg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ᴬR_T (3, 3) and ᴬt_T (3,) m of registration parameters (x, y, z, rz, ry, rx)."""
    reg = np.asarray(reg, float)
    cz, sz, cy, sy, cx, sx = np.cos(reg[3]), np.sin(reg[3]), np.cos(reg[4]), np.sin(reg[4]), np.cos(reg[5]), np.sin(reg[5])
    R = np.array([[cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
                  [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
                  [-sy, cy * sx, cy * cx]])
    return R, reg[:3].copy()


def register(p_a: np.ndarray, p_t: np.ndarray) -> np.ndarray:
    """Closed-form rigid registration (Kabsch, via `Rotation.align_vectors`) of instrument points
    p_t (N, 3) onto base-frame points p_a (N, 3), N ≥ 4: parameters (x, y, z, rz, ry, rx) with
    p_a ≈ ᴬR_T p_t + ᴬt_T — the least-squares fit of the registration alone.  ValueError if
    N < 4 or the points are collinear."""
    p_a, p_t = np.asarray(p_a, float), np.asarray(p_t, float)
    if p_t.shape[0] < 4:
        raise ValueError(f"the registration needs at least 4 points, got {p_t.shape[0]}")
    ca, ct = p_a.mean(axis=0), p_t.mean(axis=0)
    s = np.linalg.svd(p_t - ct, compute_uv=False)
    if s[1] <= 1e-9 * max(s[0], 1e-12):
        raise ValueError("the registration points are collinear (rotation undetermined)")
    rotation, _ = Rotation.align_vectors(p_a - ca, p_t - ct)
    R = rotation.as_matrix()
    rz, ry, rx = Rotation.from_matrix(R).as_euler("ZYX")
    return np.array([*(ca - R @ ct), rz, ry, rx])


def rotation_derivatives(reg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """dᴬR_T/drz, /dry, /drx (each 3×3) for ᴬR_T = Rz·Ry·Rx."""
    rz, ry, rx = reg[3:]
    Rz, Ry, Rx = rot("z", rz), rot("y", ry), rot("x", rx)
    dRz = np.array([[-np.sin(rz), -np.cos(rz), 0], [np.cos(rz), -np.sin(rz), 0], [0, 0, 0]])
    dRy = np.array([[-np.sin(ry), 0, np.cos(ry)], [0, 0, 0], [-np.cos(ry), 0, -np.sin(ry)]])
    dRx = np.array([[0, 0, 0], [0, -np.sin(rx), -np.cos(rx)], [0, np.cos(rx), -np.sin(rx)]])
    return dRz @ Ry @ Rx, Rz @ dRy @ Rx, Rz @ Ry @ dRx


def registration_jacobian(reg: np.ndarray, p_t: np.ndarray) -> np.ndarray:
    """d(ᴬR_T p_t + ᴬt_T)/d(x, y, z, rz, ry, rx), (N, 3, 6)."""
    J = np.zeros((p_t.shape[0], 3, 6))
    J[:, :, :3] = np.eye(3)
    for k, dR in enumerate(rotation_derivatives(reg)):
        J[:, :, 3 + k] = p_t @ dR.T
    return J


def to_instrument_jacobian(reg: np.ndarray, p_a: np.ndarray, J_a: np.ndarray, first: int) -> np.ndarray:
    """A base-frame point p_a (N, 3) with derivatives J_a (N, 3, P) seen in {T}:
    ᵀp = ᴬR_Tᵀ(p_a − ᴬt_T), returned with dᵀp/dx (N, 3, P) whose registration columns are
    first … first+5."""
    R, t = registration_matrix(reg)
    rel = p_a - t
    J = np.einsum("ji,njk->nik", R, J_a)  # Rᵀ · dp/dx
    J[:, :, first: first + 3] = -R.T
    for k, dR in enumerate(rotation_derivatives(reg)):
        J[:, :, first + 3 + k] = rel @ dR  # (dR)ᵀ rel, row-wise
    return rel @ R, J
