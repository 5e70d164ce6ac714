"""3-D point measurements (laser tracker, motion capture): one or several targets on the tool.

Data columns: ``joint_positions`` (n, n_joints) rad/m, ``position`` (n,3) m in the instrument
frame, optional ``target`` (n,) int.  Target 0 is the tool point (``tool.x/y/z``); target k ≥ 1
sits at ``target<k>.x/y/z`` in the tool frame.  Residual: predicted − measured, (n,3) m.
The instrument → robot registration is the chain's base frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.identify.model import Table
from pipeline.measurements.composed import Composed, skew


@dataclass(frozen=True)
class PointModel(Composed):
    n_targets: int = 1
    residual_dim = 3

    def extra_names(self) -> list[str]:
        return [f"target{k}.{a}" for k in range(1, self.n_targets) for a in "xyz"]

    def extra_units(self) -> list[str]:
        return ["m"] * len(self.extra_names())

    def extra_nominal(self) -> np.ndarray:
        return np.zeros(len(self.extra_names()))

    def _predict(self, x: np.ndarray, data: Table, jac: bool):
        t = np.asarray(data.get("target", np.zeros(len(data["joint_positions"]), int)), int)
        if self.n_targets == 1 or not np.any(t):  # the tool point alone: positions only
            p, Jp, _, _ = self.tool(x, data["joint_positions"], jac, angular=False)
            return p, Jp
        p, Jp, R, Jw = self.tool(x, data["joint_positions"], jac)
        _, xe = self.split(x)
        off = np.vstack([np.zeros(3), xe.reshape(-1, 3)])[t]  # (n,3) in the tool frame
        w = np.einsum("nij,nj->ni", R, off)
        pt = p + w
        if not jac:
            return pt, None
        J = Jp - np.einsum("nij,njp->nip", skew(w), Jw)  # δ(R o) = δω × (R o)
        rows = np.flatnonzero(t > 0)
        for a in range(3):
            J[rows, :, self.n_kin + 3 * (t[rows] - 1) + a] = R[rows, :, a]
        return pt, J

    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        return self._predict(x, data, False)[0] - np.asarray(data["position"], float)

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        return self._predict(x, data, True)[1]

    def points(self, x: np.ndarray, data: Table):
        return self._predict(x, data, True)

    def initial_guess(self, data: Table) -> np.ndarray:
        """Nominal robot, registration by Kabsch (scipy) between the nominal tool points and the
        measured points: converges from any instrument placement."""
        return registered_start(self, data, np.asarray(data["position"], float))


def registered_start(model: Composed, data: Table, measured: np.ndarray) -> np.ndarray:
    """The nominal vector with the base frame set by the best rigid fit of the nominal tool
    points onto `measured` (needs ≥ 3 non-collinear points; otherwise the nominal)."""
    x = model.nominal()
    names = model.parameter_names()
    if not all(f"base.{k}" in names for k in ("x", "roll")):
        return x
    ib = names.index("base.x")
    x0 = x.copy()
    x0[ib:ib + 6] = 0.0
    p, *_ = model.tool(x0, data["joint_positions"])
    return with_registration(names, x, p, measured)


def with_registration(names: list[str], x: np.ndarray, p: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """`x` with ``base.*`` set by the best rigid fit (scipy, Kabsch) of points `p` (N, 3) predicted with
    an identity base onto `measured` (N, 3) m; `x` unchanged for fewer than 3 non-collinear points."""
    from scipy.spatial.transform import Rotation

    from pipeline.models.urdf import rpy_of

    if len(p) < 3 or np.linalg.matrix_rank(p - p.mean(0), tol=1e-6) < 2:
        return x
    rot, _ = Rotation.align_vectors(measured - measured.mean(0), p - p.mean(0))
    R = rot.as_matrix()
    ib = names.index("base.x")
    x = x.copy()
    x[ib:ib + 3] = measured.mean(0) - R @ p.mean(0)
    x[ib + 3:ib + 6] = rpy_of(R)
    return x
