"""The error model of a URDF chain: a `RobotDescription` plus its identification parameters.

Parameters (SI), in this order:

* ``base.x, base.y, base.z, base.roll, base.pitch, base.yaw``: the instrument / world frame →
  root link transform, ``Trans · Rz(yaw) · Ry(pitch) · Rx(roll)`` (URDF rpy convention);
* per movable joint ``J``: ``J.x, J.y, J.z`` (its origin's translation, absolute, as in the
  URDF), ``J.rx, J.ry, J.rz`` (a small rotation error after the origin's nominal rotation:
  ``R_nominal · Rx · Ry · Rz``; 0 nominally, so no Euler singularity at the URDF's own angles)
  and, for revolute and continuous joints, ``J.offset`` (added to the joint reading);
* ``tool.x … tool.yaw``: tip link → tool point / tool frame, same form as the base.

Fixed joints of the chain are constant transforms.  The chain is a `pipeline.models.chain.Chain`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from pipeline.models import chain as ch
from pipeline.models.chain import CONST, ROT, TRANS, Chain, unit
from pipeline.models.urdf import RobotDescription, matrix_of_rpy, write_calibrated

FRAME_KEYS = ("x", "y", "z", "roll", "pitch", "yaw")
JOINT_KEYS = ("x", "y", "z", "rx", "ry", "rz", "offset")
_ANGLES = {"roll", "pitch", "yaw", "rx", "ry", "rz", "offset"}


def _frame_steps(o: int) -> list[tuple]:
    """Trans x,y,z then Rz(yaw) Ry(pitch) Rx(roll): parameters o..o+5 in FRAME_KEYS order."""
    return [(TRANS, unit(0), o, -1), (TRANS, unit(1), o + 1, -1), (TRANS, unit(2), o + 2, -1),
            (ROT, unit(2), o + 5, -1), (ROT, unit(1), o + 4, -1), (ROT, unit(0), o + 3, -1)]


def frame_matrix(v: np.ndarray) -> np.ndarray:
    """4×4 of a (x, y, z, roll, pitch, yaw) frame."""
    T = np.eye(4)
    T[:3, :3] = matrix_of_rpy(v[3], v[4], v[5])
    T[:3, 3] = v[:3]
    return T


_CHAINS: dict = {}


@dataclass(frozen=True)
class UrdfArm:
    """A URDF chain and a parameter vector (`vector()`; `with_vector` gives a new arm)."""

    desc: RobotDescription
    values: tuple[float, ...] = field(default=())  # empty: the URDF's nominal values

    # ----- parameters --------------------------------------------------------------
    def _joint_keys(self, j) -> tuple[str, ...]:
        return JOINT_KEYS if j.type in ("revolute", "continuous") else JOINT_KEYS[:-1]

    def parameter_names(self) -> list[str]:
        names = [f"base.{k}" for k in FRAME_KEYS]
        for j in self.desc.movable:
            names += [f"{j.name}.{k}" for k in self._joint_keys(j)]
        return names + [f"tool.{k}" for k in FRAME_KEYS]

    def parameter_units(self) -> list[str]:
        return ["rad" if n.rsplit(".", 1)[1] in _ANGLES else "m" for n in self.parameter_names()]

    def nominal_vector(self) -> np.ndarray:
        v = [0.0] * 6
        for j in self.desc.movable:
            v += list(np.asarray(j.origin)[:3, 3]) + [0.0] * (len(self._joint_keys(j)) - 3)
        return np.asarray(v + [0.0] * 6, float)

    def vector(self) -> np.ndarray:
        return np.asarray(self.values, float) if self.values else self.nominal_vector()

    def with_vector(self, x: np.ndarray) -> "UrdfArm":
        x = np.asarray(x, float)
        if x.shape != (len(self.parameter_names()),):
            raise ValueError(f"parameter vector has shape {x.shape}, expected ({len(self.parameter_names())},)")
        return replace(self, values=tuple(float(v) for v in x))

    @property
    def n_joints(self) -> int:
        return len(self.desc.movable)

    @property
    def joint_names(self) -> list[str]:
        return self.desc.joint_names

    @property
    def lower(self) -> np.ndarray:
        return np.array([j.lower for j in self.desc.movable])

    @property
    def upper(self) -> np.ndarray:
        return np.array([j.upper for j in self.desc.movable])

    def groups(self) -> dict[str, list[str]]:
        """Parameter groups for model-complexity selection (registration is always fitted)."""
        g: dict[str, list[str]] = {"registration": [f"base.{k}" for k in FRAME_KEYS] + [f"tool.{k}" for k in FRAME_KEYS],
                                   "joint offsets": [], "origin translations": [], "origin rotations": []}
        for j in self.desc.movable:
            for k in self._joint_keys(j):
                key = "joint offsets" if k == "offset" else "origin translations" if k in "xyz" else "origin rotations"
                g[key].append(f"{j.name}.{k}")
        return g

    def priority(self) -> np.ndarray:
        """Rank-test levels: registration first, then offsets and origin translations, then origin
        rotation errors, tool orientation last."""
        def level(n: str) -> int:
            head, k = n.rsplit(".", 1)
            if head == "tool":
                return 0 if k in "xyz" else 3
            if head == "base":
                return 0
            return 2 if k in ("rx", "ry", "rz") else 1
        return np.array([level(n) for n in self.parameter_names()])

    # ----- the chain -----------------------------------------------------------------
    def chain(self) -> Chain:
        hit = _CHAINS.get(id(self.desc))
        if hit is not None and hit[0] is self.desc:
            return hit[1]
        steps = _frame_steps(0)
        o, ji = 6, 0
        for j in self.desc.joints:
            T = np.asarray(j.origin, float)
            if not j.movable:
                steps.append((CONST, T))
                continue
            R = np.eye(4)
            R[:3, :3] = T[:3, :3]
            steps += [(TRANS, unit(0), o, -1), (TRANS, unit(1), o + 1, -1), (TRANS, unit(2), o + 2, -1), (CONST, R),
                      (ROT, unit(0), o + 3, -1), (ROT, unit(1), o + 4, -1), (ROT, unit(2), o + 5, -1)]
            if j.type == "prismatic":
                steps.append((TRANS, np.asarray(j.axis), -1, ji))
                o += 6
            else:
                steps.append((ROT, np.asarray(j.axis), o + 6, ji))
                o += 7
            ji += 1
        steps += _frame_steps(o)
        c = Chain.build(steps, o + 6, ji)
        if len(_CHAINS) > 64:
            _CHAINS.clear()
        _CHAINS[id(self.desc)] = (self.desc, c)
        return c

    def forward(self, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tool frame rotations (N,3,3) and positions (N,3) m in the instrument frame."""
        return ch.forward(self.chain(), x, q)

    # ----- the calibrated robot --------------------------------------------------------
    def joint_origins(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Each movable joint's calibrated origin (4×4), its offset folded in."""
        names = self.parameter_names()
        out = {}
        for j in self.desc.movable:
            v = {k: float(x[names.index(f"{j.name}.{k}")]) for k in self._joint_keys(j)}
            T = np.eye(4)
            T[:3, 3] = (v["x"], v["y"], v["z"])
            from scipy.spatial.transform import Rotation
            R = np.asarray(j.origin, float)[:3, :3] @ Rotation.from_euler("XYZ", [v["rx"], v["ry"], v["rz"]]).as_matrix()
            if "offset" in v:  # Rot(axis, q + θ0) = Rot(axis, θ0) · Rot(axis, q): fold θ0 into the origin
                R = R @ Rotation.from_rotvec(np.asarray(j.axis) * v["offset"]).as_matrix()
            T[:3, :3] = R
            out[j.name] = T
        return out

    def frames_of(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        names = self.parameter_names()
        b = np.array([x[names.index(f"base.{k}")] for k in FRAME_KEYS])
        t = np.array([x[names.index(f"tool.{k}")] for k in FRAME_KEYS])
        return frame_matrix(b), frame_matrix(t)

    def urdf_text(self, x: np.ndarray) -> str:
        """The calibrated URDF: joint origins replaced, instrument → root and tip → tool frames added."""
        base, tool = self.frames_of(np.asarray(x, float))
        return write_calibrated(self.desc, self.joint_origins(np.asarray(x, float)), base, tool)

    def ros_files(self, x: np.ndarray) -> dict[str, str]:
        """Files ROS stacks load (`pipeline.models.ros_exports`): the calibrated model.urdf, the
        robot_calibration-style calibrated_parameters.yaml and, for a Universal Robots arm, the
        controller's ur_calibration.yaml."""
        from pipeline.models.ros_exports import offsets_yaml, ur_calibration_yaml

        x = np.asarray(x, float)
        files = {"model.urdf": self.urdf_text(x), "calibrated_parameters.yaml": offsets_yaml(self, x)}
        ur = ur_calibration_yaml(self.joint_names, self.joint_origins(x))
        if ur is not None:
            files["ur_calibration.yaml"] = ur
        return files

    def to_dict(self, x: np.ndarray | None = None) -> dict:
        x = self.vector() if x is None else np.asarray(x, float)
        names = self.parameter_names()
        return {"kind": "urdf_chain", "name": self.desc.name, "root": self.desc.root, "tip": self.desc.tip,
                "units": {"length": "m", "angle": "rad"},
                "joint_names": self.joint_names,
                "parameters": {n: float(v) for n, v in zip(names, x)}}

    def link_frames(self, x: np.ndarray, q: np.ndarray) -> tuple[list[str], np.ndarray]:
        """Every frame of the chain at joint readings q (N, n_joints), in the instrument frame:
        names [root link, each joint's child link (fixed joints included), "tool"] and poses
        (N, len(names), 4, 4), m.  For drawing the robot; the last pose equals `forward`'s."""
        names, marks, s = [self.desc.root], [5], 5  # the 6 base steps end at index 5
        for j in self.desc.joints:
            s += 8 if j.movable else 1  # movable: x, y, z, nominal R, rx, ry, rz, the joint
            names.append(j.child)
            marks.append(s)
        c = self.chain()
        return names + ["tool"], ch.frames(c, np.asarray(x, float), np.atleast_2d(q), marks + [c.n_steps - 1])
