"""Serial arm kinematic model of seed 000 (Borm): base + Hayati-extended D-H joints + tool.

Chain, jig frame {W} to tool tip {E} (seed eqs. 1-5)::

    W_T_E = Trans(bx,by,bz) Rz Rx Ry                           (base, eq. 2)
          · Π_i Rz(q_i + theta_offset_i) Trans(a_i,0,d_i) Rx(alpha_i) Ry(beta_i)   (eq. 4)
          · Trans(tx,ty,tz) Rz Ry Rx                            (tool, eq. 5)

Model (the description, a frozen dataclass that round-trips the robot model JSON) is kept
apart from what is computed from it (`forward`, `tip_jacobian`: pure functions of a
parameter vector and joint angles).  Parameter vector order: base x,y,z,rz,rx,ry; per joint
theta_offset,d,a,alpha,beta; tool x,y,z,rz,ry,rx — 12 + 5·n entries, SI units.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cache
from typing import Any

import numpy as np

from pipeline.models import chain
from pipeline.models.chain import ROT as ROT_, TRANS, Chain, unit
from pipeline.models.transforms import AXES

BASE_KEYS = ("x", "y", "z", "rz", "rx", "ry")
JOINT_KEYS = ("theta_offset", "d", "a", "alpha", "beta")
TOOL_KEYS = ("x", "y", "z", "rz", "ry", "rx")
_ANGLE_KEYS = {"rz", "rx", "ry", "theta_offset", "alpha", "beta"}


@dataclass(frozen=True)
class Joint:
    """One revolute joint: geometry (m, rad) and travel limits (rad)."""

    name: str
    theta_offset: float = 0.0
    d: float = 0.0
    a: float = 0.0
    alpha: float = 0.0
    beta: float = 0.0
    lower: float = -np.pi
    upper: float = np.pi


@dataclass(frozen=True)
class LinkMass:
    """Lumped mass carried by a joint's link, for gravity-compliance models (kg, m in link frame)."""

    joint: int
    mass: float
    com: tuple[float, float, float]


@dataclass(frozen=True)
class SerialArm:
    """Description of a serial arm; `vector()` gives its identification parameters."""

    name: str
    base: dict[str, float]
    joints: tuple[Joint, ...]
    tool: dict[str, float]
    masses: tuple[LinkMass, ...] = field(default_factory=tuple)
    payload_kg: float = 0.0

    # ----- parameter vector ---------------------------------------------------------
    @property
    def n_joints(self) -> int:
        return len(self.joints)

    def parameter_names(self) -> list[str]:
        names = [f"base.{k}" for k in BASE_KEYS]
        for j in self.joints:
            names += [f"{j.name}.{k}" for k in JOINT_KEYS]
        names += [f"tool.{k}" for k in TOOL_KEYS]
        return names

    def parameter_units(self) -> list[str]:
        return ["rad" if n.split(".")[-1] in _ANGLE_KEYS else "m" for n in self.parameter_names()]

    def vector(self) -> np.ndarray:
        v = [self.base[k] for k in BASE_KEYS]
        for j in self.joints:
            v += [getattr(j, k) for k in JOINT_KEYS]
        v += [self.tool[k] for k in TOOL_KEYS]
        return np.asarray(v, dtype=float)

    def with_vector(self, x: np.ndarray) -> "SerialArm":
        x = np.asarray(x, dtype=float)
        if x.shape != (12 + 5 * self.n_joints,):
            raise ValueError(f"parameter vector has shape {x.shape}, expected ({12 + 5 * self.n_joints},)")
        base = {k: float(x[i]) for i, k in enumerate(BASE_KEYS)}
        joints = tuple(
            replace(j, **{k: float(x[6 + 5 * i + m]) for m, k in enumerate(JOINT_KEYS)})
            for i, j in enumerate(self.joints)
        )
        off = 6 + 5 * self.n_joints
        tool = {k: float(x[off + i]) for i, k in enumerate(TOOL_KEYS)}
        return replace(self, base=base, joints=joints, tool=tool)

    def chain(self) -> Chain:
        """The arm as a generic `pipeline.models.chain.Chain` (jig frame → tool tip)."""
        return arm_chain(self.n_joints)

    @property
    def lower(self) -> np.ndarray:
        return np.array([j.lower for j in self.joints])

    @property
    def upper(self) -> np.ndarray:
        return np.array([j.upper for j in self.joints])

    # ----- JSON (schemas/robot_model.schema.json) ------------------------------------
    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "kind": "serial_arm",
            "name": self.name,
            "units": {"length": "m", "angle": "rad"},
            "base": {k: float(self.base[k]) for k in BASE_KEYS},
            "joints": [
                {"name": j.name, **{k: float(getattr(j, k)) for k in JOINT_KEYS},
                 "lower": float(j.lower), "upper": float(j.upper)}
                for j in self.joints
            ],
            "tool": {k: float(self.tool[k]) for k in TOOL_KEYS},
        }
        if self.masses:
            d["masses"] = [{"joint": m.joint, "mass": m.mass, "com": list(m.com)} for m in self.masses]
        if self.payload_kg:
            d["payload_kg"] = float(self.payload_kg)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "SerialArm":
        if d.get("kind") != "serial_arm":
            raise ValueError(f"robot model kind is {d.get('kind')!r}, expected 'serial_arm'")
        joints = tuple(
            Joint(name=j["name"], **{k: float(j[k]) for k in JOINT_KEYS},
                  lower=float(j.get("lower", -np.pi)), upper=float(j.get("upper", np.pi)))
            for j in d["joints"]
        )
        masses = tuple(LinkMass(int(m["joint"]), float(m["mass"]), tuple(m["com"])) for m in d.get("masses", []))
        return cls(
            name=d.get("name", "arm"),
            base={k: float(d["base"][k]) for k in BASE_KEYS},
            joints=joints,
            tool={k: float(d["tool"][k]) for k in TOOL_KEYS},
            masses=masses,
            payload_kg=float(d.get("payload_kg", 0.0)),
        )


