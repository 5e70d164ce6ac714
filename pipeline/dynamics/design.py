"""The regressor of one dynamics model: inertial columns of the rigid body, friction and rotor-inertia
columns of the fitted joints.

Parameters θ = [π (J·10, the bodies' standard parameters), then per fitted joint its friction and
armature terms]; torque of fitted joint j at a sample: τ_j = Y_j π + f_v q̇_j + f_c s(q̇_j) + f_0 + I_a q̈_j with
s the Coulomb sign, smoothed as tanh(q̇ / w) over `coulomb_width` w (rad/s; 0: the sign itself).  Friction
of a joint only moves that joint's torque — but a motor that turns several joints (a coupled wrist: the
recording's position mix, `joint_readings.coupled_motors`) has its own viscous, Coulomb and rotor-inertia
terms on its speed u = G·q̇, reaching each joint j's torque as G_j times them.  Units: N·m·s/rad (N·s/m),
N·m (N), kg·m² (kg).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FRICTION = {"viscous": ("fv", "N·m·s/rad"), "coulomb": ("fc", "N·m"), "offset": ("f0", "N·m")}
ARMATURE = ("Ia", "kg·m²")


@dataclass(frozen=True)
class Terms:
    """Which per-joint terms the model carries beyond the rigid body."""

    friction: tuple[str, ...] = ("viscous", "coulomb", "offset")
    armature: bool = True
    coulomb_width: float = 0.01  # rad/s (m/s): tanh smoothing of the Coulomb sign; 0 = sign
    motors: tuple[tuple[str, tuple[float, ...]], ...] = ()  # coupled motors: (name, G over the chain's joints)

    def per_joint(self) -> list[tuple[str, str]]:
        out = [FRICTION[f] for f in self.friction]
        return out + ([ARMATURE] if self.armature else [])

    def per_motor(self) -> list[tuple[str, str]]:
        """A coupled motor's terms: the joint terms but the offset (a joint's own)."""
        return [k for k in self.per_joint() if k[0] != "f0"]


def motors_of(terms: Terms, fit: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """The coupled motors that move a fitted joint: (name, G (J,))."""
    return [(n, np.asarray(g, float)) for n, g in terms.motors if np.any(np.asarray(g)[np.asarray(fit, bool)])]


def extra_names(joints: list[str], fit: np.ndarray, terms: Terms) -> tuple[list[str], list[str]]:
    """Names and units of the friction / armature parameters, fitted joints in order."""
    names, units = [], []
    for j in np.flatnonzero(fit):
        for key, unit in terms.per_joint():
            names.append(f"{joints[j]}.{key}")
            units.append(unit)
    for name, _ in motors_of(terms, fit):
        for key, unit in terms.per_motor():
            names.append(f"{name}.motor.{key}")
            units.append(unit)
    return names, units


def coulomb(v: np.ndarray, width: float) -> np.ndarray:
    return np.sign(v) if width <= 0 else np.tanh(v / width)


def matrix(Y: np.ndarray, v: np.ndarray, a: np.ndarray, fit: np.ndarray, terms: Terms) -> np.ndarray:
    """X (T, F, P): the rows of the F fitted joints (`fit` (J,) bool) at each of T samples; P = J·10 +
    F·(terms per joint).  `Y` (T, J, J·10) the rigid-body regressor, `v`, `a` (T, J)."""
    idx = np.flatnonzero(fit)
    T, F = Y.shape[0], idx.size
    per = terms.per_joint()
    E = np.zeros((T, F, F * len(per)))
    for f, j in enumerate(idx):
        cols = []
        for key, _ in per:
            cols.append({"fv": v[:, j], "fc": coulomb(v[:, j], terms.coulomb_width), "f0": np.ones(T),
                         "Ia": a[:, j]}[key])
        E[:, f, f * len(per):(f + 1) * len(per)] = np.stack(cols, axis=1)
    blocks = [Y[:, idx, :], E]
    for _, g in motors_of(terms, fit):
        u, du = v @ g, a @ g
        col = {"fv": u, "fc": coulomb(u, terms.coulomb_width), "Ia": du}
        blocks.append(g[idx][None, :, None] * np.stack([col[k] for k, _ in terms.per_motor()], axis=1)[:, None, :])
    return np.concatenate(blocks, axis=2)
