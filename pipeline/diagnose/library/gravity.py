"""Gravity torques of a serial arm's lumped masses (N·m), the load of every compliance term.

Lumped masses of `SerialArm.masses` (link of joint index j, centre of mass in that link's frame)
and the payload (kg) at the tool tip; gravity is −z of the jig frame {W} (z up: the block sits level).
"""

from __future__ import annotations

import numpy as np

from pipeline.models import serial_arm
from pipeline.models.serial_arm import SerialArm

G_M_S2 = 9.80665
GRAVITY_W = np.array([0.0, 0.0, -G_M_S2])  # jig frame {W}: z up (the block sits level)

_TORQUES: dict = {}  # (arm id, x, q, payload) bytes -> (arm, torques): the compliance candidates of all joints share them


def gravity_torque(arm: SerialArm, x: np.ndarray, q: np.ndarray, payload_kg: np.ndarray | float) -> np.ndarray:
    """Gravity torque about each joint axis, (n, n_joints) N·m (read-only: memoised on the inputs).

    Lumped masses of `arm.masses` (link of joint index j, centre of mass in that link's
    frame) and the payload (kg, per row or scalar) at the tool tip; gravity is −z of {W}.
    """
    x = np.asarray(x, float)
    q = np.atleast_2d(np.asarray(q, float))
    pl = np.asarray(payload_kg, float)
    key = (id(arm), x.tobytes(), q.shape, q.tobytes(), pl.shape, pl.tobytes())
    hit = _TORQUES.get(key)
    if hit is not None and hit[0] is arm:
        return hit[1]
    tau = _gravity_torque(arm, x, q, pl)
    tau.setflags(write=False)
    if len(_TORQUES) >= 8:
        _TORQUES.pop(next(iter(_TORQUES)))
    _TORQUES[key] = (arm, tau)
    return tau


def _gravity_torque(arm: SerialArm, x: np.ndarray, q: np.ndarray, payload_kg: np.ndarray) -> np.ndarray:
    n, nj = q.shape
    F = serial_arm.frames(x, q)  # (n, nj+2, 4, 4): F[:, k] is the frame joint k rotates in
    z = F[:, :nj, :3, 2]
    o = F[:, :nj, :3, 3]
    pts, mass, link = [], [], []
    for m in arm.masses:
        T = F[:, m.joint + 1]
        pts.append(np.einsum("nij,j->ni", T[:, :3, :3], np.asarray(m.com, float)) + T[:, :3, 3])
        mass.append(np.full(n, m.mass))
        link.append(m.joint)
    pts.append(F[:, nj + 1, :3, 3])
    mass.append(np.broadcast_to(np.asarray(payload_kg, float), (n,)))
    link.append(nj - 1)
    tau = np.zeros((n, nj))
    for c, mm, j in zip(pts, mass, link):
        f = mm[:, None] * GRAVITY_W  # (n,3) N
        for k in range(j + 1):  # joints 0..j carry this mass
            tau[:, k] += np.einsum("ni,ni->n", z[:, k], np.cross(c - o[:, k], f))
    return tau
