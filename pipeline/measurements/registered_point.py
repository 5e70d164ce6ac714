"""3-D points measured by an instrument whose frame is registered to the robot's base: a laser
tracker on a parallel robot (seed 003), or any kinematics that offers `point(...)`.

Composed from
* a **kinematics** part with ``parameter_names()``, ``parameter_units()``, ``vector()``,
  ``priority()`` and either ``point(x_kin, q, offset, jac) -> (M, dM/dx_kin, R_tool or None)``
  (a parallel robot: `pipeline.models.delta_arm.DeltaKinematics`) or ``chain()`` (any serial
  robot: `UrdfArm`, `SerialArm`);
* the instrument's **registration** {T} → {A} (`pipeline.measurements.registration`, six
  parameters ``<instrument>.x, y, z, rz, ry, rx``);
* the **target** on the tool (e.g. a reflector): scalar offsets along fixed tool-frame
  directions, each a named parameter.

Data columns: ``joint_positions`` (n, n_joints), ``point`` (n, 3) m in {T}.  Residual (n, 3) m
in {A}:  r = M(x, q) − (ᴬR_T p_T + ᴬt_T).  Parameter vector: kinematics, registration, targets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.identify.model import Table
from pipeline.measurements import registration as rg
from pipeline.measurements.composed import Composed, skew
from pipeline.models import chain as ch


@dataclass(frozen=True)
class RegisteredPointModel(Composed):
    instrument: str = "tracker"
    targets: tuple[tuple[str, tuple[float, float, float], float], ...] = ()  # (name, tool-frame unit direction, nominal m)
    target_priority: int = 5  # targets last: along a fixed direction they compete with the registration

    residual_dim = 3

    # ----- parameters -------------------------------------------------------------------
    @property
    def n_kin(self) -> int:
        return len(self.kin.parameter_names())

    def registration_names(self) -> list[str]:
        return [f"{self.instrument}.{a}" for a in rg.AXES]

    def extra_names(self) -> list[str]:
        return self.registration_names() + [t[0] for t in self.targets]

    def extra_units(self) -> list[str]:
        return ["m", "m", "m", "rad", "rad", "rad"] + ["m"] * len(self.targets)

    def extra_nominal(self) -> np.ndarray:
        return np.concatenate([np.zeros(6), [t[2] for t in self.targets]])

    def extra_priority(self) -> np.ndarray:
        return np.array([0] * 6 + [self.target_priority] * len(self.targets))

    def groups(self) -> dict[str, list[str]]:
        """Held-out model selection only for kinematics that name their groups."""
        return super().groups() if hasattr(self.kin, "groups") else {}

    def parts(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(kinematic parameters, registration (6,), target values)."""
        x = np.asarray(x, float)
        return x[:self.n_kin], x[self.n_kin:self.n_kin + 6], x[self.n_kin + 6:]

    def offset(self, x: np.ndarray) -> np.ndarray:
        """The target's offset in the tool frame (3,) m."""
        _, _, tv = self.parts(x)
        return sum((v * np.asarray(t[1], float) for t, v in zip(self.targets, tv)), np.zeros(3))

    # ----- predictions ------------------------------------------------------------------
    def kin_point(self, xk: np.ndarray, q: np.ndarray, offset: np.ndarray, jac: bool):
        """The kinematics' point at `offset` (tool frame): its own `point`, or a serial chain's
        tool frame moved by the offset (δ(R o) = δω × (R o))."""
        if hasattr(self.kin, "point"):
            return self.kin.point(xk, q, offset, jac)
        q = np.atleast_2d(np.asarray(q, float))
        if not jac:
            R, p = ch.forward(self.kin.chain(), xk, q)
            return p + R @ offset, None, R
        p, Jp, R, Jw = ch.jacobian(self.kin.chain(), xk, q, angular=True)
        w = R @ offset
        return p + w, Jp - np.einsum("nij,njp->nip", skew(w), Jw), R

    def target_point(self, x: np.ndarray, q: np.ndarray, jac: bool = False):
        """Target position M in {A} (n, 3) m; with jac also dM/dx (n, 3, P), zero on the
        registration columns."""
        xk, _, _ = self.parts(x)
        M, Jk, R = self.kin_point(xk, q, self.offset(x), jac)
        if not jac:
            return M
        n = M.shape[0]
        J = np.zeros((n, 3, self.n_kin + 6 + len(self.targets)))
        J[:, :, :self.n_kin] = Jk
        for k, t in enumerate(self.targets):
            d = np.asarray(t[1], float)
            J[:, :, self.n_kin + 6 + k] = d if R is None else R @ d
        return M, J

    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        R, t = rg.registration_matrix(self.parts(x)[1])
        return self.target_point(x, data["joint_positions"]) - (np.asarray(data["point"]) @ R.T + t)

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        _, J = self.target_point(x, data["joint_positions"], jac=True)
        J[:, :, self.n_kin:self.n_kin + 6] = -rg.registration_jacobian(self.parts(x)[1],
                                                                       np.asarray(data["point"], float))
        return J

    def points(self, x: np.ndarray, data: Table) -> tuple[np.ndarray, np.ndarray]:
        """The tool point (offset zero) seen in the instrument frame {T}, (n, 3) m, and its
        derivatives (n, 3, P): in {T} a prediction does not depend on the arbitrary origin of
        {A}, so its covariance is the accuracy a user gets when commanding in the workcell."""
        xk, reg, _ = self.parts(x)
        q = np.atleast_2d(np.asarray(data["joint_positions"], float))
        p, Jk, _ = self.kin_point(xk, q, np.zeros(3), True)
        J = np.zeros((q.shape[0], 3, self.n_kin + 6 + len(self.targets)))
        J[:, :, :self.n_kin] = Jk
        return rg.to_instrument_jacobian(reg, p, J, self.n_kin)

    def initial_guess(self, data: Table) -> np.ndarray:
        """Nominal kinematics with the registration from the closed-form fit of the nominal
        target positions to the measured points (≥ 4 points)."""
        x = self.nominal()
        x[self.n_kin:self.n_kin + 6] = rg.register(self.target_point(x, data["joint_positions"]), data["point"])
        return x

    def uncalibrated(self, data: Table) -> np.ndarray:
        """Before calibration: the nominal robot seen through the least-squares registration
        (closed form), as a user without a calibration has it."""
        return self.initial_guess(data)
