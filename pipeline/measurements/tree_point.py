"""3-D points measured on several tips of a robot's tree, with the robot's static compliance.

Data columns: ``joint_positions`` (n, n_joints) rad/m (the read joints of `UrdfTree.joint_names`),
``position`` (n, 3) m in the instrument frame, ``target`` (n,) int: the tip the row measures (index
into `UrdfTree.tips`).  Residual: predicted − measured, (n, 3) m.  With physics terms, the gravity
load on every movable joint of the tree comes from the joint readings, the URDF's inertials and the
payload (`pipeline.physics.compliance.loads`: Pinocchio, computed once per set of readings).

Physics terms (parameters appended after the kinematics', rad/(N·m), nominal 0 = rigid):

* ``J.compliance``: joint J turns by c_J · τ_J (its axial gravity moment) — a joint's torsional
  compliance (the inverse of its stiffness, N·m/rad);
* ``J.lateral1``, ``J.lateral2``: joint J's child frame tilts by c · τ about each axis normal to
  J's axis (bearing and link bending), through the tree's lateral virtual joints;
* ``J.compliance_load`` (rad/(N·m)²): joint J's compliance changes with its load, c + h·|τ|, so it turns by
  c·τ + h·τ·|τ| — a gear that stiffens as its load grows (a harmonic drive: h < 0), to first order in h;
* errors of the readings (`pipeline.physics.encoder`, after the compliance terms): ``J.ecc_sin``,
  ``J.ecc_cos`` (rad), ``J.scale``, ``J.coupling`` (rad/rad) — the read joint J turns by
  a·sin q + b·cos q + s·q + κ·q_driver more than read, before the couplings are expanded; ``J.backlash``
  (rad) adds b·d/2, d the optional column ``approach`` (n, n_joints) −1/0/+1 (0 or absent: unknown).

The deflections enter the chain exactly (as joint values); the loads are evaluated at the
configuration given in the table (the readings to first order; `pipeline.physics.compliance`
re-evaluates them at the deflected configuration for static equilibrium).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from pipeline.identify.model import Table
from pipeline.measurements.composed import Composed
from pipeline.measurements.point import with_registration
from pipeline.models import chain as ch

COMPLIANCE_UNIT = "rad/(N·m)"
LOAD_UNIT = "rad/(N·m)²"  # a compliance's change per N·m of load
_SMALL: dict = {}  # (id of a model, its kept terms) → (that model, `TreePointModel.without`)


@dataclass(frozen=True)
class TreePointModel(Composed):
    """Points on the tips of a `UrdfTree` (see module docstring)."""

    compliant: tuple[str, ...] = ()  # joints with a torsional compliance parameter
    stiffening: tuple[str, ...] = ()  # joints with a load-dependent compliance (J.compliance_load)
    payload: tuple = ()  # ((mass kg, link, (x, y, z) m in the link frame), …) carried besides the URDF's links
    forced: bool = False  # True: the physics terms are always fitted (not left to the model selection)
    encoder: tuple[str, ...] = ()  # reading-error terms (`pipeline.physics.encoder`): J.ecc_sin, J.scale, …
    absent: tuple[str, ...] = ()  # families asked for that the data cannot carry (backlash: no motion direction)
    residual_dim = 3

    # ----- physics parameters ---------------------------------------------------------------
    def gravity_names(self) -> list[str]:
        """The compliance terms (rad/(N·m)), before the encoder terms in the parameter vector."""
        return [f"{j}.compliance" for j in self.compliant] + \
               [f"{j}.lateral{a}" for j in self.kin.lateral for a in (1, 2)] + \
               [f"{j}.compliance_load" for j in self.stiffening]

    def nonnegative(self) -> list[str]:
        """Terms no physical robot has negative: the compliances (a stiffness is positive).  `least_squares.fit`
        holds one estimated negative at 0 (refused) and refits the rest.  A load-dependent compliance may be
        negative (a joint that stiffens under load)."""
        return [n for n in self.gravity_names() if not n.endswith(".compliance_load")]

    def extra_names(self) -> list[str]:
        return self.gravity_names() + list(self.encoder)

    def extra_units(self) -> list[str]:
        from pipeline.physics.encoder import UNITS

        ng = len(self.gravity_names()) - len(self.stiffening)
        return [COMPLIANCE_UNIT] * ng + [LOAD_UNIT] * len(self.stiffening) + \
            [UNITS[n.rsplit(".", 1)[1]] for n in self.encoder]

    def extra_nominal(self) -> np.ndarray:
        return np.zeros(len(self.extra_names()))

    def extra_priority(self) -> np.ndarray:
        return np.ones(len(self.extra_names()), int)

    def groups(self) -> dict[str, list[str]]:
        g = dict(self.kin.groups())
        phys = {}
        if self.compliant:
            phys["joint compliance"] = [f"{j}.compliance" for j in self.compliant]
        if self.kin.lateral:
            phys["lateral compliance"] = [f"{j}.lateral{a}" for j in self.kin.lateral for a in (1, 2)]
        if self.stiffening:
            phys["load-dependent compliance"] = [f"{j}.compliance_load" for j in self.stiffening]
        if self.encoder:
            from pipeline.physics.encoder import GROUPS, family

            for n in self.encoder:
                phys.setdefault(GROUPS[family(n)], []).append(n)
        if self.forced:
            g["registration"] = g["registration"] + [n for v in phys.values() for n in v]
            return g
        return g | phys

    def late_groups(self) -> tuple[str, ...]:
        """The reading-error groups: offered to the model selection after the geometry and the compliance
        (`pipeline.identify.complexity`), so a reading error never displaces a geometric group.  Backlash is
        offered with the geometry: a play of a few mrad is a first-order error (a joint offset that flips
        with the direction of approach), and offered last it left the lateral compliance refused before it
        (held-out 0.260 mm against 0.217 mm offered first, `tests/test_physics_backlash.py`'s campaign)."""
        from pipeline.physics.encoder import GROUPS

        return () if self.forced else tuple(g for g in GROUPS.values() if g != "backlash")

    def without(self, names) -> "TreePointModel":
        """This model without the physics terms among `names` (a lateral joint's virtual joints only when both
        its terms go): at 0 they are no-ops, so the smaller model has the same residuals and the same
        Jacobian columns for every other parameter, with shorter chains and a narrower Jacobian
        (`pipeline.identify.least_squares.fit` fits terms held at 0 on it).  Self when none can go."""
        drop = set(names)
        compliant = tuple(j for j in self.compliant if f"{j}.compliance" not in drop)
        stiffening = tuple(j for j in self.stiffening if f"{j}.compliance_load" not in drop)
        lateral = tuple(j for j in self.kin.lateral if not {f"{j}.lateral1", f"{j}.lateral2"} <= drop)
        encoder = tuple(n for n in self.encoder if n not in drop)
        if (compliant, lateral, encoder, stiffening) == (self.compliant, self.kin.lateral, self.encoder,
                                                         self.stiffening):
            return self
        key = (id(self), compliant, lateral, encoder, stiffening)
        hit = _SMALL.get(key)
        if hit is not None and hit[0] is self:
            return hit[1]
        from dataclasses import replace

        kin = self.kin if lateral == self.kin.lateral else replace(self.kin, lateral=lateral)
        small = replace(self, kin=kin, compliant=compliant, encoder=encoder, stiffening=stiffening)
        if len(_SMALL) > 64:
            _SMALL.clear()
        _SMALL[key] = (self, small)
        return small

    # ----- evaluation ------------------------------------------------------------------------
    def deflected(self, x: np.ndarray, data: Table) -> np.ndarray:
        """Full joint matrix (n, J_all + 2·L) with the reading errors and compliant deflections added (rad)."""
        _, xe = self.split(x)
        q = data["joint_positions"]
        if self.encoder:
            from pipeline.physics.encoder import corrected

            q = corrected(self.kin, self.encoder, xe[len(self.gravity_names()):], q, data.get("approach"))
        qf = self.kin.expand(q)
        if not self.gravity_names():
            return qf
        col = {j.name: i for i, j in enumerate(self.kin.all_joints)}
        nc = len(self.compliant)
        load = self.load(data)
        ax = load.axial
        for i, j in enumerate(self.compliant):
            qf[:, col[j]] += xe[i] * ax[:, col[j]]
        lat = load.lateral
        nj = len(self.kin.all_joints)
        for i, j in enumerate(self.kin.lateral):
            for a in range(2):
                qf[:, nj + 2 * i + a] = xe[nc + 2 * i + a] * lat[:, col[j], a]
        ns = nc + 2 * len(self.kin.lateral)
        for i, j in enumerate(self.stiffening):
            qf[:, col[j]] += xe[ns + i] * ax[:, col[j]] * np.abs(ax[:, col[j]])
        return qf

    def load(self, data: Table):
        """Gravity load (`pipeline.physics.gravity.Load`) on every joint of the tree at the table's readings."""
        from pipeline.physics.compliance import loads

        return loads(self.kin, data["joint_positions"], self.payload)

    def _predict(self, x: np.ndarray, data: Table, jac: bool, free: np.ndarray | None = None):
        """Points (n, 3) and, with `jac`, d point / d x (n, 3, P) — or only the columns `free` ((P,) bool) holds,
        (n, 3, free.sum()): the same numbers, the others not computed."""
        xk, _ = self.split(x)
        qf = self.deflected(x, data)
        n = len(qf)
        tip = np.asarray(data.get("target", np.zeros(n, int)), int)
        P = len(self.parameter_names())
        cols = None if free is None else np.where(free, np.cumsum(free) - 1, -1)  # each parameter's column, −1 none
        W = P if free is None else int(np.sum(free))
        p = np.empty((n, 3))
        J = np.zeros((n, 3, W)) if jac else None
        col = {j.name: i for i, j in enumerate(self.kin.all_joints)}
        ne = len(self.extra_names())
        ext = np.arange(ne) if cols is None else np.flatnonzero(cols[self.n_kin:] >= 0)  # extra terms asked for
        dest = self.n_kin + ext if cols is None else cols[self.n_kin:][ext]
        kcols = None if cols is None else cols[:self.n_kin]
        if jac and self.encoder:
            from pipeline.physics.encoder import basis

            enc_B, enc_col = basis(self.kin, self.encoder, data["joint_positions"], data.get("approach"))
        for k in range(len(self.kin.descs)):
            rows = np.flatnonzero(tip == k)
            if rows.size == 0:
                continue
            c = self.kin.chain(k)
            if not jac:
                p[rows] = ch.forward(c, xk, qf[rows])[1]
                continue
            if not ne:
                p[rows], J[rows] = ch.jacobian(c, xk, qf[rows], width=W, columns=kcols)
                continue
            p[rows], Jk, Jq = ch.jacobians(c, xk, qf[rows], W, self._joint_columns, kcols)
            if ext.size:
                Jk[:, :, dest] = self._extra_columns(data, rows, Jq, enc_B if self.encoder else None,
                                                     enc_col if self.encoder else None, col)[:, :, ext]
            J[rows] = Jk
        return p, J

    def _extra_columns(self, data: Table, rows: np.ndarray, Jq: np.ndarray, enc_B, enc_col, col: dict) -> np.ndarray:
        """d point / d (physics terms) (len(rows), 3, n_extra) of the rows of one tip: through the joint
        columns Jq (d point / d full joint matrix) times each term's load or reading basis."""
        nj, nc = len(self.kin.all_joints), len(self.compliant)
        E = np.zeros((len(rows), 3, len(self.extra_names())))
        if self.encoder:  # d p / d reading through the couplings, times each term's basis
            Jr = Jq[:, :, :nj] @ self.kin.coupling_matrix()
            E[:, :, len(self.gravity_names()):] = Jr[:, :, enc_col] * enc_B[rows, None, :]
        if self.gravity_names():
            load = self.load(data)
            ax = load.axial[rows]
            ci = np.array([col[j] for j in self.compliant], int)  # every compliance column at once
            E[:, :, :nc] = Jq[:, :, ci] * ax[:, None, ci]
            li = np.array([col[j] for j in self.kin.lateral], int)
            nl = 2 * len(li)  # lateral virtual joint 2i + a ↔ parameter 2i + a, load (joint i, normal a)
            E[:, :, nc:nc + nl] = Jq[:, :, nj:nj + nl] * load.lateral[rows][:, li, :].reshape(len(rows), 1, nl)
            if self.stiffening:  # d p / d h = d p / d q_J · τ|τ|
                si = np.array([col[j] for j in self.stiffening], int)
                E[:, :, nc + nl:nc + nl + si.size] = Jq[:, :, si] * (ax[:, si] * np.abs(ax[:, si]))[:, None, :]
        return E

    def held_columns(self, x: np.ndarray, data: Table, names) -> np.ndarray:
        """d point / d term (n, 3, len(names)) of physics terms this model does not carry (`without` dropped
        them), held at 0: the columns the model with them has at x, the same numbers — a compliance,
        d point / d q_J times J's axial load; a lateral term, the turn about e1 or e2 after J's own (`ch.turns_after`)
        times its lateral load; a reading term, d point / d reading times its basis."""
        from pipeline.physics.encoder import basis
        from pipeline.physics.gravity import normals

        names = list(names)
        qf = self.deflected(x, data)
        xk = self.split(x)[0]
        n, nj = len(qf), len(self.kin.all_joints)
        tip = np.asarray(data.get("target", np.zeros(n, int)), int)
        col = {j.name: i for i, j in enumerate(self.kin.all_joints)}
        by = {j.name: j for j in self.kin.all_joints}
        split = [n.rsplit(".", 1) for n in names]
        enc = [i for i, (_, kind) in enumerate(split) if kind not in ("compliance", "compliance_load", "lateral1",
                                                                        "lateral2")]
        lat = [i for i, (_, kind) in enumerate(split) if kind in ("lateral1", "lateral2")]
        load = self.load(data) if len(enc) < len(names) else None
        if enc:
            B, bcol = basis(self.kin, tuple(names[i] for i in enc), data["joint_positions"], data.get("approach"))
        out = np.zeros((n, 3, len(names)))
        for k in range(len(self.kin.descs)):
            rows = np.flatnonzero(tip == k)
            if rows.size == 0:
                continue
            c = self.kin.chain(k)
            _, Jq = ch.joint_jacobian(c, xk, qf[rows])
            for i, (joint, kind) in enumerate(split):
                if kind in ("compliance", "compliance_load"):
                    tau = load.axial[rows][:, col[joint]]
                    out[rows, :, i] = Jq[:, :, col[joint]] * (tau if kind == "compliance" else tau * np.abs(tau))[:, None]
            if lat:
                steps = {int(c.joint[s]): s for s in np.flatnonzero(c.joint >= 0)}
                here = [i for i in lat if col[split[i][0]] in steps]
                if here:
                    axes = [normals(by[split[i][0]].axis)[int(split[i][1][-1]) - 1] for i in here]
                    T = ch.turns_after(c, xk, qf[rows], np.array([steps[col[split[i][0]]] for i in here]), axes)
                    for m, i in enumerate(here):
                        a = int(split[i][1][-1]) - 1
                        out[rows, :, i] = T[:, :, m] * load.lateral[rows][:, col[split[i][0]], a][:, None]
            if enc:
                Jr = Jq[:, :, :nj] @ self.kin.coupling_matrix()
                out[np.ix_(rows, [0, 1, 2], enc)] = Jr[:, :, bcol] * B[rows, None, :]
        return out

    @cached_property
    def _joint_columns(self) -> np.ndarray:
        """The full joint matrix's columns the physics terms act through (their d p / d q is needed)."""
        col = {j.name: i for i, j in enumerate(self.kin.all_joints)}
        nj = len(col)
        A = self.kin.coupling_matrix()
        read = {n: i for i, n in enumerate(self.kin.joint_names)}
        driven = {k for n in self.encoder for k in np.flatnonzero(A[:, read[n.rsplit(".", 1)[0]]])}
        return np.array(sorted({col[j] for j in self.compliant + self.stiffening}
                               | set(range(nj, nj + 2 * len(self.kin.lateral)))
                               | {int(k) for k in driven}), int)

    @cached_property
    def n_kin(self) -> int:
        return len(self.kin.parameter_names())

    def parameter_names(self) -> list[str]:
        return list(self._names)

    @cached_property
    def _names(self) -> tuple[str, ...]:
        return tuple(self.kin.parameter_names() + self.extra_names())

    def tool(self, x: np.ndarray, q: np.ndarray, jac: bool = True, angular: bool = True):
        """Tip 0's tool frame from readings `q` (rigid): for callers that draw or plan one tool."""
        xk, _ = self.split(x)
        c = self.kin.chain(0)
        qf = self.kin.expand(q)
        if not jac:
            R, p = ch.forward(c, xk, qf)
            return p, None, R, None
        width = len(self.parameter_names())
        if not angular:
            p, Jp = ch.jacobian(c, xk, qf, width=width)
            return p, Jp, None, None
        return ch.jacobian(c, xk, qf, angular=True, width=width)

    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        return self._predict(x, data, False)[0] - np.asarray(data["position"], float)

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        return self._predict(x, data, True)[1]

    def jacobian_columns(self, x: np.ndarray, data: Table, free: np.ndarray) -> np.ndarray:
        """`jacobian`'s columns where `free` ((P,) bool) holds, (n, 3, free.sum()), computing only those
        (a solver's step moves the free parameters only)."""
        return self._predict(x, data, True, np.asarray(free, bool))[1]

    def points(self, x: np.ndarray, data: Table):
        return self._predict(x, data, True)

    def initial_guess(self, data: Table) -> np.ndarray:
        """Nominal robot; registration by the best rigid fit of the nominal tip points onto the measured."""
        x = self.nominal()
        p = self._predict(np.where(np.char.startswith(np.array(self.parameter_names()), "base."), 0.0, x), data,
                          False)[0]
        return with_registration(self.parameter_names(), x, p, np.asarray(data["position"], float))

    def exports(self, x: np.ndarray, std: np.ndarray | None = None, free: np.ndarray | None = None) -> dict[str, str]:
        """model.urdf (geometry) and, with physics terms, model.physics.yaml (what URDF cannot carry), each
        term with its 1σ when `std` (per parameter) is given."""
        out = {"model.urdf": self.kin.urdf_text(self.split(x)[0])}
        if self.extra_names() or self.absent:
            from pipeline.physics.compliance import to_yaml

            out["model.physics.yaml"] = to_yaml(self._physics(x, std, free))
        return out

    def describe(self, x: np.ndarray, std: np.ndarray | None = None, free: np.ndarray | None = None) -> dict:
        d = super().describe(x)
        if self.extra_names() or self.absent:
            d["physics"] = self._physics(x, std, free)
        return d

    def _physics(self, x, std, free) -> dict:
        from pipeline.physics.compliance import document

        P = len(self.parameter_names())
        ok = lambda a: a is not None and np.size(a) == P  # noqa: E731
        return document(self, x, np.asarray(std, float) if ok(std) else None,
                        np.asarray(free, bool) if ok(free) else None)


__all__ = ["TreePointModel", "COMPLIANCE_UNIT", "LOAD_UNIT"]
