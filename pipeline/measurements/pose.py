"""6-D pose measurements (camera marker, tracker 6-DoF probe).

Data columns: ``joint_positions``, ``position`` (n,3) m and ``orientation`` (n,4) unit
quaternion (x, y, z, w) of the measured tool frame in the instrument frame.  Residual (n,6):
position error (m) and the rotation error ``log(R_pred · R_measᵀ)`` (a world-frame rotation
vector, rad) scaled by ``sigma_m / sigma_rad`` — both halves in metres with the weights of the
stated uncertainties.  The registration is the base frame, the tool frame is ``tool.*``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.identify.model import Table
from pipeline.measurements.composed import Composed, skew


def log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (n,3) of rotation matrices (n,3,3)."""
    return Rotation.from_matrix(R).as_rotvec()


def inverse_left_jacobian(phi: np.ndarray) -> np.ndarray:
    """J_l⁻¹(φ) of SO(3), (n,3,3): log(exp(δ)·exp(φ)) ≈ φ + J_l⁻¹(φ) δ."""
    th = np.linalg.norm(phi, axis=-1)
    K = skew(phi)
    small = th < 1e-6
    ths = np.where(small, 1.0, th)
    c = np.where(small, 1 / 12, (1 / ths**2 - (1 + np.cos(ths)) / (2 * ths * np.sin(ths))))
    return np.eye(3) - 0.5 * K + c[:, None, None] * (K @ K)


@dataclass(frozen=True)
class PoseModel(Composed):
    sigma_m: float = 1e-3
    sigma_rad: float = 1e-3
    residual_dim = 6

    @property
    def weight(self) -> float:
        """Metres per radian that put rotation residuals on the position residuals' scale."""
        return self.sigma_m / self.sigma_rad

    def _rot_error(self, R: np.ndarray, data: Table) -> np.ndarray:
        Rm = Rotation.from_quat(np.asarray(data["orientation"], float)).as_matrix()
        return log_so3(R @ np.swapaxes(Rm, 1, 2))

    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        p, _, R, _ = self.tool(x, data["joint_positions"])
        dp = p - np.asarray(data["position"], float)
        return np.hstack([dp, self.weight * self._rot_error(R, data)])

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        p, Jp, R, Jw = self.tool(x, data["joint_positions"])
        phi = self._rot_error(R, data)
        Jr = inverse_left_jacobian(phi) @ Jw
        return np.concatenate([Jp, self.weight * Jr], axis=1)

    def initial_guess(self, data: Table) -> np.ndarray:
        """Registration by Kabsch on the positions, tool orientation from the mean rotation."""
        from pipeline.measurements.point import registered_start
        from pipeline.models.urdf import rpy_of

        x = registered_start(self, data, np.asarray(data["position"], float))
        names = self.parameter_names()
        if "tool.roll" in names:
            it = names.index("tool.roll")
            x[it:it + 3] = 0.0
            _, _, R, _ = self.tool(x, data["joint_positions"])
            Rm = Rotation.from_quat(np.asarray(data["orientation"], float)).as_matrix()
            rel = Rotation.from_matrix(np.swapaxes(R, 1, 2) @ Rm).mean().as_matrix()  # R · R_tool = R_meas
            x[it:it + 3] = rpy_of(rel)
        return x
