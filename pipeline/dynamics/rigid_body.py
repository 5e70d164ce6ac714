"""The URDF's tree as a rigid-body model of the recorded joints (Pinocchio), its joint-torque
regressor and inertial parameters.

Every joint of the URDF that is not recorded is locked at its neutral position, so the links it
carries ride rigidly on the recorded joint above them (`pin.buildReducedModel`).  The torque of the
recorded joints is linear in the bodies' standard inertial parameters π (10 per body, in the body's
joint frame, Pinocchio's order m, m·c_x, m·c_y, m·c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz with I about
the joint-frame origin; kg, kg·m, kg·m²): τ = Y(q, q̇, q̈) π, Y from `pin.computeJointTorqueRegressor`
(the recursion is Pinocchio's, not ours).  Units SI: rad, m, s, N·m (N for a prismatic joint).

Each body's π is split into the *link* part (the recorded joint's child link and the links fixed to it:
what identification changes and `urdf_out` writes) and the *carried* part (links behind locked joints,
held at their URDF values): π = π_link + π_carried.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.errors import RobocalError

PARAMS = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
UNITS = ("kg", "kg·m", "kg·m", "kg·m", "kg·m²", "kg·m²", "kg·m²", "kg·m²", "kg·m²", "kg·m²")
G = 9.81


@dataclass(frozen=True, eq=False)
class RigidBody:
    """The reduced model: `joints` (the recorded joints, in the recording's order), `model` (Pinocchio,
    one body per recorded joint), `pin_q` / `pin_v` (each recorded joint's index in Pinocchio's q and v;
    continuous joints take two q entries, cos and sin), `links` (the child link of each joint),
    `carried` (J·10,) the locked subtrees' parameters in each body."""

    joints: tuple[str, ...]
    model: pin.Model
    pin_q: np.ndarray
    pin_v: np.ndarray
    body_of: np.ndarray  # (J,) Pinocchio joint id (body) of each recorded joint, in recording order
    continuous: np.ndarray  # (J,) bool: a continuous joint (q stored as cos, sin)
    links: tuple[str, ...]
    carried: np.ndarray

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    def parameter_names(self) -> list[str]:
        return [f"{j}.{p}" for j in self.joints for p in PARAMS]

    def parameter_units(self) -> list[str]:
        return [u for _ in self.joints for u in UNITS]


def build(urdf_text: str, joints: list[str], source: str = "URDF") -> RigidBody:
    """The rigid-body model of `urdf_text` with only `joints` free (every other joint locked at its
    neutral position); a joint the URDF lacks, or one that is not revolute, continuous or prismatic,
    is a one-line `RobocalError` naming `source`."""
    try:
        full = pin.buildModelFromXML(urdf_text)
    except (RuntimeError, ValueError) as e:
        raise RobocalError(f"{source}: Pinocchio cannot build a model ({e})") from None
    names = list(full.names)
    missing = [j for j in joints if j not in names]
    if missing:
        raise RobocalError(f"{source}: joint(s) {', '.join(missing)} not in the URDF's tree")
    lock = [full.getJointId(n) for n in names[1:] if n not in joints]
    red = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
    body, pq, pv, cont = [], [], [], []
    for j in joints:
        jid = red.getJointId(j)
        jm = red.joints[jid]
        if jm.nv != 1 or jm.nq not in (1, 2):
            raise RobocalError(f"{source}: joint {j!r} has {jm.nq} position and {jm.nv} velocity coordinates; "
                               "dynamics takes revolute, continuous and prismatic joints")
        body.append(jid)
        pq.append(jm.idx_q)
        pv.append(jm.idx_v)
        cont.append(jm.nq == 2)
    if red.nv != len(joints):
        raise RobocalError(f"{source}: the reduced model has {red.nv} velocities for {len(joints)} joints")
    own = np.concatenate([full.inertias[full.getJointId(j)].toDynamicParameters() for j in joints])
    whole = np.concatenate([red.inertias[b].toDynamicParameters() for b in body])
    links = tuple(_child_link(full, j) for j in joints)
    return RigidBody(tuple(joints), red, np.array(pq), np.array(pv), np.array(body), np.array(cont), links,
                     whole - own)


