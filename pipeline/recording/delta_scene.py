"""A Delta robot's scene for ROS / Foxglove tools: a URDF of its links and a ``/tf`` message per posture.

A Delta is a closed chain, which URDF cannot express; the description is the kinematic *tree* a viewer
needs, with the closure carried by the transforms:

- ``base`` (the fixed platform, a disc of radius ``a`` in the base frame {A}, z up);
- ``upper_arm_<i>`` (i = 1..3): revolute joint ``actuator_<i>`` at the actuator axis A_i =
  Rz(φ_i)·(a, 0, 0), frame yawed by φ_i; the joint turns about −y_i so that a positive actuator angle θ
  raises the elbow (θ = 0: arm horizontal, pointing outwards), the arm lies along its x axis;
- ``forearm_<i>``: floating joint from ``base`` (the parallelogram's centre line), origin at the elbow,
  x axis towards the platform's ball joint, length ``l2``;
- ``platform``: floating joint from ``base``, origin at the platform point P (its pose from the forward
  kinematics);
- ``robocal_tool``: fixed joint from ``platform``, the tracker's reflector ``reflector_offset_m`` below
  P along the platform's z axis (seed 003 eq. 13).

The messages are the *nominal* robot's (recordings are written before any calibration), like the serial
arms' in `pipeline.recording.scene`: ``base`` → ``robocal_instrument`` is the identity (the tracker's
registration is what the calibration estimates).  Lengths m, angles rad, quaternions (x, y, z, w).
"""

from __future__ import annotations

import numpy as np

from pipeline.models import delta as dm

INSTRUMENT_FRAME = "robocal_instrument"
TOOL_FRAME = "robocal_tool"


def _cyl(length: float, radius: float, along_x: bool = True) -> str:
    """A cylinder visual of `length` m centred half-way along x (or a flat disc about z)."""
    if along_x:
        return (f'<visual><origin xyz="{length / 2:.6g} 0 0" rpy="0 1.5707963267948966 0"/><geometry>'
                f'<cylinder radius="{radius:.6g}" length="{length:.6g}"/></geometry></visual>')
    return f'<visual><geometry><cylinder radius="{radius:.6g}" length="{length:.6g}"/></geometry></visual>'


def urdf_text(delta: dm.Delta, reflector_offset_m: float = 0.0) -> str:
    """The Delta's URDF (module docstring): links, the three actuator joints with their limits (rad),
    floating forearms and platform, the reflector as ``robocal_tool``."""
    parts = [f'<?xml version="1.0"?>\n<robot name="{delta.name.split(" (")[0].replace(" ", "_")}">',
             f'<link name="base">{_cyl(0.01, delta.a + 0.02, along_x=False)}</link>',
             f'<link name="platform">{_cyl(0.01, delta.b + 0.01, along_x=False)}</link>',
             f'<link name="{TOOL_FRAME}"/>',
             '<joint name="platform_pose" type="floating"><parent link="base"/><child link="platform"/></joint>',
             f'<joint name="reflector" type="fixed"><parent link="platform"/><child link="{TOOL_FRAME}"/>'
             f'<origin xyz="0 0 {-reflector_offset_m:.9g}"/></joint>']
    for i, phi in enumerate(delta.phi, start=1):
        x, y = delta.a * np.cos(phi), delta.a * np.sin(phi)
        parts += [f'<link name="upper_arm_{i}">{_cyl(delta.l1, 0.015)}</link>',
                  f'<link name="forearm_{i}">{_cyl(delta.l2, 0.008)}</link>',
                  f'<joint name="actuator_{i}" type="revolute"><parent link="base"/><child link="upper_arm_{i}"/>'
                  f'<origin xyz="{x:.9g} {y:.9g} 0" rpy="0 0 {phi:.17g}"/><axis xyz="0 -1 0"/>'
                  f'<limit lower="{delta.lower:.17g}" upper="{delta.upper:.17g}" effort="0" velocity="0"/></joint>',
                  f'<joint name="forearm_{i}_pose" type="floating"><parent link="base"/>'
                  f'<child link="forearm_{i}"/></joint>']
    return "\n".join(parts + ["</robot>"]) + "\n"


def _frame_x_along(d: np.ndarray) -> np.ndarray:
    """Rotations (N, 3, 3) whose x axis is the unit vector of d (N, 3), y horizontal where possible."""
    x = d / np.linalg.norm(d, axis=-1, keepdims=True)
    up = np.broadcast_to([0.0, 0.0, 1.0], x.shape)
    y = np.cross(up, x)
    n = np.linalg.norm(y, axis=-1, keepdims=True)
    y = np.where(n > 1e-9, y / np.where(n > 1e-9, n, 1.0), [0.0, 1.0, 0.0])
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def transforms(delta: dm.Delta, theta: np.ndarray, reflector_offset_m: float = 0.0):
    """(frame pairs [(parent, child)], T (N, K, 4, 4)) of the nominal Delta at actuator angles theta (N, 3)
    rad; postures the forward kinematics cannot assemble keep the platform at (0, 0, −l2)."""
    from pipeline.models.transforms import rot

    theta = np.atleast_2d(np.asarray(theta, float))
    n = theta.shape[0]
    beta = np.zeros(len(dm.beta_names(delta.n_legs)))
    p, ok = dm.forward(delta, beta, theta)
    p = np.where(ok[:, None], p, [0.0, 0.0, -delta.l2])
    g = dm.geometry(delta, beta, theta, p)
    pairs, mats = [("base", INSTRUMENT_FRAME)], [np.broadcast_to(np.eye(4), (n, 4, 4))]
    for i, phi in enumerate(delta.phi):
        T = np.zeros((n, 4, 4))
        T[:, 3, 3] = 1.0
        T[:, :3, :3] = rot("z", np.array([phi]))[0] @ rot("y", -theta[:, i])
        T[:, :3, 3] = g["base"][:, i]
        F = np.zeros((n, 4, 4))
        F[:, 3, 3] = 1.0
        F[:, :3, :3] = _frame_x_along(g["platform"][:, i] - g["elbow"][:, i])
        F[:, :3, 3] = g["elbow"][:, i]
        pairs += [("base", f"upper_arm_{i + 1}"), ("base", f"forearm_{i + 1}")]
        mats += [T, F]
    P = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    P[:, :3, 3] = p
    tool = np.eye(4)
    tool[2, 3] = -reflector_offset_m
    pairs += [("base", "platform"), ("platform", TOOL_FRAME)]
    mats += [P, np.broadcast_to(tool, (n, 4, 4))]
    return pairs, np.stack(mats, axis=1)


def frame_messages(delta: dm.Delta, theta: np.ndarray, t_ns: np.ndarray, reflector_offset_m: float = 0.0):
    """One ``foxglove.FrameTransforms`` message body per posture (theta (N, 3) rad, t_ns (N,))."""
    from scipy.spatial.transform import Rotation

    pairs, T = transforms(delta, theta, reflector_offset_m)
    quats = Rotation.from_matrix(T[..., :3, :3].reshape(-1, 3, 3)).as_quat().reshape(*T.shape[:2], 4)
    out = []
    for i, t in enumerate(np.asarray(t_ns, np.int64)):
        stamp = {"sec": int(t) // 1_000_000_000, "nsec": int(t) % 1_000_000_000}
        out.append({"transforms": [
            {"timestamp": stamp, "parent_frame_id": a, "child_frame_id": b,
             "translation": dict(zip("xyz", map(float, T[i, k, :3, 3]))),
             "rotation": dict(zip("xyzw", map(float, quats[i, k])))} for k, (a, b) in enumerate(pairs)]})
    return out
