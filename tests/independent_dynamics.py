"""Independent generator of dynamics logs: joint positions, velocities and efforts of a URDF arm whose true
inertials differ from its URDF's, with friction and physics the rigid-body model leaves out.

Shares no code with robocal: the true URDF is the nominal one with its `<inertial>` elements rewritten here
(ElementTree), the torques are Pinocchio's RNEA of that URDF (`pin.rnea`, the library's recursion, not
robocal's regressor), the trajectory is a sum of sines with rest windows written here with its exact
derivatives, and every friction or drive form is written from its physics below.  Writes the three CSV
tables FIGAROH ships (`t`, `- JOINT_position` …), which `robocal import csv --measure effort` reads.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

ARM = """<robot name="gen4">
  <link name="base"/>
  <link name="s1"><inertial><origin xyz="0.0 0.01 0.08" rpy="0 0 0"/><mass value="4.0"/>
    <inertia ixx="0.06" ixy="0.001" ixz="0" iyy="0.05" iyz="0.002" izz="0.03"/></inertial></link>
  <link name="s2"><inertial><origin xyz="0.22 0.0 0.01" rpy="0 0 0"/><mass value="3.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0.001" iyy="0.05" iyz="0" izz="0.05"/></inertial></link>
  <link name="s3"><inertial><origin xyz="0.15 0.01 0.0" rpy="0 0 0"/><mass value="1.8"/>
    <inertia ixx="0.006" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <link name="s4"><inertial><origin xyz="0.0 0.0 0.05" rpy="0 0 0"/><mass value="0.8"/>
    <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial></link>
  <joint name="a1" type="revolute"><parent link="base"/><child link="s1"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-2.8" upper="2.8" effort="80" velocity="1.6"/></joint>
  <joint name="a2" type="revolute"><parent link="s1"/><child link="s2"/><origin xyz="0 0 0.15" rpy="1.5708 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-1.8" upper="1.8" effort="80" velocity="1.6"/></joint>
  <joint name="a3" type="revolute"><parent link="s2"/><child link="s3"/><origin xyz="0.45 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-2.2" upper="2.2" effort="40" velocity="2.0"/></joint>
  <joint name="a4" type="revolute"><parent link="s3"/><child link="s4"/><origin xyz="0.35 0 0" rpy="0 1.5708 0"/>
    <axis xyz="0 0 1"/><limit lower="-2.8" upper="2.8" effort="10" velocity="2.5"/></joint>
</robot>"""
JOINTS = ["a1", "a2", "a3", "a4"]
PRESLIDING = 1e-4  # rad/s: Coulomb friction passes through zero over ±0.1 mrad/s (a rest is a rest, not ±f_c)
FRICTION = {"fv": (0.3, 0.5, 0.25, 0.1), "fc": (1.0, 1.4, 0.7, 0.3), "f0": (0.2, -0.3, 0.1, 0.05),
            "ia": (0.02, 0.03, 0.01, 0.004)}


def true_urdf(seed: int, text: str = ARM, error: float = 0.1) -> str:
    """The URDF with every link's mass and inertia × (1 + U(±error)) and centre of mass moved U(±2 cm)."""
    rng = np.random.default_rng(seed)
    root = ET.fromstring(text)
    for link in root.findall("link"):
        ine = link.find("inertial")
        if ine is None:
            continue
        k = 1 + rng.uniform(-error, error)
        m = ine.find("mass")
        m.set("value", repr(float(m.get("value")) * k))
        o = ine.find("origin")
        xyz = np.array([float(v) for v in o.get("xyz").split()]) + rng.uniform(-0.02, 0.02, 3)
        o.set("xyz", " ".join(repr(float(v)) for v in xyz))
        i = ine.find("inertia")
        for key in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz"):
            i.set(key, repr(float(i.get(key)) * k))
    return ET.tostring(root, encoding="unicode")


