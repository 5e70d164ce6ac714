"""Points reconstructed by a sensor on the flange that must lie on known fixture points: a
laser-stripe scanner seeing a target's corner (seed 001), or any flange-mounted instrument
that turns its reading into a point.

Composed from
* a serial **arm** with ``vector()``, ``chain()`` and ``parameter_names()`` (`SerialArm`,
  `UrdfArm`); its joint offsets may be calibrated with the sensor;
* a **sensor** part with ``parameter_names()``, ``parameter_units()``, ``n_params`` and
  ``flange_points(s, data, jac, excess) -> (p_F (n,3) m, dp_F/ds (n,3,ns))``
  (`pipeline.models.stripe_sensor.StripeSensor`).

Data columns: ``joint_positions`` (n, n_joints), ``corner`` (n, 3) m in the base frame {B}, and
the sensor's own columns.  Residual (n, 3) m:  r = R_F(q) p_F + t_F(q) − corner.  Parameter
vector: the sensor's, then (optionally) the arm's joint offsets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.identify.model import Table
from pipeline.measurements.composed import skew
from pipeline.models import chain as ch

OFFSET_KEYS = ("theta_offset", "offset")  # a joint's offset in D-H (`SerialArm`) and URDF (`UrdfArm`) vectors


@dataclass(frozen=True)
class SensedPointModel:
    arm: object = None
    sensor: object = None
    nominal_x: tuple[float, ...] = ()  # the sensor's nominal parameters
    joint_offsets: bool = False

    residual_dim = 3

    # ----- description ------------------------------------------------------------------
    def offset_index(self) -> np.ndarray:
        """Positions of the arm's joint offsets in its parameter vector, joint order."""
        return np.array([i for i, n in enumerate(self.arm.parameter_names()) if n.rsplit(".", 1)[-1] in OFFSET_KEYS])

    def offset_joints(self) -> np.ndarray:
        """The joint (column of ``joint_positions``) each offset belongs to."""
        joints = list(getattr(self.arm, "joint_names", None) or [j.name for j in self.arm.joints])
        names = self.arm.parameter_names()
        return np.array([joints.index(names[i].rsplit(".", 1)[0]) for i in self.offset_index()], int)

    def parameter_names(self) -> list[str]:
        names = self.sensor.parameter_names()
        if self.joint_offsets:
            arm_names = self.arm.parameter_names()
            names += [arm_names[i] for i in self.offset_index()]
        return names

    def parameter_units(self) -> list[str]:
        return self.sensor.parameter_units() + (["rad"] * len(self.offset_index()) if self.joint_offsets else [])

    def nominal(self) -> np.ndarray:
        x = np.asarray(self.nominal_x, float)
        if self.joint_offsets:
            x = np.concatenate([x, self.arm.vector()[self.offset_index()]])
        return x

    # ----- kinematics -------------------------------------------------------------------
    def _arm_vector(self, x: np.ndarray) -> np.ndarray:
        xa = self.arm.vector()
        if self.joint_offsets:
            xa[self.offset_index()] = x[self.sensor.n_params:]
        return xa

    def flange(self, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flange rotations (n,3,3) and positions (n,3) m in {B}."""
        return ch.forward(self.arm.chain(), self._arm_vector(np.asarray(x, float)), np.atleast_2d(q))

    def points(self, x: np.ndarray, data: Table, excess=None) -> tuple[np.ndarray, np.ndarray]:
        """Sensed points P (n,3) m in {B} and dP/dx (n,3,P); `excess`: the sensor's extra terms."""
        x = np.asarray(x, float)
        ns = self.sensor.n_params
        p_f, J_f = self.sensor.flange_points(x[:ns], data, jac=True, excess=excess)
        q = np.atleast_2d(np.asarray(data["joint_positions"], float))
        R_f, t_f = self.flange(x, q)
        w = np.einsum("nij,nj->ni", R_f, p_f)
        P = w + t_f
        J = np.zeros((p_f.shape[0], 3, x.size))
        J[:, :, :ns] = np.einsum("nij,njk->nik", R_f, J_f)
        if self.joint_offsets:  # an offset acts as its joint angle: dP/dq = dt_F/dq + δω × (R_F p_F)
            _, Jq, Jw = ch.joint_jacobian(self.arm.chain(), self._arm_vector(x), q, angular=True)
            J[:, :, ns:] = (Jq - np.einsum("nij,njk->nik", skew(w), Jw))[:, :, self.offset_joints()]
        return P, J

    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        x = np.asarray(x, float)
        p_f, _ = self.sensor.flange_points(x[:self.sensor.n_params], data)
        R_f, t_f = self.flange(x, data["joint_positions"])
        return np.einsum("nij,nj->ni", R_f, p_f) + t_f - np.asarray(data["corner"], float)

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        return self.points(x, data)[1]