def _child_link(full: pin.Model, joint: str) -> str:
    jid = full.getJointId(joint)
    for f in full.frames:
        if f.parentJoint == jid and f.type == pin.FrameType.BODY and f.placement.isIdentity():
            return f.name
    return joint


def standard_parameters(rb: RigidBody) -> np.ndarray:
    """π (J·10,) of the model's bodies (links and what they carry), recording joint order."""
    return np.concatenate([rb.model.inertias[int(b)].toDynamicParameters() for b in rb.body_of])


def link_parameters(rb: RigidBody) -> np.ndarray:
    """π_link (J·10,): the URDF's own inertial parameters of each recorded joint's child link."""
    return standard_parameters(rb) - rb.carried


def _pin_q(rb: RigidBody, q: np.ndarray) -> np.ndarray:
    """Pinocchio configurations (T, nq) of joint positions (T, J) rad / m."""
    q = np.atleast_2d(np.asarray(q, float))
    out = np.zeros((q.shape[0], rb.model.nq))
    for k in range(rb.n_joints):
        if rb.continuous[k]:
            out[:, rb.pin_q[k]], out[:, rb.pin_q[k] + 1] = np.cos(q[:, k]), np.sin(q[:, k])
        else:
            out[:, rb.pin_q[k]] = q[:, k]
    return out


def regressor(rb: RigidBody, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Y (T, J, J·10): joint torques = Y @ π at each sample (q rad / m, v rad/s, a rad/s², (T, J)).
    One Pinocchio call per sample (C++); columns reordered to the recording's joints."""
    Q = _pin_q(rb, q)
    v = np.atleast_2d(np.asarray(v, float))
    a = np.atleast_2d(np.asarray(a, float))
    V = np.zeros((v.shape[0], rb.model.nv))
    A = np.zeros_like(V)
    V[:, rb.pin_v], A[:, rb.pin_v] = v, a
    data = rb.model.createData()
    out = np.empty((Q.shape[0], rb.model.nv, 10 * (rb.model.njoints - 1)))
    for i in range(Q.shape[0]):
        out[i] = pin.computeJointTorqueRegressor(rb.model, data, Q[i], V[i], A[i])
    cols = (10 * (rb.body_of - 1)[:, None] + np.arange(10)).ravel()
    return out[:, rb.pin_v][:, :, cols]


def torques(rb: RigidBody, q: np.ndarray, v: np.ndarray, a: np.ndarray, pi: np.ndarray | None = None) -> np.ndarray:
    """Inverse dynamics τ (T, J) by Pinocchio's RNEA with parameters π (default the URDF's)."""
    m = rb.model
    if pi is not None:
        m = m.copy()
        for k, b in enumerate(rb.body_of):
            m.inertias[int(b)] = pin.Inertia.FromDynamicParameters(np.asarray(pi[10 * k:10 * k + 10], float))
    Q = _pin_q(rb, q)
    V = np.zeros((Q.shape[0], m.nv))
    A = np.zeros_like(V)
    V[:, rb.pin_v], A[:, rb.pin_v] = v, a
    data = m.createData()
    return np.stack([pin.rnea(m, data, Q[i], V[i], A[i]) for i in range(Q.shape[0])])[:, rb.pin_v]


def subtree_weight(rb: RigidBody, joint: str) -> float:
    """g × the mass the joint carries (its body and everything beyond it), N: the weight a vertical
    lift's drive holds at rest."""
    data = rb.model.createData()
    pin.computeSubtreeMasses(rb.model, data)
    return float(G * data.mass[int(rb.body_of[rb.joints.index(joint)])])


def pseudo_inertia(pi: np.ndarray) -> np.ndarray:
    """The 4×4 pseudo-inertia J = [[½tr(I)·1 − I, h], [hᵀ, m]] of one body's π (10,): physically
    consistent (a non-negative mass density can produce it) iff J ⪰ 0 (positive mass, inertia
    satisfying the triangle inequalities, centre of mass inside the body's inertial ellipsoid)."""
    m, hx, hy, hz, xx, xy, yy, xz, yz, zz = pi
    I = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    out = np.zeros((4, 4))
    out[:3, :3] = 0.5 * np.trace(I) * np.eye(3) - I
    out[:3, 3] = out[3, :3] = (hx, hy, hz)
    out[3, 3] = m
    return out
