"""Gravity compliance of any URDF robot with inertials (torques in N·m, frames of the URDF).

A joint of finite stiffness k_j deflects under the gravity torque of everything it carries:
the true angle is the reading plus δq_j = c_j·τ_j(q), c_j = 1/k_j (rad/(N·m)), with

    τ_j = z_j · Σ_l (p_l − o_j) × (m_l·g)        (revolute; prismatic: z_j · Σ_l m_l·g, N)

over the links l after joint j in the chain root → tip (their `<inertial>` mass m_l and centre of
mass p_l), o_j and z_j the joint's origin and axis, g = 9.80665 m/s² along −z of the root link (the
URDF convention; `gravity` otherwise).  Frames come from the URDF's nominal joint origins: the
torques enter the signature to first order, where millimetre errors of the origins do not matter.
Links off the chain (a gripper's fingers hung on a fixed joint below the tip are on it) and the
payload (not in a URDF campaign's table) are not counted.
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


def _rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(n, 4, 4) rotations about a unit axis by angles (n,) (Rodrigues)."""
    k = np.asarray(axis, float)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    T = np.broadcast_to(np.eye(4), (angle.size, 4, 4)).copy()
    T[:, :3, :3] = np.eye(3) + s * K + (1 - c) * (K @ K)
    return T


def gravity_torques(desc, q: np.ndarray, gravity: np.ndarray = GRAVITY_ROOT,
                    payload: tuple[float, np.ndarray] | None = None) -> np.ndarray:
    """Generalised gravity force on each movable joint (n, n_joints): N·m (revolute) or N (prismatic);
    `payload`: an extra (mass kg, centre of mass (3,) m in the tip link's frame) carried at the tip."""
    q = np.atleast_2d(np.asarray(q, float))
    n = q.shape[0]
    masses = inertials(desc)
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    o, z, kinds, loads = [], [], [], []  # loads: (force (3,), point (n, 3), last joint before it)
    if desc.root in masses:
        m, c = masses[desc.root]
        loads.append((m * gravity, np.broadcast_to(c, (n, 3)), -1))
    ji = -1
    for j in desc.joints:
        T = T @ np.asarray(j.origin, float)
        if j.movable:
            ji += 1
            axis = np.asarray(j.axis, float)
            o.append(T[:, :3, 3].copy())
            z.append(T[:, :3, :3] @ axis)
            kinds.append(j.type)
            if j.type == "prismatic":
                D = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
                D[:, :3, 3] = q[:, ji, None] * axis
                T = T @ D
            else:
                T = T @ _rotation(axis, q[:, ji])
        if j.child in masses:
            m, c = masses[j.child]
            loads.append((m * gravity, T[:, :3, :3] @ c + T[:, :3, 3], ji))
    if payload is not None and payload[0] > 0:
        loads.append((payload[0] * gravity, T[:, :3, :3] @ np.asarray(payload[1], float) + T[:, :3, 3], ji))
    tau = np.zeros((n, ji + 1))
    for f, p, last in loads:
        for k in range(last + 1):
            if kinds[k] == "prismatic":
                tau[:, k] += z[k] @ f
            else:
                tau[:, k] += np.einsum("ni,ni->n", z[k], np.cross(p - o[k], f))
    return tau