def _smoothstep(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic step S(x) from 0 (x ≤ 0) to 1 (x ≥ 1) and its first two derivatives."""
    x = np.clip(x, 0.0, 1.0)
    return 10 * x**3 - 15 * x**4 + 6 * x**5, 30 * x**2 - 60 * x**3 + 30 * x**4, 60 * x - 180 * x**2 + 120 * x**3


def _window(t: np.ndarray, rests: list[tuple[float, float]], ramp: float) -> tuple[np.ndarray, ...]:
    """A C² envelope (w, w', w'') that is 0 inside each rest window [a, b], 1 a ramp away from them (the
    windows apart by more than two ramps, so at most one shapes any instant)."""
    w, d1, d2 = np.ones_like(t), np.zeros_like(t), np.zeros_like(t)
    for a, b in rests:
        fall, f1, f2 = _smoothstep((t - (a - ramp)) / ramp)
        rise, r1, r2 = _smoothstep((t - b) / ramp)
        w += rise - fall
        d1 += (r1 - f1) / ramp
        d2 += (r2 - f2) / ramp**2
    return w, d1, d2


def trajectory(seed: int, duration: float = 40.0, rate: float = 100.0, text: str = ARM,
               joints: list[str] = JOINTS) -> tuple[np.ndarray, ...]:
    """(t, q, q̇, q̈): per joint four sines (0.05–0.45 Hz, random phases) about the middle of its range at up to
    70 % of the half-range (less where its velocity limit binds), with the arm at rest at the start, the end and in two 2 s windows between;
    exact derivatives."""
    rng = np.random.default_rng(seed + 1)
    root = ET.fromstring(text)
    lim = {j.get("name"): (float(j.find("limit").get("lower")), float(j.find("limit").get("upper")),
                           float(j.find("limit").get("velocity"))) for j in root.findall("joint") if j.find("limit") is not None}
    t = np.arange(0.0, duration, 1.0 / rate)
    rests = [(-1.0, 2.0), (0.35 * duration, 0.35 * duration + 2), (0.65 * duration, 0.65 * duration + 2),
             (duration - 2.5, duration + 1)]
    w, w1, w2 = _window(t, rests, 1.5)
    q, v, a = (np.zeros((t.size, len(joints))) for _ in range(3))
    for k, j in enumerate(joints):
        lo, hi, vmax = lim[j]
        f = rng.uniform(0.05, 0.45, 4)
        ph = rng.uniform(0, 2 * np.pi, 4)
        amp = rng.uniform(0.5, 1.0, 4)
        amp *= 0.7 * 0.5 * (hi - lo) / amp.sum()
        om = 2 * np.pi * f
        s = np.sum(amp * np.sin(om * t[:, None] + ph), axis=1)
        s1 = np.sum(amp * om * np.cos(om * t[:, None] + ph), axis=1)
        s2 = np.sum(-amp * om**2 * np.sin(om * t[:, None] + ph), axis=1)
        vk = w1 * s + w * s1
        c = min(1.0, 0.9 * vmax / np.abs(vk).max())  # within the joint's velocity limit
        q[:, k] = 0.5 * (lo + hi) + c * w * s
        v[:, k] = c * vk
        a[:, k] = c * (w2 * s + 2 * w1 * s1 + w * s2)
    return t, q, v, a


def rnea(text: str, q: np.ndarray, v: np.ndarray, a: np.ndarray, joints: list[str] = JOINTS) -> np.ndarray:
    """Inverse dynamics τ (T, J) of the URDF `text` by Pinocchio's RNEA (joints not listed at 0)."""
    m = pin.buildModelFromXML(text)
    d = m.createData()
    iq = [m.joints[m.getJointId(j)].idx_q for j in joints]
    iv = [m.joints[m.getJointId(j)].idx_v for j in joints]
    out = np.empty_like(q)
    Q, V, A = np.zeros(m.nq), np.zeros(m.nv), np.zeros(m.nv)
    for i in range(q.shape[0]):
        Q[iq], V[iv], A[iv] = q[i], v[i], a[i]
        out[i] = pin.rnea(m, d, Q, V, A)[iv]
    return out


def efforts(seed: int, t, q, v, a, noise: float = 0.05, effects: dict | None = None, error: float = 0.1,
            text: str = ARM, joints: list[str] = JOINTS) -> tuple[np.ndarray, str]:
    """(efforts (T, J) N·m, the true URDF): RNEA of the perturbed URDF + viscous, Coulomb (the sign of v, through zero
    over ±`PRESLIDING`), offset and rotor
    inertia, + the `effects` {name: (joint index or None, value, option)}, + N(0, noise²)."""
    rng = np.random.default_rng(seed + 2)
    truth = true_urdf(seed, text, error)
    rigid = rnea(truth, q, v, a, joints)
    if "joint_elasticity" in (effects or {}):  # the link lags the motor-side reading q by c·τ: solve τ = RNEA(q − c·τ)
        k, c, _ = effects["joint_elasticity"]
        from scipy.signal import butter, filtfilt

        b, a_ = butter(2, 3.0, fs=1.0 / (t[1] - t[0]))
        for _ in range(4):  # the link's motion is the reading's less c·(τ, τ̇, τ̈), quasi-static: the torque's
            # derivatives from its content below 3 Hz (far below the joint's resonance, which this model leaves out)
            d1 = np.gradient(filtfilt(b, a_, rigid[:, k]), t, edge_order=2)
            ql, vl, al = q.copy(), v.copy(), a.copy()
            ql[:, k] -= c * rigid[:, k]
            vl[:, k] -= c * d1
            al[:, k] -= c * np.gradient(d1, t, edge_order=2)
            rigid = rnea(truth, ql, vl, al, joints)
    tau = rigid + np.asarray(FRICTION["fv"]) * v + np.asarray(FRICTION["fc"]) * np.tanh(v / PRESLIDING) + \
        np.asarray(FRICTION["f0"]) + np.asarray(FRICTION["ia"]) * a
    span = t[-1] - t[0]
    for name, (k, val, opt) in (effects or {}).items():
        if name == "stribeck":  # the breakaway bump above Coulomb at low speed, Gaussian in v / v_s
            tau[:, k] += val * np.exp(-(v[:, k] / opt) ** 2) * np.sign(v[:, k])
        elif name == "asymmetric_coulomb":  # a Coulomb level that differs with direction: + while moving
            tau[:, k] += val * (np.abs(v[:, k]) > 1e-6)
        elif name == "load_friction":  # friction proportional to the transmitted torque
            tau[:, k] += val * np.abs(rigid[:, k]) * np.sign(v[:, k])
        elif name == "friction_drift":  # Coulomb rising linearly by `val` over the session
            tau[:, k] += val * ((t - t[0]) / span - 0.5) * np.sign(v[:, k])
        elif name == "cable_spring":  # a spring across the joint about its range's middle
            tau[:, k] -= val * (q[:, k] - opt)
        elif name == "position_torque":  # periodic in the joint's angle
            tau[:, k] += val * np.sin(opt * q[:, k] + 0.4)
        elif name == "drive_scale":  # the drive reports (1 + s) × the torque
            tau[:, k] *= 1 + val
    if "time_offset" in (effects or {}):  # the effort stream late by δ
        delay = effects["time_offset"][1]
        tau = np.stack([np.interp(t - delay, t, tau[:, k]) for k in range(tau.shape[1])], axis=1)
    return tau + rng.normal(0.0, noise, tau.shape), truth


def write_tables(folder: Path, t, q, v, e, joints: list[str] = JOINTS) -> tuple[Path, Path, Path]:
    """The position, velocity and effort tables (FIGAROH's layout: `t`, then `- JOINT_kind` columns)."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for kind, x in (("position", q), ("velocity", v), ("effort", e)):
        p = folder / f"gen_{kind}.csv"
        head = "t," + ",".join(f"- {j}_{kind}" for j in joints)
        np.savetxt(p, np.column_stack([t, x]), delimiter=",", header=head, comments="", fmt="%.10g")
        out.append(p)
    return tuple(out)


def true_parameters(truth: str, joints: list[str] = JOINTS) -> np.ndarray:
    """θ of the truth in the order an identification names them: per joint's body m, m·c (3), inertia about the
    joint frame (xx, xy, yy, xz, yz, zz) — Pinocchio's dynamic parameters — then per joint fv, fc, f0, Ia."""
    m = pin.buildModelFromXML(truth)
    pi = np.concatenate([m.inertias[m.getJointId(j)].toDynamicParameters() for j in joints])
    fr = np.stack([FRICTION["fv"], FRICTION["fc"], FRICTION["f0"], FRICTION["ia"]], axis=1).ravel()
    return np.concatenate([pi, fr])
