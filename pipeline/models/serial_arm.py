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
from typing import Any

import numpy as np

from pipeline.models.transforms import AXES, rot

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


# ----- the chain as elementary steps --------------------------------------------------
# Each step: (is_rotation, axis index, parameter index, joint index or -1).  A joint's
# first step rotates by q_i + theta_offset_i.
def _chain(n_joints: int) -> list[tuple[bool, int, int, int]]:
    steps: list[tuple[bool, int, int, int]] = []
    for k, (rot_, ax) in enumerate([(False, "x"), (False, "y"), (False, "z"), (True, "z"), (True, "x"), (True, "y")]):
        steps.append((rot_, AXES[ax], k, -1))
    for i in range(n_joints):
        o = 6 + 5 * i  # theta_offset, d, a, alpha, beta
        steps += [(True, 2, o, i), (False, 0, o + 2, -1), (False, 2, o + 1, -1), (True, 0, o + 3, -1), (True, 1, o + 4, -1)]
    o = 6 + 5 * n_joints
    for k, (rot_, ax) in enumerate([(False, "x"), (False, "y"), (False, "z"), (True, "z"), (True, "y"), (True, "x")]):
        steps.append((rot_, AXES[ax], o + k, -1))
    return steps


_ROT_PLANE = ((1, 2), (2, 0), (0, 1))  # (i, j) of a rotation about x, y, z: T[i,j] = −sin, T[j,i] = sin


def _step_matrix(is_rot: bool, ax: int, value: float) -> np.ndarray:
    T = np.eye(4)
    if is_rot:  # the entries of `rot` (same cos/sin), set in place: this runs per call of `forward`
        i, j = _ROT_PLANE[ax]
        c, sn = np.cos(value), np.sin(value)
        T[i, i] = T[j, j] = c
        T[i, j], T[j, i] = -sn, sn
    else:
        T[ax, 3] = value
    return T


_RUNS: dict = {}  # (x bytes, chain length, s, e) -> `_constant_run`: the planners call `forward` thousands of times per x


def _constant_run(x: np.ndarray, steps: list, s: int, e: int):
    """Product P of the constant steps s..e−1 and each step's axis and origin in the run's
    first frame (memoised per parameter vector)."""
    key = (x.tobytes(), len(steps), s, e)
    hit = _RUNS.get(key)
    if hit is not None:
        return hit
    P = np.eye(4)  # product of the run's steps before the current one
    ax_local = np.empty((e - s, 3))
    org_local = np.empty((e - s, 3))
    for k in range(s, e):
        k_rot, k_ax, k_pi, _ = steps[k]
        ax_local[k - s], org_local[k - s] = P[:3, k_ax], P[:3, 3]
        P = P @ _step_matrix(k_rot, k_ax, x[k_pi])
    if len(_RUNS) > 4096:
        _RUNS.clear()
    for a in (P, ax_local, org_local):
        a.setflags(write=False)  # shared by every later call with this x: a caller writing into it would be a bug
    _RUNS[key] = (P, ax_local, org_local)
    return P, ax_local, org_local


_WALKS: dict = {}  # (x, q, want_jacobian) bytes -> _walk's arrays (read-only)


