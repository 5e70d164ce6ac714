"""What every measurement type shares: a kinematic chain plus the type's own parameters.

A measurement type (3-D point, 6-D pose, plane contact, point coincidence) is composed from
* a **kinematics** object — anything with ``parameter_names()``, ``parameter_units()``,
  ``vector()``, ``chain()`` (a `pipeline.models.chain.Chain` ending at the tool frame),
  ``priority()``, ``n_joints``, ``lower``/``upper``: `UrdfArm`, seed 000's `SerialArm`;
* the type's **extra parameters** (targets, planes, fixture points), appended after the
  chain's in the parameter vector.

Adding an instrument is one new module in this package with a subclass of `Composed`:
identify, observe, plan, diagnose and report only see the `MeasurementModel` protocol.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.identify.model import Table
from pipeline.models import chain as ch


def skew(v: np.ndarray) -> np.ndarray:
    """[v]× for (...,3) vectors, (...,3,3)."""
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1), np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


@dataclass(frozen=True)
class Composed:
    """Base of the measurement types (see module docstring).  Subclasses set `system`,
    `residual_dim` and implement `residuals`/`jacobian` (and the extra-parameter hooks)."""

    kin: object

    system = "urdf"
    residual_dim = 1

    # ----- extra parameters (overridden by types that have them) --------------------------
    def extra_names(self) -> list[str]:
        return []

    def extra_units(self) -> list[str]:
        return []

    def extra_nominal(self) -> np.ndarray:
        return np.zeros(0)

    def extra_priority(self) -> np.ndarray:
        return np.zeros(len(self.extra_names()), int)

    # ----- MeasurementModel ------------------------------------------------------------
    @property
    def n_kin(self) -> int:
        return self.kin.chain().n_params

    def parameter_names(self) -> list[str]:
        return self.kin.parameter_names() + self.extra_names()

    def parameter_units(self) -> list[str]:
        return self.kin.parameter_units() + self.extra_units()

    def nominal(self) -> np.ndarray:
        return np.concatenate([self.kin.vector(), self.extra_nominal()])

    def priority(self) -> np.ndarray:
        return np.concatenate([self.kin.priority(), self.extra_priority()])

    fit_tool = True  # False: the tool frame is known (held at its URDF / given value)

    def groups(self) -> dict[str, list[str]]:
        """Parameter groups for model selection; "registration" is always fitted, groups whose
        name starts with "_" never are."""
        g = dict(self.kin.groups()) if hasattr(self.kin, "groups") else {}
        if self.extra_names():
            g["registration"] = g.get("registration", []) + self.extra_names()
        if not self.fit_tool and "registration" in g:
            g["_known tool"] = [n for n in g["registration"] if n.startswith("tool.")]
            g["registration"] = [n for n in g["registration"] if not n.startswith("tool.")]
        return g

    def uncalibrated(self, data: Table) -> np.ndarray:
        """The reference of "RMS before": the nominal robot with only the registration fitted
        (instrument frame, tool / targets, planes, points), as a user without a calibration has."""
        from pipeline.identify.complexity import fixed_for
        from pipeline.identify.least_squares import FitOptions, fit

        if "registration" not in self.groups():
            return self.nominal()
        return fit(self, data, FitOptions(fixed=fixed_for(self, ["registration"]), before=False)).x

    def exports(self, x: np.ndarray) -> dict[str, str]:
        """The calibrated robot as a URDF (when the kinematics come from one), with the parameter
        files ROS stacks load (`UrdfArm.ros_files`)."""
        if hasattr(self.kin, "ros_files"):
            return self.kin.ros_files(self.split(x)[0])
        if not hasattr(self.kin, "urdf_text"):
            return {}
        return {"model.urdf": self.kin.urdf_text(self.split(x)[0])}

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(x, float)
        return x[:self.n_kin], x[self.n_kin:]

    def tool(self, x: np.ndarray, q: np.ndarray, jac: bool = True, angular: bool = True):
        """Tool frame over the campaign: positions (N,3), d/dx (N,3,P), rotations (N,3,3) and the
        angular derivative (N,3,P), P covering the whole parameter vector (extras: zero).  With
        `jac` False the derivatives are None (forward kinematics only: residual evaluations)."""
        xk, _ = self.split(x)
        if not jac:
            R, p = ch.forward(self.kin.chain(), xk, q)
            return p, None, R, None
        width = self.n_kin + len(self.extra_names())
        if not angular:  # position only (a point on the tool): no angular part, no rotations
            p, Jp = ch.jacobian(self.kin.chain(), xk, q, width=width)
            return p, Jp, None, None
        return ch.jacobian(self.kin.chain(), xk, q, angular=True, width=width)

    def points(self, x: np.ndarray, data: Table) -> tuple[np.ndarray, np.ndarray]:
        """The tool point (N,3) m and its Jacobian (N,3,P)."""
        p, Jp, _, _ = self.tool(x, data["joint_positions"], angular=False)
        return p, Jp

    def describe(self, x: np.ndarray) -> dict:
        d = self.kin.with_vector(self.split(x)[0]).to_dict()
        if self.extra_names():
            d["measurement_parameters"] = {n: float(v) for n, v in zip(self.extra_names(), self.split(x)[1])}
        return d
