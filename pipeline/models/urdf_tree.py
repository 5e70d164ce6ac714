"""The error model of a URDF robot's tree: several tips, coupled joints, one parameter vector.

A whole robot is measured at several points at once (two hands, a head): each tip is the end of a
chain root → tip (`pipeline.models.chain.Chain`), and the chains share every joint they have in
common (a torso), so one parameter vector describes the robot.  Parameters (SI), in this order:

* ``base.x … base.yaw``: instrument → root link, as in `pipeline.models.urdf_arm`;
* per movable joint of the tree (each joint once, in order of first appearance root → tips):
  ``J.x, J.y, J.z, J.rx, J.ry, J.rz`` and, for revolute joints, ``J.offset`` — as in `UrdfArm`;
* per tip: ``tool.*`` for one tip, ``tool.<tip>.*`` for several (tip link → tool point/frame).

**Coupled joints** are driven by others: q_c = Σ_k a_k · q_k (rad), given as `coupled` or read from
the URDF's `<mimic>` (q = multiplier · q_other + offset).  They are not in the joint readings
(`joint_names`); `expand` computes them.  Their own origin and offset parameters stay in the model:
the rank test of identification decides what the data can tell apart.

**Lateral virtual joints** (for the physics terms of `pipeline.physics`): a joint listed in `lateral`
gets two extra rotation steps after its own turn, about the two axes e1, e2 normal to its axis
(`pipeline.physics.gravity.normals`, in the joint's frame), whose values are extra columns of the
full joint matrix (0 for a rigid robot).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from pipeline.models import chain as ch
from pipeline.models.chain import CONST, ROT, TRANS, Chain, unit
from pipeline.models.urdf import RobotDescription, UrdfJoint, write_calibrated
from pipeline.models.urdf_arm import FRAME_KEYS, JOINT_KEYS, _ANGLES, _frame_steps, frame_matrix

_CHAINS: dict = {}


@dataclass(frozen=True)
class UrdfTree:
    """Chains root → tip sharing one parameter vector (see module docstring)."""

    descs: tuple[RobotDescription, ...]
    coupled: tuple = ()  # ((joint, ((other, factor), …), offset), …)
    lateral: tuple[str, ...] = ()
    values: tuple[float, ...] = field(default=())

    # ----- structure -------------------------------------------------------------------
    @property
    def tips(self) -> list[str]:
        return [d.tip for d in self.descs]

    @property
    def root(self) -> str:
        return self.descs[0].root

    @property
    def urdf(self) -> str:
        return self.descs[0].urdf

    @property
    def name(self) -> str:
        return self.descs[0].name

    @cached_property
    def all_joints(self) -> list[UrdfJoint]:
        """Every movable joint of the tree's chains, once, in order of first appearance."""
        seen: dict[str, UrdfJoint] = {}
        for d in self.descs:
            for j in d.movable:
                seen.setdefault(j.name, j)
        return list(seen.values())

    @cached_property
    def coupling(self) -> dict[str, tuple[dict[str, float], float]]:
        return {c: (dict(terms), float(off)) for c, terms, off in self.coupled}

    @cached_property
    def joint_names(self) -> list[str]:
        """The joints read in a recording: every movable joint but the coupled ones."""
        cp = self.coupling
        return [j.name for j in self.all_joints if j.name not in cp]

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def lower(self) -> np.ndarray:
        by = {j.name: j for j in self.all_joints}
        return np.array([by[n].lower for n in self.joint_names])

    @property
    def upper(self) -> np.ndarray:
        by = {j.name: j for j in self.all_joints}
        return np.array([by[n].upper for n in self.joint_names])

    def expand(self, q: np.ndarray) -> np.ndarray:
        """Full joint matrix (n, J_all [+ 2 per lateral joint, zero]) from readings (n, n_joints)."""
        q = np.atleast_2d(np.asarray(q, float))
        col = {n: i for i, n in enumerate(self.joint_names)}
        cp = self.coupling
        out = np.zeros((q.shape[0], len(self.all_joints) + 2 * len(self.lateral)))
        for k, j in enumerate(self.all_joints):
            if j.name in cp:
                terms, off = cp[j.name]
                out[:, k] = off + sum(f * q[:, col[o]] for o, f in terms.items())
            else:
                out[:, k] = q[:, col[j.name]]
        return out

    def coupling_matrix(self) -> np.ndarray:
        """d q_full / d q_read, (J_all, n_joints)."""
        return self._coupling_matrix.copy()

    @cached_property
    def _coupling_matrix(self) -> np.ndarray:
        col = {n: i for i, n in enumerate(self.joint_names)}
        cp = self.coupling
        A = np.zeros((len(self.all_joints), self.n_joints))
        for k, j in enumerate(self.all_joints):
            if j.name in cp:
                for o, f in cp[j.name][0].items():
                    A[k, col[o]] = f
            else:
                A[k, col[j.name]] = 1.0
        return A

    # ----- parameters --------------------------------------------------------------------
    @staticmethod
    def _joint_keys(j: UrdfJoint) -> tuple[str, ...]:
        return JOINT_KEYS if j.type in ("revolute", "continuous") else JOINT_KEYS[:-1]

    def tool_prefix(self, k: int) -> str:
        return "tool" if len(self.descs) == 1 else f"tool.{self.descs[k].tip}"

    def parameter_names(self) -> list[str]:
        return list(self._parameter_names)

    @cached_property
    def _parameter_names(self) -> tuple[str, ...]:
        names = [f"base.{k}" for k in FRAME_KEYS]
        for j in self.all_joints:
            names += [f"{j.name}.{k}" for k in self._joint_keys(j)]
        for k in range(len(self.descs)):
            names += [f"{self.tool_prefix(k)}.{a}" for a in FRAME_KEYS]
        return tuple(names)

    def parameter_units(self) -> list[str]:
        return ["rad" if n.rsplit(".", 1)[1] in _ANGLES else "m" for n in self.parameter_names()]

    def nominal_vector(self) -> np.ndarray:
        v = [0.0] * 6
        for j in self.all_joints:
            v += list(np.asarray(j.origin)[:3, 3]) + [0.0] * (len(self._joint_keys(j)) - 3)
        return np.asarray(v + [0.0] * 6 * len(self.descs), float)

    def vector(self) -> np.ndarray:
        return np.asarray(self.values, float) if self.values else self.nominal_vector()

    def with_vector(self, x: np.ndarray) -> "UrdfTree":
        x = np.asarray(x, float)
        if x.shape != (len(self.parameter_names()),):
            raise ValueError(f"parameter vector has shape {x.shape}, expected ({len(self.parameter_names())},)")
        return replace(self, values=tuple(float(v) for v in x))

    def groups(self) -> dict[str, list[str]]:
        """Parameter groups for model selection (registration: base and every tool frame)."""
        tools = [n for n in self.parameter_names() if n.startswith("tool.")]
        g: dict[str, list[str]] = {"registration": [f"base.{k}" for k in FRAME_KEYS] + tools,
                                   "joint offsets": [], "origin translations": [], "origin rotations": []}
        for j in self.all_joints:
            for k in self._joint_keys(j):
                key = "joint offsets" if k == "offset" else "origin translations" if k in "xyz" else "origin rotations"
                g[key].append(f"{j.name}.{k}")
        return g

    def priority(self) -> np.ndarray:
        def level(n: str) -> int:
            head, k = n.rsplit(".", 1)
            if head.startswith("tool"):
                return 0 if k in "xyz" else 3
            if head == "base":
                return 0
            return 2 if k in ("rx", "ry", "rz") else 1
        return np.array([level(n) for n in self.parameter_names()])

    # ----- chains ------------------------------------------------------------------------
    def chain(self, k: int = 0) -> Chain:
        """The chain root → tip k over the whole parameter vector and the full joint matrix."""
        key = (id(self.descs), self.coupled, self.lateral, k)
        hit = _CHAINS.get(key)
        if hit is not None and hit[0] is self.descs:
            return hit[1]
        names = self.parameter_names()
        index = {n: i for i, n in enumerate(names)}
        jcol = {j.name: i for i, j in enumerate(self.all_joints)}
        nj = len(self.all_joints)
        steps = _frame_steps(0)
        for j in self.descs[k].joints:
            T = np.asarray(j.origin, float)
            if not j.movable:
                steps.append((CONST, T))
                continue
            o = index[f"{j.name}.x"]
            R = np.eye(4)
            R[:3, :3] = T[:3, :3]
            steps += [(TRANS, unit(0), o, -1), (TRANS, unit(1), o + 1, -1), (TRANS, unit(2), o + 2, -1), (CONST, R),
                      (ROT, unit(0), o + 3, -1), (ROT, unit(1), o + 4, -1), (ROT, unit(2), o + 5, -1)]
            if j.type == "prismatic":
                steps.append((TRANS, np.asarray(j.axis), -1, jcol[j.name]))
            else:
                steps.append((ROT, np.asarray(j.axis), o + 6, jcol[j.name]))
            if j.name in self.lateral:
                from pipeline.physics.gravity import normals

                e = normals(j.axis)
                v = nj + 2 * self.lateral.index(j.name)
                steps += [(ROT, e[0], -1, v), (ROT, e[1], -1, v + 1)]
        o = index[f"{self.tool_prefix(k)}.x"]
        steps += _frame_steps(o)
        c = Chain.build(steps, len(names), nj + 2 * len(self.lateral))
        if len(_CHAINS) > 64:
            _CHAINS.clear()
        _CHAINS[key] = (self.descs, c)
        return c

    def link_frames(self, x: np.ndarray, q: np.ndarray, k: int = 0) -> tuple[list[str], np.ndarray]:
        """Every frame of the chain root → tip k at readings q (N, n_joints), in the instrument frame (rigid,
        as `UrdfArm.link_frames`): names [root, each joint's child link, "tool"] and poses (N, F, 4, 4), m."""
        names, marks, s = [self.root], [5], 5  # the 6 base steps end at index 5
        for j in self.descs[k].joints:
            s += (8 + 2 * (j.name in self.lateral)) if j.movable else 1
            names.append(j.child)
            marks.append(s)
        c = self.chain(k)
        return names + ["tool"], ch.frames(c, np.asarray(x, float)[:c.n_params], self.expand(q), marks + [c.n_steps - 1])

    def forward(self, x: np.ndarray, q: np.ndarray, k: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Tool frame k: rotations (N,3,3) and positions (N,3) m in the instrument frame, from readings."""
        return ch.forward(self.chain(k), x, self.expand(q))

    # ----- the calibrated robot ----------------------------------------------------------------
    def joint_origins(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Each movable joint's calibrated origin (4×4), its offset folded in."""
        from scipy.spatial.transform import Rotation

        names = self.parameter_names()
        out = {}
        for j in self.all_joints:
            v = {k: float(x[names.index(f"{j.name}.{k}")]) for k in self._joint_keys(j)}
            T = np.eye(4)
            T[:3, 3] = (v["x"], v["y"], v["z"])
            R = np.asarray(j.origin, float)[:3, :3] @ Rotation.from_euler("XYZ", [v["rx"], v["ry"], v["rz"]]).as_matrix()
            if "offset" in v:
                R = R @ Rotation.from_rotvec(np.asarray(j.axis) * v["offset"]).as_matrix()
            T[:3, :3] = R
            out[j.name] = T
        return out

    def frames_of(self, x: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """Instrument → root (4×4) and each tip → tool (4×4)."""
        names = self.parameter_names()
        b = np.array([x[names.index(f"base.{k}")] for k in FRAME_KEYS])
        tools = [frame_matrix(np.array([x[names.index(f"{self.tool_prefix(k)}.{a}")] for a in FRAME_KEYS]))
                 for k in range(len(self.descs))]
        return frame_matrix(b), tools

    def urdf_text(self, x: np.ndarray) -> str:
        """The calibrated URDF: joint origins replaced, the instrument frame and one tool link per tip added."""
        x = np.asarray(x, float)
        base, tools = self.frames_of(x)
        text = write_calibrated(self.descs[0], self.joint_origins(x), base, tools[0],
                                tool_link="robocal_tool" if len(self.descs) == 1 else f"robocal_tool_{self.tips[0]}")
        for k in range(1, len(self.descs)):
            d = replace(self.descs[k], urdf=text)
            text = write_calibrated(d, {}, None, tools[k], tool_link=f"robocal_tool_{self.tips[k]}")
        return text

    def to_dict(self, x: np.ndarray | None = None) -> dict:
        x = self.vector() if x is None else np.asarray(x, float)
        return {"kind": "urdf_tree", "name": self.name, "root": self.root, "tips": self.tips,
                "units": {"length": "m", "angle": "rad"}, "joint_names": self.joint_names,
                "coupled": {c: {"terms": t, "offset": o} for c, (t, o) in self.coupling.items()},
                "parameters": {n: float(v) for n, v in zip(self.parameter_names(), x)}}
