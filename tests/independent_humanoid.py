"""An independent generator of a dual-arm humanoid upper body that bends under gravity.

It shares NO code with robocal (no `pipeline` import): its own robot (a kinematic tree written out as
a URDF with `<inertial>` elements), its own forward kinematics over the tree (products of 4×4
homogeneous matrices), its own whole-tree gravity (the moment of every link a joint carries — the
other arm and the head included — about the joint's origin) and its own elastic model, solved at
static equilibrium by fixed-point iteration:

- joint compliance:   the joint turns by δq_j = c_j · (z_j · M_j)           (rad, c_j in rad/(N·m));
                      with a load-dependent stiffness k_j(τ) = 1/c_j + h_j·|τ| (a harmonic drive stiffens
                      as its load grows; h_j in 1/rad), δq_j = τ / k_j(τ), τ = z_j · M_j;
- lateral compliance: the joint's child frame tilts about the two axes normal to the joint's axis,
                      by c⊥1_j · (e1_j · M_j) and c⊥2_j · (e2_j · M_j)    (rad; one value or one per normal),
  where M_j = Σ_l (p_l − o_j) × (m_l · g) over every link l below joint j in the tree (N·m, world
  frame), o_j the joint's origin and (z_j, e1_j, e2_j) its axis and two normals, all at the deflected
  configuration (the iteration converges to the equilibrium; ~1e-9 rad after 8 passes here).

The torso is a three-joint pitch chain whose last joint is driven by the other two,
q3 = −q1 − q2 (the chest stays level, as on humanoids with a parallel torso linkage); the CSV
carries only the two driven joints. Optional reading errors of the encoders (off by default): an
eccentric encoder disc, q_true = q_read + a·sin q_read + b·cos q_read (rad), and a gear-ratio error,
q_true = q_read + s·q_read, on chosen read joints (before the torso coupling); a transmission through the
joint before it on the arm (cables, belts), q_true = q_read + κ·q_read(driver), the driver's raw reading; free play (backlash) b,
q_true = q_read + b·d/2 with d = ±1 the joint's direction of approach at the posture (drawn at random
per posture and joint, written as the columns `dir_<joint>`). Geometry errors: joint offsets and origin perturbations (mm,
mrad) of every joint; a motion-capture frame with an unknown pose; one marker per hand at an
unknown offset. Measurements: both hand markers in the motion-capture frame with isotropic
Gaussian noise (m).  The robot's true masses may differ from the URDF's (`mass_error`: each link's mass
scaled by its own factor, its centre of mass moved; the URDF written is the nominal one): the gravity loads
the calibrated model computes from the URDF are then not the true ones.

`write(out_dir, seed=…)` writes `humanoid.urdf` (nominal), `postures.csv` (one row per posture:
the 14 arm and 2 torso joint readings in rad, then `lx,ly,lz,rx,ry,rz` in m) and `truth.json`.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

G = np.array([0.0, 0.0, -9.80665])  # m/s², −z of the base link


# ----- 4×4 algebra -------------------------------------------------------------------------
def rot_axis(axis, angle) -> np.ndarray:
    """(…, 4, 4) rotation about a unit axis (3,) by angles (…) (Rodrigues)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    a = np.asarray(angle, float)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    s, c = np.sin(a)[..., None, None], np.cos(a)[..., None, None]
    T = np.broadcast_to(np.eye(4), a.shape + (4, 4)).copy()
    T[..., :3, :3] = np.eye(3) + s * K + (1 - c) * (K @ K)
    return T


def origin(xyz, rpy) -> np.ndarray:
    """URDF origin: translation xyz (m), then fixed-axis roll, pitch, yaw (rad): Rz(y)·Ry(p)·Rx(r)."""
    r, p, y = rpy
    T = rot_axis([0, 0, 1], y) @ rot_axis([0, 1, 0], p) @ rot_axis([1, 0, 0], r)
    T[:3, 3] = xyz
    return T