def _walk(x: np.ndarray, q: np.ndarray, want_jacobian: bool):
    """`_walk_chain`, memoised on its inputs: a fit and the diagnosis ask for the same chain at
    the same parameters several times (residuals and Jacobian, tip and joint Jacobians).  The
    arrays returned are read-only; the public functions hand out copies."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    key = (x.tobytes(), q.shape, q.tobytes(), want_jacobian)
    hit = _WALKS.get(key)
    if hit is None:
        hit = _walk_chain(x, q, want_jacobian)
        for a in hit:
            if isinstance(a, np.ndarray):
                a.setflags(write=False)
        if len(_WALKS) >= 8:
            _WALKS.pop(next(iter(_WALKS)))
        _WALKS[key] = hit
    return hit


def _walk_chain(x: np.ndarray, q: np.ndarray, want_jacobian: bool):
    """Walk the chain.  Runs of constant steps are folded into one 4×4 product and joint
    rotations are applied as column operations, so the batch cost is a few small array
    operations per joint.  With `want_jacobian`, the world axis and origin of every
    elementary step are recovered from the frame at the start of its constant run."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n, nj = q.shape
    if x.shape[0] != 12 + 5 * nj:
        raise ValueError(f"{nj} joint angles per row do not fit a {x.shape[0]}-parameter model")
    steps = _chain(nj)
    axes_w = np.empty((len(steps), n, 3)) if want_jacobian else None
    origins = np.empty((len(steps), n, 3)) if want_jacobian else None
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    s = 0
    while s < len(steps):
        is_rot, ax, pi, ji = steps[s]
        if ji >= 0:  # joint rotation about the current z axis by q + theta_offset
            if want_jacobian:
                axes_w[s] = T[:, :3, 2]
                origins[s] = T[:, :3, 3]
            ang = q[:, ji] + x[pi]
            c, sn = np.cos(ang)[:, None], np.sin(ang)[:, None]
            c0, c1 = T[:, :3, 0].copy(), T[:, :3, 1]
            T[:, :3, 0] = c * c0 + sn * c1
            T[:, :3, 1] = c * c1 - sn * c0
            s += 1
            continue
        e = s
        while e < len(steps) and steps[e][3] < 0:
            e += 1
        P, ax_local, org_local = _constant_run(x, steps, s, e)
        if want_jacobian:
            R = T[:, :3, :3]
            axes_w[s:e] = np.moveaxis(R @ ax_local.T, 2, 0)
            origins[s:e] = np.moveaxis(R @ org_local.T, 2, 0) + T[:, :3, 3]
        T = T @ P
        s = e
    return T[:, :3, :3], T[:, :3, 3], steps, axes_w, origins


def forward(x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tool pose in the jig frame: rotations (N,3,3) and tip positions (N,3) in m."""
    R, o, *_ = _walk(np.asarray(x, dtype=float), q, False)
    return R.copy(), o.copy()


def tip_position(x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Tool-tip positions (N,3) in the jig frame {W}, m."""
    return forward(x, q)[1]


def tip_jacobian(x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip positions (N,3) and their derivative wrt the parameters, (N,3,P) in m per unit.

    Each elementary rotation about world axis u at origin o moves the tip by u × (p − o);
    each elementary translation by u.  Steps that share a parameter add up.
    """
    x = np.asarray(x, dtype=float)
    _, p, steps, axes_w, origins = _walk(x, q, True)
    is_rot = np.array([st[0] for st in steps])
    pidx = np.array([st[2] for st in steps])
    cols = axes_w.copy()  # translations: the axis itself
    a, d = axes_w[is_rot], p[None] - origins[is_rot]
    cols[is_rot] = np.stack([a[..., 1] * d[..., 2] - a[..., 2] * d[..., 1],  # a × d, written out:
                             a[..., 2] * d[..., 0] - a[..., 0] * d[..., 2],  # np.cross is 4× slower
                             a[..., 0] * d[..., 1] - a[..., 1] * d[..., 0]], axis=-1)
    J = np.zeros((p.shape[0], 3, x.shape[0]))
    J[:, :, pidx] = cols.transpose(1, 2, 0)  # every parameter drives exactly one step
    return p.copy(), J


def joint_jacobian(x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip positions (N,3) and their derivative wrt the joint angles, (N,3,n_joints)."""
    x = np.asarray(x, dtype=float)
    _, p, steps, axes_w, origins = _walk(x, q, True)
    nj = np.atleast_2d(q).shape[1]
    J = np.zeros((p.shape[0], 3, nj))
    for s, (is_rot, _ax, _pi, ji) in enumerate(steps):
        if ji >= 0:
            J[:, :, ji] = np.cross(axes_w[s], p - origins[s])
    return p.copy(), J


def frames(x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """World poses of base, each joint frame and the tool: (N, n_joints + 2, 4, 4)."""
    x = np.asarray(x, dtype=float)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n, nj = q.shape
    R = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    o = np.zeros((n, 3))
    out = np.zeros((n, nj + 2, 4, 4))
    out[..., 3, 3] = 1
    steps = _chain(nj)
    # frame boundaries: after the 6 base steps, after each 5 joint steps, at the end
    marks = {6 + 5 * i - 1: i for i in range(nj + 1)}
    marks[len(steps) - 1] = nj + 1
    for s, (is_rot, ax, pi, ji) in enumerate(steps):
        if is_rot:
            R = R @ rot("xyz"[ax], x[pi] + q[:, ji] if ji >= 0 else x[pi])
        else:
            o = o + R[:, :, ax] * x[pi]
        if s in marks:
            out[:, marks[s], :3, :3] = R
            out[:, marks[s], :3, 3] = o
    return out
