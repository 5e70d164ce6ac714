"""The independent generator's own arm physics (`independent_touch`): 4×4 forward kinematics, gravity torques
of lumped masses, and a gear's play (a dead band).  Shares no code with robocal: only numbers of the arm are read
(`Arm.of`).  Every angle rad, length m, torque N·m."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


# ----- 4×4 kinematics ----------------------------------------------------------------------
def _rot(axis: str, a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, float)
    c, s = np.cos(a), np.sin(a)
    T = np.zeros(a.shape + (4, 4))
    T[..., 3, 3] = 1
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    k = 3 - i - j
    T[..., k, k] = 1
    T[..., i, i], T[..., i, j], T[..., j, i], T[..., j, j] = c, -s, s, c
    return T


def _trans(x, y, z, shape=()) -> np.ndarray:
    T = np.broadcast_to(np.eye(4), shape + (4, 4)).copy()
    T[..., 0, 3], T[..., 1, 3], T[..., 2, 3] = x, y, z
    return T


@dataclass(frozen=True)
class Arm:
    """Plain numbers: base (x, y, z, rz, rx, ry), joints [(θ, d, a, α, β)], tool (x, y, z, rz, ry, rx)."""

    base: tuple
    joints: tuple
    tool: tuple
    lower: tuple
    upper: tuple
    masses: tuple = ()  # ((joint index, kg, (x, y, z) in that joint's link frame), ...)

    @staticmethod
    def of(arm) -> "Arm":
        b, t = arm.base, arm.tool
        return Arm((b["x"], b["y"], b["z"], b["rz"], b["rx"], b["ry"]),
                   tuple((j.theta_offset, j.d, j.a, j.alpha, j.beta) for j in arm.joints),
                   (t["x"], t["y"], t["z"], t["rz"], t["ry"], t["rx"]),
                   tuple(j.lower for j in arm.joints), tuple(j.upper for j in arm.joints),
                   tuple((m.joint, m.mass, tuple(m.com)) for m in getattr(arm, "masses", ())))


def pose(arm: Arm, q: np.ndarray, link_scale: np.ndarray | None = None) -> np.ndarray:
    """W_T_E (n, 4, 4) at joint angles q (n, 6); `link_scale` (n, 2) multiplies (a2, d4), or
    (n, 6) every joint's a and d."""
    q = np.atleast_2d(q)
    n = q.shape[0]
    x, y, z, rz, rx, ry = arm.base
    T = (_trans(x, y, z) @ _rot("z", rz) @ _rot("x", rx) @ _rot("y", ry))[None].repeat(n, 0)
    for i, (th, d, a, al, be) in enumerate(arm.joints):
        a_i = np.full(n, a)
        d_i = np.full(n, d)
        if link_scale is not None and link_scale.shape[1] == 6:
            a_i, d_i = a * link_scale[:, i], d * link_scale[:, i]
        elif link_scale is not None and i == 1:
            a_i = a * link_scale[:, 0]
        elif link_scale is not None and i == 3:
            d_i = d * link_scale[:, 1]
        T = T @ _rot("z", q[:, i] + th) @ _trans(a_i, np.zeros(n), d_i, (n,)) @ _rot("x", al) @ _rot("y", be)
    tx, ty, tz, trz, tr_y, trx = arm.tool
    return T @ (_trans(tx, ty, tz) @ _rot("z", trz) @ _rot("y", tr_y) @ _rot("x", trx))


def tip(arm: Arm, q: np.ndarray, link_scale: np.ndarray | None = None) -> np.ndarray:
    return pose(arm, q, link_scale)[:, :3, 3]


def gravity_torque(arm: Arm, q: np.ndarray, payload_kg: np.ndarray) -> np.ndarray:
    """(n, 6) N·m: torque of gravity (−z of the jig frame, 9.80665 m/s²) about each joint's axis, from the
    lumped link masses and the payload at the tool point (this file's own 4×4 chain)."""
    q = np.atleast_2d(q)
    n = q.shape[0]
    x, y, z, rz, rx, ry = arm.base
    T = (_trans(x, y, z) @ _rot("z", rz) @ _rot("x", rx) @ _rot("y", ry))[None].repeat(n, 0)
    axes, origins, links = [], [], []
    for i, (th, d, a, al, be) in enumerate(arm.joints):
        axes.append(T[:, :3, 2].copy())
        origins.append(T[:, :3, 3].copy())
        T = T @ _rot("z", q[:, i] + th) @ _trans(np.full(n, a), np.zeros(n), np.full(n, d), (n,)) @ _rot("x", al) \
            @ _rot("y", be)
        links.append(T.copy())
    tx, ty, tz, *_ = arm.tool
    loads = [(j, np.full(n, m), np.einsum("nij,j->ni", links[j][:, :3, :3], np.asarray(c)) + links[j][:, :3, 3])
             for j, m, c in arm.masses]
    loads.append((5, np.broadcast_to(np.asarray(payload_kg, float), (n,)),
                  np.einsum("nij,j->ni", T[:, :3, :3], np.array([tx, ty, tz])) + T[:, :3, 3]))
    tau = np.zeros((n, 6))
    for j, m, p in loads:
        f = m[:, None] * np.array([0.0, 0.0, -9.80665])
        for k in range(j + 1):
            tau[:, k] += np.einsum("ni,ni->n", axes[k], np.cross(p - origins[k], f))
    return tau


def play(motor: np.ndarray, width: float, link0: float) -> np.ndarray:
    """The link angle behind a gear with `width` rad of play (the hysteresis of a dead band): the link stays
    put until the motor, on its way `motor` (m,), takes up the play on one side, then follows it at half the
    play behind; `link0` its start.  Returns the link angle at each sample."""
    out = np.empty(motor.size)
    link = link0
    for i, m in enumerate(motor):
        link = min(max(link, m - width / 2), m + width / 2)
        out[i] = link
    return out


def backlash_error(q_a: np.ndarray, dq: np.ndarray, s: np.ndarray, width: float, j: int) -> np.ndarray:
    """δq_j (n,) = link − motor at each latch: the motor path of joint j through the campaign (each approach
    from the previous retract pose to q_a, then the search to the latch, then back to q_a) through `play`."""
    n = q_a.shape[0]
    path = np.stack([q_a[:, j], q_a[:, j] + s * dq[:, j], q_a[:, j]], axis=1).ravel()  # approach, latch, retract
    link = play(path, width, q_a[0, j] - width / 2)
    return link.reshape(n, 3)[:, 1] - path.reshape(n, 3)[:, 1]