def normals(axis) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors normal to `axis` and to each other (a right-handed set e1, e2, axis)."""
    z = np.asarray(axis, float) / np.linalg.norm(axis)
    a = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(a, z)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(z, e1)


# ----- the robot ---------------------------------------------------------------------------
@dataclass
class Joint:
    name: str
    parent: str
    child: str
    xyz: tuple
    rpy: tuple = (0.0, 0.0, 0.0)
    axis: tuple = (0.0, 0.0, 1.0)
    kind: str = "revolute"  # or "fixed"
    limit: tuple = (-2.5, 2.5)


@dataclass
class Link:
    name: str
    mass: float = 0.0  # kg
    com: tuple = (0.0, 0.0, 0.0)  # m, link frame


def _arm(side: str, sign: float) -> tuple[list[Joint], list[Link]]:
    s = side
    joints = [
        Joint(f"{s}_j1", "chest", f"{s}_shoulder", (0.0, sign * 0.22, 0.25), axis=(0, 1, 0), limit=(-1.4, 1.4)),
        Joint(f"{s}_j2", f"{s}_shoulder", f"{s}_upper", (0.0, sign * 0.08, 0.0), axis=(1, 0, 0),
              limit=(-0.3, 1.2) if sign > 0 else (-1.2, 0.3)),
        Joint(f"{s}_j3", f"{s}_upper", f"{s}_upper2", (0.0, 0.0, -0.16), axis=(0, 0, 1), limit=(-1.2, 1.2)),
        Joint(f"{s}_j4", f"{s}_upper2", f"{s}_fore", (0.02, 0.0, -0.16), axis=(0, 1, 0), limit=(-2.0, -0.2)),
        Joint(f"{s}_j5", f"{s}_fore", f"{s}_fore2", (0.0, 0.0, -0.14), axis=(0, 0, 1), limit=(-1.2, 1.2)),
        Joint(f"{s}_j6", f"{s}_fore2", f"{s}_hand", (0.0, 0.0, -0.14), axis=(0, 1, 0), limit=(-1.0, 1.0)),
    ]
    links = [Link(f"{s}_shoulder", 2.0, (0, sign * 0.03, 0)), Link(f"{s}_upper", 3.0, (0, 0, -0.08)),
             Link(f"{s}_upper2", 2.0, (0, 0, -0.08)), Link(f"{s}_fore", 2.0, (0, 0, -0.07)),
             Link(f"{s}_fore2", 1.5, (0, 0, -0.07)), Link(f"{s}_hand", 1.5, (0, 0, -0.06))]
    return joints, links


def humanoid() -> tuple[list[Joint], list[Link]]:
    """The nominal robot: base → torso pitch ×3 (the third coupled) → chest → head and two 6-dof arms."""
    joints = [
        Joint("torso_j1", "base", "torso1", (0.0, 0.0, 0.35), axis=(0, 1, 0), limit=(-0.3, 0.9)),
        Joint("torso_j2", "torso1", "torso2", (0.0, 0.0, 0.30), axis=(0, 1, 0), limit=(-1.2, 0.3)),
        Joint("torso_j3", "torso2", "chest", (0.0, 0.0, 0.30), axis=(0, 1, 0), limit=(-1.5, 1.5)),
        Joint("neck", "chest", "head", (0.0, 0.0, 0.40), kind="fixed"),
    ]
    links = [Link("base", 20.0, (0, 0, 0.1)), Link("torso1", 8.0, (0, 0, 0.15)), Link("torso2", 8.0, (0, 0, 0.15)),
             Link("chest", 15.0, (0.0, 0, 0.2)), Link("head", 4.0, (0.03, 0, 0.08))]
    for side, sign in (("left", 1.0), ("right", -1.0)):
        j, lk = _arm(side, sign)
        joints += j
        links += lk
    return joints, links


COUPLED = {"torso_j3": {"torso_j1": -1.0, "torso_j2": -1.0}}
READ = [j.name for j in humanoid()[0] if j.kind != "fixed" and j.name not in COUPLED]
TIPS = {"left": "left_hand", "right": "right_hand"}


def urdf_text(joints: list[Joint], links: list[Link], name: str = "humanoid") -> str:
    """The robot as URDF text (inertials with a small diagonal inertia; no meshes)."""
    out = [f'<robot name="{name}">']
    for lk in links:
        if lk.mass > 0:
            c = " ".join(f"{v:.6g}" for v in lk.com)
            out.append(f'  <link name="{lk.name}"><inertial><origin xyz="{c}" rpy="0 0 0"/>'
                       f'<mass value="{lk.mass:.6g}"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" '
                       f'izz="0.01"/></inertial></link>')
        else:
            out.append(f'  <link name="{lk.name}"/>')
    for j in joints:
        xyz, rpy, ax = (" ".join(f"{v:.9g}" for v in t) for t in (j.xyz, j.rpy, j.axis))
        body = f'<parent link="{j.parent}"/><child link="{j.child}"/><origin xyz="{xyz}" rpy="{rpy}"/>'
        if j.kind != "fixed":
            body += (f'<axis xyz="{ax}"/><limit lower="{j.limit[0]:.6g}" upper="{j.limit[1]:.6g}" '
                     f'effort="200" velocity="1"/>')
        out.append(f'  <joint name="{j.name}" type="{j.kind}">{body}</joint>')
    out.append("</robot>")
    return "\n".join(out) + "\n"


# ----- kinematics and gravity over the tree ------------------------------------------------
def link_frames(joints, q: dict[str, np.ndarray], tilt: dict[str, np.ndarray] | None = None) -> dict:
    """{link: (n, 4, 4) pose in the base frame}; `q` joint angles (n,) by name, `tilt` (n, 2) lateral
    rotations (rad) about each joint's normals (e1, e2), applied at the joint's origin after its turn."""
    n = len(next(iter(q.values())))
    frames = {"base": np.broadcast_to(np.eye(4), (n, 4, 4)).copy()}
    for j in joints:
        T = frames[j.parent] @ origin(j.xyz, j.rpy)
        if j.kind != "fixed":
            T = T @ rot_axis(j.axis, q[j.name])
            if tilt is not None and j.name in tilt:
                e1, e2 = normals(j.axis)
                T = T @ rot_axis(e1, tilt[j.name][:, 0]) @ rot_axis(e2, tilt[j.name][:, 1])
        frames[j.child] = T
    return frames


def subtree(joints, link: str) -> list[str]:
    """Every link at or below `link` in the tree."""
    out, todo = [], [link]
    while todo:
        lk = todo.pop()
        out.append(lk)
        todo += [j.child for j in joints if j.parent == lk]
    return out


def gravity_moments(joints, links, frames, payload: dict | None = None) -> dict[str, np.ndarray]:
    """{joint: (n, 3) moment of gravity, N·m in the base frame, about the joint's origin} of every
    link (and payload {link: (kg, com (3,) m)}) the joint carries in the tree."""
    mass = {lk.name: (lk.mass, np.asarray(lk.com, float)) for lk in links if lk.mass > 0}
    for lk, (m, c) in (payload or {}).items():
        m0, c0 = mass.get(lk, (0.0, np.zeros(3)))
        mass[lk] = (m0 + m, (m0 * c0 + m * np.asarray(c, float)) / (m0 + m))
    out = {}
    for j in joints:
        if j.kind == "fixed":
            continue
        o = (frames[j.parent] @ origin(j.xyz, j.rpy))[:, :3, 3]
        M = 0.0
        for lk in subtree(joints, j.child):
            if lk in mass:
                m, c = mass[lk]
                p = (frames[lk] @ np.append(c, 1.0))[:, :3]
                M = M + np.cross(p - o, m * G)
        out[j.name] = M
    return out


def joint_axes(joints, frames) -> dict[str, tuple]:
    """{joint: ((n, 3) axis, e1, e2) in the base frame} at the joint's child frame."""
    out = {}
    for j in joints:
        if j.kind == "fixed":
            continue
        R = frames[j.child][:, :3, :3]
        e1, e2 = normals(j.axis)
        out[j.name] = (R @ np.asarray(j.axis, float) / np.linalg.norm(j.axis), R @ e1, R @ e2)
    return out


def equilibrium(joints, links, q: dict, compliance: dict, lateral: dict, payload=None, passes: int = 12,
                hardening: dict | None = None):
    """Deflected angles and tilts at static equilibrium (fixed-point iteration from no deflection);
    `lateral` {joint: c or (c1, c2)}, `hardening` {joint: h} (1/rad: the stiffness 1/c + h·|τ|).
    Returns (q_true {joint: (n,)}, tilt {joint: (n, 2)}, moments of the last pass, residual of the last
    update in rad)."""
    hardening = hardening or {}
    qd, tilt, step = dict(q), {}, np.inf
    for _ in range(passes):
        frames = link_frames(joints, qd, tilt)
        M = gravity_moments(joints, links, frames, payload)
        ax = joint_axes(joints, frames)
        new_q, new_tilt = dict(q), {}
        for name, c in compliance.items():
            tau = np.einsum("ni,ni->n", ax[name][0], M[name])
            new_q[name] = q[name] + tau / (1.0 / c + hardening.get(name, 0.0) * np.abs(tau))
        for name, c in lateral.items():
            c2 = np.broadcast_to(np.asarray(c, float), (2,))
            new_tilt[name] = c2 * np.stack([np.einsum("ni,ni->n", ax[name][k], M[name]) for k in (1, 2)], 1)
        step = max([np.max(np.abs(new_q[k] - qd[k])) for k in compliance] +
                   [np.max(np.abs(new_tilt[k] - tilt.get(k, 0.0))) for k in lateral] + [0.0])
        qd, tilt = new_q, new_tilt
    return qd, tilt, M, step


# ----- a campaign --------------------------------------------------------------------------
@dataclass
class Truth:
    joint_offset: dict = field(default_factory=dict)  # rad
    origin_dxyz: dict = field(default_factory=dict)  # m
    origin_drpy: dict = field(default_factory=dict)  # rad
    compliance: dict = field(default_factory=dict)  # rad/(N·m)
    lateral: dict = field(default_factory=dict)  # rad/(N·m): one for both normal axes, or (c1, c2)
    hardening: dict = field(default_factory=dict)  # 1/rad: joint stiffness 1/c + h·|τ| (load-dependent)
    mass_scale: dict = field(default_factory=dict)  # {link: factor}: the true mass over the URDF's
    com_shift: dict = field(default_factory=dict)  # {link: (3,) m}: the true centre of mass minus the URDF's
    eccentricity: dict = field(default_factory=dict)  # {joint: (a, b)} rad: δq = a·sin q + b·cos q
    scale: dict = field(default_factory=dict)  # {joint: s}: δq = s·q (a gear ratio off by s)
    backlash: dict = field(default_factory=dict)  # {joint: b} rad: δq = b·d/2, d = ±1 the direction of approach
    coupling: dict = field(default_factory=dict)  # {joint: (driver, κ)}: δq = κ·q_read(driver), rad/rad
    marker: dict = field(default_factory=dict)  # m, in the hand link's frame
    registration_xyz: tuple = (0.0, 0.0, 0.0)  # m: the mocap frame's pose in the base frame
    registration_rpy: tuple = (0.0, 0.0, 0.0)


def default_truth(rng: np.random.Generator, geometry: bool = True) -> Truth:
    """Stiffnesses of a light humanoid (torso 2–4·10⁴, shoulders 0.8–1.5·10⁴ N·m/rad; lateral at the
    lowest torso joint 5·10⁴) and, if `geometry`, offsets of ±1 mrad, origins ±0.5 mm / ±1 mrad."""
    joints, _ = humanoid()
    t = Truth()
    movable = [j.name for j in joints if j.kind != "fixed"]
    if geometry:
        t.joint_offset = {k: float(rng.uniform(-1e-3, 1e-3)) for k in movable}
        t.origin_dxyz = {k: rng.uniform(-5e-4, 5e-4, 3).tolist() for k in movable}
        t.origin_drpy = {k: rng.uniform(-1e-3, 1e-3, 3).tolist() for k in movable}
    t.compliance = {"torso_j1": 1 / 3.0e4, "torso_j2": 1 / 2.0e4, "left_j1": 1 / 1.2e4, "right_j1": 1 / 1.0e4,
                    "left_j2": 1 / 1.5e4, "right_j2": 1 / 0.8e4}
    t.lateral = {"torso_j1": 1 / 5.0e4}
    t.marker = {"left": [0.01, 0.02, -0.08], "right": [-0.01, -0.02, -0.08]}
    t.registration_xyz = (1.8, -0.4, 0.05)
    t.registration_rpy = (0.01, -0.02, 2.6)
    return t


def whole_truth(t: Truth, rng: np.random.Generator) -> Truth:
    """`t` made a soft, torque-controlled humanoid (the physics a whole-robot calibration must find): every
    arm joint compliant (stiffness 2–8·10³ N·m/rad, the wrist's softest), lateral compliance at the torso,
    shoulders and elbows with a different value about each normal (2–8·10⁴ N·m/rad), the torso and
    shoulders stiffening with their load (h: the stiffness doubles at 20–60 N·m), and the true masses off the
    URDF's by ±15 % (centres of mass by ±1 cm)."""
    joints, links = humanoid()
    arm = [j.name for j in joints if j.name.startswith(("left_", "right_"))]
    t.compliance = dict(t.compliance) | {k: float(1 / rng.uniform(2e3, 8e3)) for k in arm if k not in t.compliance}
    lat = ["torso_j1", "torso_j2"] + [f"{s}_j{i}" for s in ("left", "right") for i in (1, 2, 4)]
    t.lateral = {k: tuple(float(1 / v) for v in rng.uniform(2e4, 8e4, 2)) for k in lat}
    t.hardening = {k: float(rng.uniform(20, 60) ** -1 / t.compliance[k])
                   for k in ("torso_j1", "torso_j2", "left_j1", "right_j1", "left_j2", "right_j2")}
    t.mass_scale = {lk.name: float(rng.uniform(0.85, 1.15)) for lk in links if lk.mass > 0}
    t.com_shift = {lk.name: rng.uniform(-0.01, 0.01, 3).tolist() for lk in links if lk.mass > 0}
    return t


def true_links(t: Truth) -> list[Link]:
    """The nominal links with the truth's mass factors and centre-of-mass shifts applied."""
    return [Link(lk.name, lk.mass * t.mass_scale.get(lk.name, 1.0),
                 tuple(np.add(lk.com, t.com_shift.get(lk.name, (0.0, 0.0, 0.0))))) for lk in humanoid()[1]]


def true_robot(t: Truth) -> list[Joint]:
    """The nominal joints with the truth's origin errors applied."""
    joints, _ = humanoid()
    out = []
    for j in joints:
        dx, dr = np.asarray(t.origin_dxyz.get(j.name, (0, 0, 0))), np.asarray(t.origin_drpy.get(j.name, (0, 0, 0)))
        out.append(Joint(j.name, j.parent, j.child, tuple(np.add(j.xyz, dx)), tuple(np.add(j.rpy, dr)),
                         j.axis, j.kind, j.limit))
    return out


def postures(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """n joint readings (rad) of the driven joints, uniform inside 90 % of each joint's limits."""
    joints, _ = humanoid()
    out = {}
    for j in joints:
        if j.name in READ:
            lo, hi = j.limit
            mid, half = (lo + hi) / 2, 0.45 * (hi - lo)
            out[j.name] = rng.uniform(mid - half, mid + half, n)
    return out


def measure(t: Truth, q_read: dict, noise_m: float, rng: np.random.Generator, payload=None,
            approach: dict | None = None) -> dict:
    """Marker positions (n, 3) per hand in the mocap frame, at static equilibrium, with noise; `approach`
    {joint: (n,) ±1} the directions of approach (needed where the truth has backlash)."""
    joints, links = true_robot(t), true_links(t)
    turned = {k: v + t.scale.get(k, 0.0) * v for k, v in q_read.items()}  # the motor's true turn
    for k, (a, b) in t.eccentricity.items():
        turned[k] = turned[k] + a * np.sin(q_read[k]) + b * np.cos(q_read[k])
    for k, b in t.backlash.items():
        turned[k] = turned[k] + 0.5 * b * np.asarray(approach[k], float)
    for k, (drv, kappa) in t.coupling.items():
        turned[k] = turned[k] + kappa * q_read[drv]
    q = {k: v + t.joint_offset.get(k, 0.0) for k, v in turned.items()}
    for name, comb in COUPLED.items():
        q[name] = sum(c * turned[k] for k, c in comb.items()) + t.joint_offset.get(name, 0.0)
    qd, tilt, _, step = equilibrium(joints, links, q, t.compliance, t.lateral, payload, hardening=t.hardening)
    assert step < 1e-9, step
    frames = link_frames(joints, qd, tilt)
    T_base_mocap = origin(t.registration_xyz, t.registration_rpy)
    inv = np.linalg.inv(T_base_mocap)
    out = {}
    for side, tip in TIPS.items():
        p = frames[tip] @ np.append(t.marker[side], 1.0)
        y = (inv @ p[..., None])[..., :3, 0]
        out[side] = y + rng.normal(0.0, noise_m, y.shape)
    return out


def write(out_dir: Path, seed: int = 0, n: int = 300, noise_m: float = 2e-4, geometry: bool = True,
          session: int | None = None, eccentricity: dict | None = None, scale: dict | None = None,
          backlash: dict | None = None, directions: bool = False, coupling: dict | None = None,
          whole: bool = False) -> Path:
    """humanoid.urdf (nominal), postures.csv and truth.json under `out_dir`; returns the folder.  The robot
    (truth) comes from `seed`; `session` (default: the same stream) draws another set of postures and noise
    of the same robot — a second measurement session.  `eccentricity` {joint: (a, b) rad} and `scale`
    {joint: s} add encoder errors to read joints (none by default); `backlash` {joint: b rad} a free play,
    `directions` (implied by `backlash`) the columns `dir_<joint>` (±1, drawn per posture and joint);
    `coupling` {joint: (driver, κ)} a reading of `joint` off by κ times the driver's reading; `whole` the
    physics of a soft humanoid besides (`whole_truth`: every arm joint compliant, lateral compliance per
    normal, load-dependent stiffness, masses off the URDF's)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    t = default_truth(rng, geometry)
    t.eccentricity = {k: tuple(map(float, v)) for k, v in (eccentricity or {}).items()}
    t.scale = {k: float(v) for k, v in (scale or {}).items()}
    t.backlash = {k: float(v) for k, v in (backlash or {}).items()}
    t.coupling = {k: (str(drv), float(kappa)) for k, (drv, kappa) in (coupling or {}).items()}
    if whole:  # its own stream: the robot of `seed` is otherwise the same
        t = whole_truth(t, np.random.default_rng([seed, 7]))
    if session is not None:
        rng = np.random.default_rng([seed, session])
    joints, links = humanoid()
    (out_dir / "humanoid.urdf").write_text(urdf_text(joints, links))
    q = postures(rng, n)
    drng = np.random.default_rng([seed, 0 if session is None else session, 99])  # its own stream
    d = {k: drng.choice([-1, 1], n) for k in READ} if (directions or backlash) else {}
    y = measure(t, q, noise_m, rng, approach=d)
    cols = READ + ["lx", "ly", "lz", "rx", "ry", "rz"] + [f"dir_{k}" for k in d]
    data = np.column_stack([q[k] for k in READ] + [y["left"], y["right"]] + [d[k] for k in d])
    lines = [",".join(cols)] + [",".join(f"{v:.12g}" for v in row) for row in data]
    (out_dir / "postures.csv").write_text("\n".join(lines) + "\n")
    truth = {"noise_m": noise_m, "n": n, "seed": seed, "session": session, "coupled": COUPLED,
             "stiffness_Nm_per_rad": {k: 1 / v for k, v in t.compliance.items()},
             "lateral_stiffness_Nm_per_rad": {k: (1 / np.asarray(v, float)).tolist() for k, v in t.lateral.items()},
             **{k: v for k, v in vars(t).items()}}
    (out_dir / "truth.json").write_text(json.dumps(truth, indent=1, default=list) + "\n")
    return out_dir


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--noise-m", type=float, default=2e-4)
    ap.add_argument("--whole", action="store_true", help="a soft humanoid's whole physics (whole_truth)")
    a = ap.parse_args()
    print(write(a.out, a.seed, a.n, a.noise_m, whole=a.whole))
