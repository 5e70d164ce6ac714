"""Point coincidence: every contact of a group puts the tool point on the same unknown fixed point
(a ball in a socket, a sphere in a cone — MUKCa's self-calibration).

Data columns: ``joint_positions`` and ``group`` (n,) int.  Parameters: each group's point
``point.<name>.x/y/z`` (m, robot base frame).  Residual (n,3): tool point − its group's point.
Optional known distances between group points add one residual row each (``kind`` = 1 rows:
``group``, ``group_b``, ``distance``; residual |P_a − P_b| − distance in the first component).
The base frame cannot be told apart from the points: it ranks last and is held at nominal.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.identify.model import Table
from pipeline.measurements.composed import Composed


@dataclass(frozen=True)
class CoincidenceModel(Composed):
    groups_: tuple[str, ...] = field(default_factory=tuple)
    start: tuple[tuple[float, float, float], ...] = field(default_factory=tuple)
    # as for planes: a free tool point can sit where no joint moves it.  None: not said (held known, unless the
    # model choice's left-out groups free it: `shrinkage_groups`); True / False: the campaign's explicit setting
    fit_tool: bool | None = None

    residual_dim = 3
    fixes_frame = False  # the groups' points take up any rigid motion: accuracy is relative (`accuracy.propagate`)

    def extra_names(self) -> list[str]:
        return [f"point.{g}.{a}" for g in self.groups_ for a in "xyz"]

    def extra_units(self) -> list[str]:
        return ["m"] * len(self.extra_names())

    def extra_nominal(self) -> np.ndarray:
        if self.start:
            return np.asarray(self.start, float).ravel()
        return np.zeros(3 * len(self.groups_))

    def priority(self) -> np.ndarray:
        pr = super().priority()
        names = self.parameter_names()
        return np.array([4 if n.startswith("base.") else v for n, v in zip(names, pr)])

    def _split_rows(self, data: Table):
        kind = np.asarray(data.get("kind", np.zeros(len(data["group"]), int)), int)
        return kind == 0, kind == 1

    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        touch, dist = self._split_rows(data)
        _, xe = self.split(x)
        P = xe.reshape(-1, 3)
        g = np.asarray(data["group"], int)
        p, *_ = self.tool(x, data["joint_positions"], jac=False)
        r = np.zeros((len(g), 3))
        r[touch] = p[touch] - P[g[touch]]
        if dist.any():
            gb = np.asarray(data["group_b"], int)
            r[dist, 0] = np.linalg.norm(P[g[dist]] - P[gb[dist]], axis=1) - np.asarray(data["distance"], float)[dist]
        return r

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        touch, dist = self._split_rows(data)
        _, xe = self.split(x)
        P = xe.reshape(-1, 3)
        g = np.asarray(data["group"], int)
        _, Jp, *_ = self.tool(x, data["joint_positions"], angular=False)
        J = np.where(touch[:, None, None], Jp, 0.0)
        rows = np.flatnonzero(touch)
        for a in range(3):
            J[rows, a, self.n_kin + 3 * g[rows] + a] = -1.0
        if dist.any():
            gb = np.asarray(data["group_b"], int)
            for i in np.flatnonzero(dist):
                dv = P[g[i]] - P[gb[i]]
                u = dv / max(np.linalg.norm(dv), 1e-12)
                J[i, 0, self.n_kin + 3 * g[i]:self.n_kin + 3 * g[i] + 3] += u
                J[i, 0, self.n_kin + 3 * gb[i]:self.n_kin + 3 * gb[i] + 3] -= u
        return J

    def initial_guess(self, data: Table) -> np.ndarray:
        """Each group's point starts at the mean nominal tool point of its contacts."""
        x = self.nominal()
        touch, _ = self._split_rows(data)
        p, *_ = self.tool(x, data["joint_positions"])
        g = np.asarray(data["group"], int)
        for k in range(len(self.groups_)):
            m = touch & (g == k)
            if m.any():
                x[self.n_kin + 3 * k:self.n_kin + 3 * k + 3] = p[m].mean(0)
        return x
