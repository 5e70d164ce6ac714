"""Gravity load on every joint of a URDF robot's whole tree, computed by Pinocchio.

For each configuration, the static wrench each movable joint transmits to everything it carries in
the tree — the rest of its own chain, other branches (a second arm, a head), a payload hung on any
link — from the URDF's `<inertial>` elements, with gravity g = 9.80665 m/s² along −z of the URDF's
root link.  Returned, per joint, in the joint's own frame at that configuration (the child link's
frame, which turns with the joint):

* ``axial`` (n, J): the moment of gravity about the joint's axis, N·m (revolute, continuous), or the
  force along it, N (prismatic) — what turns a compliant joint;
* ``lateral`` (n, J, 2): the moment about the two axes normal to the joint's axis, N·m, along
  (e1, e2) of `normals` — what tilts a joint whose bearing or link bends.

Both are the moments gravity exerts (the sign that deflects a compliant joint), the negative of the
wrench a motor and bearing must hold.  Joints of the URDF that are not in `joint_names` are held at 0,
those in `coupled` at their linear combination of the others (rad).  Pinocchio's recursive Newton–Euler
runs once per configuration (C++); nothing here is in a solver's loop.
"""

from __future__ import annotations

import functools
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from pipeline.errors import RobocalError

G_M_S2 = 9.80665


def normals(axis) -> np.ndarray:
    """(2, 3): two unit vectors e1, e2 normal to `axis` and to each other, (e1, e2, axis) right-handed."""
    z = np.asarray(axis, float) / np.linalg.norm(axis)
    a = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(a, z)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(z, e1)])


def has_inertials(urdf: str) -> bool:
    """Whether any link of the URDF text has a mass > 0."""
    for m in ET.fromstring(urdf).iter("mass"):
        try:
            if float(m.get("value", "0")) > 0:
                return True
        except ValueError:
            continue
    return False


@functools.lru_cache(maxsize=8)
def _model(urdf: str):
    import pinocchio as pin

    try:
        model = pin.buildModelFromXML(urdf)
    except Exception as e:  # Pinocchio's parser: malformed URDF for dynamics
        raise RobocalError(f"URDF: Pinocchio cannot build the robot's dynamics ({type(e).__name__}: {e})") from None
    model.gravity.linear = np.array([0.0, 0.0, -G_M_S2])
    return model


@dataclass(frozen=True)
class Load:
    """Gravity load per configuration (see module docstring): axial (n, J), lateral (n, J, 2)."""

    axial: np.ndarray
    lateral: np.ndarray


def gravity_load(urdf: str, joint_names: list[str], q: np.ndarray, coupled: dict | None = None,
                 payload: list[tuple[float, str, np.ndarray]] | None = None, gravity: np.ndarray | None = None) -> Load:
    """The gravity load on each joint in `joint_names` at configurations `q` (n, J) rad or m.

    `coupled`: {joint: {joint_k: factor_k}} for joints of the URDF driven by others (not in `q`);
    `payload`: [(mass kg, link, centre of mass (3,) m in the link's frame)] hung on links; `gravity`:
    (3,) m/s² in the root link's frame (default 9.80665 along −z)."""
    import pinocchio as pin

    base = _model(urdf)
    custom = gravity is not None and not np.allclose(gravity, [0.0, 0.0, -G_M_S2], rtol=0, atol=0)
    model = base.copy() if payload or custom else base
    if custom:
        model.gravity.linear = np.asarray(gravity, float)
    for mass, link, com in payload or []:
        if not model.existFrame(link):
            raise RobocalError(f"payload: link {link!r} is not in the URDF")
        fr = model.frames[model.getFrameId(link)]
        inertia = pin.Inertia(float(mass), np.asarray(com, float), np.zeros((3, 3)))
        model.inertias[fr.parentJoint] = model.inertias[fr.parentJoint] + fr.placement.act(inertia)
    data = model.createData()
    q = np.atleast_2d(np.asarray(q, float))
    n, J = q.shape
    ids = []
    for name in joint_names:
        if not model.existJointName(name):
            raise RobocalError(f"URDF: joint {name!r} is not a joint Pinocchio built (is it fixed?)")
        ids.append(model.getJointId(name))
    coupled = coupled or {}
    col = {name: i for i, name in enumerate(joint_names)}
    full = {name: q[:, i] for i, name in enumerate(joint_names)}
    for name, comb in coupled.items():
        full[name] = sum(float(c) * q[:, col[k]] for k, c in comb.items())
    Q = np.tile(pin.neutral(model), (n, 1))
    for name, values in full.items():
        if not model.existJointName(name):
            continue
        jm = model.joints[model.getJointId(name)]
        if jm.nq == 2:  # continuous joint: (cos, sin)
            Q[:, jm.idx_q], Q[:, jm.idx_q + 1] = np.cos(values), np.sin(values)
        else:
            Q[:, jm.idx_q] = values
    axes, prismatic = _axes(model, ids)
    frames = [np.vstack([normals(a), a]) for a in axes]  # rows e1, e2, axis in the joint frame
    zero = np.zeros(model.nv)
    axial, lateral = np.empty((n, J)), np.empty((n, J, 2))
    for r in range(n):
        pin.rnea(model, data, Q[r], zero, zero)
        for k, jid in enumerate(ids):
            f = data.f[jid]  # wrench the parent applies to the subtree, joint frame: −gravity's
            m = -frames[k] @ f.angular
            axial[r, k] = -(axes[k] @ f.linear) if prismatic[k] else m[2]
            lateral[r, k] = m[:2]
    return Load(axial, lateral)


def _axes(model, ids: list[int]) -> tuple[list[np.ndarray], list[bool]]:
    """Each 1-dof joint's unit axis in its own frame and whether it slides (from its motion subspace)."""
    import pinocchio as pin

    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    axes, slides = [], []
    for jid in ids:
        if model.joints[jid].nv != 1:
            raise RobocalError(f"URDF: joint {model.names[jid]!r} has {model.joints[jid].nv} degrees of freedom, expected 1")
        col = np.asarray(pin.getJointJacobian(model, data, jid, pin.ReferenceFrame.LOCAL))[:, model.joints[jid].idx_v]
        slide = np.linalg.norm(col[3:]) < 1e-12
        a = col[:3] if slide else col[3:]
        axes.append(a / np.linalg.norm(a))
        slides.append(bool(slide))
    return axes, slides