# ----- the chain as elementary steps (pipeline.models.chain) ----------------------------
# base: Tx Ty Tz Rz Rx Ry; per joint: Rz(q + theta_offset) Tx(a) Tz(d) Rx(alpha) Ry(beta);
# tool: Tx Ty Tz Rz Ry Rx.  Every parameter drives exactly one step.
@cache
def arm_chain(n_joints: int) -> Chain:
    """The seed-000 model of an n-joint arm as a generic `Chain` (parameter order of `vector`)."""
    R, P = ROT_, TRANS
    steps = [(kind, unit(AXES[ax]), k, -1)
             for k, (kind, ax) in enumerate([(P, "x"), (P, "y"), (P, "z"), (R, "z"), (R, "x"), (R, "y")])]
    for i in range(n_joints):
        o = 6 + 5 * i  # theta_offset, d, a, alpha, beta
        steps += [(R, unit(2), o, i), (P, unit(0), o + 2, -1), (P, unit(2), o + 1, -1),
                  (R, unit(0), o + 3, -1), (R, unit(1), o + 4, -1)]
    o = 6 + 5 * n_joints
    steps += [(kind, unit(AXES[ax]), o + k, -1)
              for k, (kind, ax) in enumerate([(P, "x"), (P, "y"), (P, "z"), (R, "z"), (R, "y"), (R, "x")])]
    return Chain.build(steps, 12 + 5 * n_joints, n_joints)


def _chain_of(q: np.ndarray) -> tuple[Chain, np.ndarray]:
    q = np.atleast_2d(np.asarray(q, dtype=float))
    return arm_chain(q.shape[1]), q


def forward(x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tool pose in the jig frame: rotations (N,3,3) and tip positions (N,3) in m."""
    c, q = _chain_of(q)
    return chain.forward(c, x, q)


def tip_position(x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Tool-tip positions (N,3) in the jig frame {W}, m."""
    return forward(x, q)[1]


def tip_jacobian(x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip positions (N,3) and their derivative wrt the parameters, (N,3,P) in m per unit.

    Each elementary rotation about world axis u at origin o moves the tip by u × (p − o);
    each elementary translation by u (`pipeline.models.chain.jacobian`).
    """
    c, q = _chain_of(q)
    return chain.jacobian(c, x, q)


def joint_jacobian(x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip positions (N,3) and their derivative wrt the joint angles, (N,3,n_joints)."""
    c, q = _chain_of(q)
    return chain.joint_jacobian(c, x, q)


def frames(x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """World poses of base, each joint frame and the tool: (N, n_joints + 2, 4, 4)."""
    c, q = _chain_of(q)
    nj = q.shape[1]
    # frame boundaries: after the 6 base steps, after each joint's 5 steps, at the end
    marks = [6 + 5 * i - 1 for i in range(nj + 1)] + [c.n_steps - 1]
    return chain.frames(c, x, q, marks)
