"""Gravity compliance of any URDF robot with inertials (torques in N·m, frames of the URDF).

A joint of finite stiffness k_j deflects under the gravity torque of everything it carries:
the true angle is the reading plus δq_j = c_j·τ_j(q), c_j = 1/k_j (rad/(N·m)), with

    τ_j = z_j · Σ_l (p_l − o_j) × (m_l·g)        (revolute; prismatic: z_j · Σ_l m_l·g, N)

over every link l joint j carries in the URDF's tree — the rest of the chain, other branches (a
second arm, a head, a gripper's fingers) — with their `<inertial>` mass m_l and centre of mass p_l,
o_j and z_j the joint's origin and axis, g = 9.80665 m/s² along −z of the root link (the URDF
convention; `gravity` otherwise).  Computed by Pinocchio (`pipeline.physics.gravity`) from the
URDF's nominal joint origins: the torques enter the signature to first order, where millimetre
errors of the origins do not matter.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

G_M_S2 = 9.80665
GRAVITY_ROOT = np.array([0.0, 0.0, -G_M_S2])


def inertials(desc) -> dict[str, tuple[float, np.ndarray]]:
    """{link: (mass kg, centre of mass (3,) m in the link frame)} of the URDF's links with a mass > 0."""
    out = {}
    for link in ET.fromstring(desc.urdf).findall("link"):
        ine = link.find("inertial")
        m = None if ine is None else ine.find("mass")
        if m is None:
            continue
        mass = float(m.get("value", "0"))
        o = ine.find("origin")
        com = np.array([float(v) for v in ((o.get("xyz") if o is not None else None) or "0 0 0").split()])
        if mass > 0 and np.all(np.isfinite(com)) and com.shape == (3,):
            out[link.get("name")] = (mass, com)
    return out


def gravity_torques(desc, q: np.ndarray, gravity: np.ndarray = GRAVITY_ROOT,
                    payload: tuple[float, np.ndarray] | None = None) -> np.ndarray:
    """Generalised gravity force on each movable joint of the chain (n, n_joints): N·m (revolute) or N
    (prismatic), from every link each joint carries in the URDF's whole tree (Pinocchio,
    `pipeline.physics.gravity`; joints off the chain held at 0); `payload`: an extra (mass kg, centre of
    mass (3,) m in the tip link's frame) carried at the tip."""
    from pipeline.physics.gravity import gravity_load

    extra = [(float(payload[0]), desc.tip, np.asarray(payload[1], float))] if payload is not None and payload[0] > 0 else []
    return gravity_load(desc.urdf, desc.joint_names, q, payload=extra, gravity=gravity).axial
