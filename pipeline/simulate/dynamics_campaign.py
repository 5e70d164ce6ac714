"""A dynamics campaign with known truth: a URDF robot with perturbed inertials, friction, rotor inertia and
physics the rigid-body model leaves out, run along an excitation trajectory, its efforts logged with noise.

- `random_truth`: each recorded joint's child link with its mass and inertia scaled and its centre of mass
  moved (a physically consistent body: `pin.Inertia`), and per fitted joint viscous, Coulomb, offset
  friction and rotor inertia drawn in plausible ranges;
- `EFFECTS`: physics injected beyond the model, each written here as the physics (not as the diagnosis
  library's columns): Stribeck, direction-dependent Coulomb, load-dependent friction, friction that
  drifts over the session, a torque periodic in the joint angle, a cable spring, a drive-scale error, an
  effort stream late by δ, an elastic joint (the link lagging the motor-side reading by c·τ);
- `efforts`: the torques the drives report, N·m (N), by Pinocchio's RNEA on the true bodies plus friction
  and effects, with white noise.

Pure numpy functions of (truth, trajectory); the command line (`robocal simulate dynamics`) writes the
recording and the truth file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.dynamics.rigid_body import RigidBody, link_parameters, torques
from pipeline.errors import RobocalError

REST = 1e-6  # rad/s (m/s): slower than this the joint rests
STRIBECK_VS = 0.05  # rad/s (m/s): the default Stribeck velocity of an injected bump
EFFECTS = {
    "stribeck": "f_s N·m (v_s rad/s after /, default 0.05): f_s·exp(−(v/v_s)²)·sign(v) above Coulomb",
    "asymmetric_coulomb": "f_a N·m: a Coulomb level f_a higher while moving (either direction) than the offset at rest",
    "load_friction": "μ: friction μ·|τ_rigid|·sign(v) growing with the transmitted torque",
    "friction_drift": "Δf_c N·m: Coulomb friction rising linearly by Δf_c over the session (a warming gearbox)",
    "position_torque": "a N·m (harmonic n after /, default 2): a·sin(n·q + 0.7)",
    "cable_spring": "k N·m/rad: −k·(q − the middle of the joint's travel)",
    "drive_scale": "s: the effort reads (1 + s) × the torque",
    "time_offset": "δ s: the effort stream δ late (stream-wide; write time_offset=δ)",
    "joint_elasticity": "c rad/(N·m): the link lags the motor-side reading by c·τ",
}


@dataclass(frozen=True)
class Truth:
    """π (J·10,) the bodies' true standard parameters; per fitted joint (F,) viscous, Coulomb, offset, rotor
    inertia; `effects` [(name, joint or None, value, option or None)]."""

    pi: np.ndarray
    fv: np.ndarray
    fc: np.ndarray
    f0: np.ndarray
    ia: np.ndarray
    effects: tuple = ()


def random_truth(rb: RigidBody, fit: np.ndarray, seed: int, inertia_error: float = 0.1,
                 friction_scale: float = 1.0) -> Truth:
    """Perturbed bodies (mass and inertia × (1 + e), e ~ U(±inertia_error); centre of mass moved by
    U(±inertia_error) × 5 cm per axis) and friction drawn per fitted joint (× `friction_scale`)."""
    rng = np.random.default_rng(seed)
    own = link_parameters(rb)
    pi = rb.carried.copy()
    for k in range(rb.n_joints):
        ine = pin.Inertia.FromDynamicParameters(own[10 * k:10 * k + 10])
        m = max(ine.mass, 1e-3) * (1 + rng.uniform(-inertia_error, inertia_error))
        c = np.asarray(ine.lever) + rng.uniform(-1, 1, 3) * inertia_error * 0.05
        Ic = np.asarray(ine.inertia) * (1 + rng.uniform(-inertia_error, inertia_error))
        if not np.all(np.linalg.eigvalsh(Ic) > 0):
            Ic = np.eye(3) * 1e-4
        pi[10 * k:10 * k + 10] += pin.Inertia(m, c, Ic).toDynamicParameters()
    F = int(np.sum(fit))
    return Truth(pi, friction_scale * rng.uniform(0.05, 0.5, F), friction_scale * rng.uniform(0.2, 1.5, F),
                 friction_scale * rng.uniform(-0.5, 0.5, F), rng.uniform(0.0, 0.05, F))


def parse_effects(items: list[str], joints: list[str], fitted: list[str]) -> tuple:
    """``NAME:JOINT=VALUE[/OPTION]`` or ``time_offset=VALUE`` (repeatable) → ((name, joint, value, option), …);
    one line for an unknown name, a joint that is not fitted or a value that is not a number."""
    out = []
    for text in items:
        head, sep, val = text.partition("=")
        name, _, joint = head.partition(":")
        name, joint = name.strip(), joint.strip() or None
        val, _, opt = val.partition("/")
        if name not in EFFECTS or not sep:
            raise RobocalError(f"--effect {text!r}: expected NAME:JOINT=VALUE with NAME one of {', '.join(EFFECTS)}")
        if (name == "time_offset") != (joint is None):
            raise RobocalError(f"--effect {text!r}: " + ("time_offset=δ takes no joint" if joint else
                                                         f"{name} needs a joint, {name}:JOINT=VALUE"))
        if joint is not None and joint not in fitted:
            raise RobocalError(f"--effect {text!r}: {joint!r} is not a fitted joint ({', '.join(fitted)})")
        try:
            v, o = float(val), (float(opt) if opt else None)
        except ValueError:
            raise RobocalError(f"--effect {text!r}: {val!r} is not a number") from None
        if not np.isfinite(v) or (o is not None and not np.isfinite(o)):
            raise RobocalError(f"--effect {text!r}: not a finite number")
        out.append((name, joint, v, o))
    return tuple(out)


def _derivatives(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = np.gradient(x, t, axis=0, edge_order=2)
    return d, np.gradient(d, t, axis=0, edge_order=2)


def efforts(rb: RigidBody, truth: Truth, fit: np.ndarray, t: np.ndarray, q: np.ndarray, v: np.ndarray,
            a: np.ndarray, noise: float, seed: int, limits: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The efforts (T, J) the drives report along (t, q, v, a) (module docstring); joints not fitted report
    their rigid-body torque with the same noise."""
    rng = np.random.default_rng(seed + 7919)
    idx = np.flatnonzero(fit)
    ql, vl, al = q, v, a
    eff = {name: [] for name in EFFECTS}
    for e in truth.effects:
        eff[e[0]].append(e)
    c = np.zeros(rb.n_joints)
    for _, j, val, _ in eff["joint_elasticity"]:
        c[list(rb.joints).index(j)] = val
    rigid = torques(rb, ql, vl, al, truth.pi)
    for _ in range(4 if c.any() else 0):  # the link lags the motor-side reading: q_link = q − c·τ (fixed point)
        ql = q - c * rigid
        vl, al = _derivatives(t, ql)
        rigid = torques(rb, ql, vl, al, truth.pi)
    tau = rigid.copy()
    span = max(float(t[-1] - t[0]), 1e-9)
    for f, j in enumerate(idx):
        s = np.sign(v[:, j]) * (np.abs(v[:, j]) > REST)  # at rest (a table's rounding aside) no Coulomb friction
        tau[:, j] += truth.fv[f] * v[:, j] + truth.fc[f] * s + truth.f0[f] + truth.ia[f] * a[:, j]
    col = {name: list(rb.joints).index(name) for name in rb.joints}
    for name, j, val, opt in truth.effects:
        if j is None:
            continue
        k, vk = col[j], v[:, col[j]]
        if name == "stribeck":
            tau[:, k] += val * np.exp(-(vk / (opt or STRIBECK_VS)) ** 2) * np.sign(vk)
        elif name == "asymmetric_coulomb":
            tau[:, k] += val * (np.abs(vk) > 1e-4)
        elif name == "load_friction":
            tau[:, k] += val * np.abs(rigid[:, k]) * np.sign(vk)
        elif name == "friction_drift":
            tau[:, k] += val * ((t - t[0]) / span - 0.5) * np.sign(vk)
        elif name == "position_torque":
            tau[:, k] += val * np.sin((opt or 2) * q[:, k] + 0.7)
        elif name == "cable_spring":
            mid = 0.5 * (limits[0][k] + limits[1][k]) if limits is not None else float(np.mean(q[:, k]))
            tau[:, k] -= val * (q[:, k] - mid)
    for name, j, val, _ in eff["drive_scale"]:
        tau[:, col[j]] *= 1 + val
    for _, _, delay, _ in eff["time_offset"]:
        tau = np.stack([np.interp(t - delay, t, tau[:, k]) for k in range(tau.shape[1])], axis=1)
    return tau + rng.normal(0.0, noise, tau.shape)


def truth_document(rb: RigidBody, truth: Truth, fit: np.ndarray, seed: int, noise: float) -> dict:
    """TRUTH.json: every parameter the identification estimates, by the identification's names (θ: the
    bodies' standard parameters, then per fitted joint fv, fc, f0, Ia), and the injected effects."""
    names = rb.parameter_names()
    theta = list(truth.pi)
    for f, j in enumerate(np.flatnonzero(fit)):
        names += [f"{rb.joints[j]}.{k}" for k in ("fv", "fc", "f0", "Ia")]
        theta += [truth.fv[f], truth.fc[f], truth.f0[f], truth.ia[f]]
    return {"kind": "robocal.dynamics_truth", "seed": seed, "effort_noise_Nm": noise, "names": names,
            "theta": [float(x) for x in theta],
            "effects": [{"effect": n, "joint": j, "value": v, **({"option": o} if o is not None else {})}
                        for n, j, v, o in truth.effects]}
