"""Plane contacts: the tool point touches a plane.  One residual per contact: n·p − d (m).

Data columns: ``joint_positions`` and ``plane`` (n,) int, the index of the plane touched.
Each plane is known (normal and offset given, e.g. a machined jig face: seed 000's touch jig)
or unknown (its tilt and offset estimated: ``plane.<id>.a``, ``.b`` rotate the nominal normal
about two perpendicular axes, ``plane.<id>.d`` is the offset along it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.identify.model import Table
from pipeline.measurements.composed import Composed


@dataclass(frozen=True)
class Plane:
    name: str
    normal: tuple[float, float, float]
    offset: float
    known: bool = True


def _perp(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


@dataclass(frozen=True)
class PlaneModel(Composed):
    planes: tuple[Plane, ...] = field(default_factory=tuple)
    # a tool point free to move can collapse onto a point the joints cannot move.  None: not said (held known,
    # unless the model choice's left-out groups free it: `shrinkage_groups`); True / False: the campaign's setting
    fit_tool: bool | None = None

    residual_dim = 1

    def _unknown(self) -> list[int]:
        return [i for i, pl in enumerate(self.planes) if not pl.known]

    def extra_names(self) -> list[str]:
        return [f"plane.{self.planes[i].name}.{k}" for i in self._unknown() for k in "abd"]

    def extra_units(self) -> list[str]:
        return ["rad", "rad", "m"] * len(self._unknown())

    def extra_nominal(self) -> np.ndarray:
        return np.array([v for i in self._unknown() for v in (0.0, 0.0, self.planes[i].offset)], float)

    def _geometry(self, x: np.ndarray):
        """Unit normals (k,3), offsets (k,), and for unknown planes dn/da, dn/db (k,3)."""
        _, xe = self.split(x)
        N = np.array([pl.normal for pl in self.planes], float)
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        d = np.array([pl.offset for pl in self.planes], float)
        dA, dB = np.zeros_like(N), np.zeros_like(N)
        for k, i in enumerate(self._unknown()):
            a, b, d[i] = xe[3 * k:3 * k + 3]
            u, v = _perp(N[i])
            m = N[i] + a * u + b * v
            nm = np.linalg.norm(m)
            n = m / nm
            P = (np.eye(3) - np.outer(n, n)) / nm
            N[i], dA[i], dB[i] = n, P @ u, P @ v
        return N, d, dA, dB

    def row_planes(self, x: np.ndarray, data: Table):
        """Per contact: unit normal (n,3), offset (n,), and the plane's index among the unknown
        planes (−1 for a known plane) with dn/da, dn/db (n,3) for those rows."""
        N, d, dA, dB = self._geometry(x)
        k = np.asarray(data["plane"], int)
        which = np.full(len(self.planes), -1)
        which[self._unknown()] = np.arange(len(self._unknown()))
        return N[k], d[k], which[k], dA[k], dB[k]

    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        p, *_ = self.tool(x, data["joint_positions"], jac=False)
        n, d, *_ = self.row_planes(x, data)
        return (np.einsum("ni,ni->n", n, p) - d)[:, None]

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        p, Jp, *_ = self.tool(x, data["joint_positions"], angular=False)
        n, _, u, dA, dB = self.row_planes(x, data)
        J = np.einsum("ni,nip->np", n, Jp)
        rows = np.flatnonzero(u >= 0)
        if rows.size:
            col = self.n_kin + 3 * u[rows]
            J[rows, col] = np.einsum("ni,ni->n", p[rows], dA[rows])
            J[rows, col + 1] = np.einsum("ni,ni->n", p[rows], dB[rows])
            J[rows, col + 2] = -1.0
        return J[:, None, :]
