"""Drive and transmission terms a rigid-body dynamics model leaves out (torques in N·m, N for a
prismatic joint).  Same conventions as `friction`: a basis (T, F, k) of torque per unit parameter,
linear, the measured torque being the model's plus B·θ.  Beyond `friction`'s keys the table holds
the fitted joints' filtered positions ``q`` (T, F), the fitted model's torque ``tau_fit`` (T, F) with
its first time derivative ``dtau`` (N·m/s), the rigid-body part's first and second ``drigid``, ``ddrigid``
(N·m/s, N·m/s²), and the URDF's torque
derivatives ``dtau_dq``, ``dtau_dv``, ``mass_matrix`` (T, F, F): ∂τ_f/∂(q, q̇, q̈)_g of the fitted joints.

- ``position_torque@J``: a torque periodic in the joint's angle, a·sin(nq) + b·cos(nq) (cogging of
  the motor seen through the gear, a cable or hose pulling at one side, an unbalanced seal); forms
  n = 1, 2, 3 (revolute joints);
- ``cable_spring@J``: a spring across the joint, −k·(q − q̄) (a cable loom, a hose, a gas spring);
  its rest offset is the model's offset term;
- ``drive_scale@J``: the effort → torque constant off by a factor, τ_measured = (1 + s)·τ:
  the term is s·τ̂.  A scale shared by every drive is taken entirely by the inertial parameters (all of
  them scale with it): only scales that differ between drives, and only where the joints share
  parameters, can be seen — an absolute scale needs a known load;
- ``time_offset``: the effort stream δ seconds behind the positions, τ_measured(t) = τ(t − δ), on every
  fitted joint (one δ for the stream): δ·(τ̂(t − δ_f) − τ̂(t))/δ_f, forms δ_f = ±5, ±10 and ±20 ms;
- ``joint_elasticity@J``: a joint of finite stiffness K read on the motor side: the link lags the reading
  by c·τ_J (c = 1/K, rad/(N·m); τ_J the link side's rigid-body torque the spring carries, friction is on the
  motor side), so every fitted joint's torque is the model's at the lagged link motion, to first order
  −c·(∂τ/∂q_J·τ_J + ∂τ/∂q̇_J·τ̇_J + M_·J·τ̈_J) (the URDF's RNEA derivatives).
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.friction import on_joint, torque_scale, units_of
from pipeline.diagnose.library.term import Effect

HARMONICS = (1, 2, 3)
SCALE_PLAUSIBLE = 0.3  # a drive constant off by up to 30 %
OFFSET_PLAUSIBLE_S = 0.05  # effort / position streams up to 50 ms apart
OFFSET_FORMS_S = (-0.02, -0.01, -0.005, 0.005, 0.01, 0.02)  # the stream offset's forms (the held-out error picks one)
COMPLIANCE_PLAUSIBLE = 1e-2  # rad/(N·m): a joint stiffness down to 100 N·m/rad


def position_torque(table, f: int, n: int) -> Effect:
    tu, _ = units_of(table, f)
    name = table["joints"][f]

    def basis(_arm, _x, t):
        q = np.asarray(t["q"], float)[:, f]
        return on_joint(t, f, np.stack([np.sin(n * q), np.cos(n * q)], axis=1))

    return Effect("position_torque", f"{name} (n {n})", ("a", "b"), (tu, tu), torque_scale(table, f), "torque",
                  basis, 20 + n, f"q_{name}", f"sweep {name} slowly over its whole range in both directions",
                  data={"joint": f, "form": f"n {n}"})


def cable_spring(table, f: int) -> Effect:
    tu, vu = units_of(table, f)
    name = table["joints"][f]
    q = np.asarray(table["q"], float)[:, f]
    qbar = float(q.mean())
    span = max(float(np.ptp(q)), 1e-9)
    pu = vu.split("/")[0]

    def basis(_arm, _x, t):
        return on_joint(t, f, -(np.asarray(t["q"], float)[:, f] - qbar)[:, None])

    return Effect("cable_spring", name, ("k",), (f"{tu}/{pu}",), torque_scale(table, f) / span, "torque", basis, 19,
                  f"q_{name}", f"hold {name} still at several positions across its range (static torques)",
                  data={"joint": f})


def drive_scale(table, f: int) -> Effect:
    name = table["joints"][f]

    def basis(_arm, _x, t):
        return on_joint(t, f, np.asarray(t["tau_fit"], float)[:, f][:, None])

    return Effect("drive_scale", name, ("s",), ("1",), SCALE_PLAUSIBLE, "torque", basis, 30, f"load_{name}",
                  f"lift a known payload with {name} (the absolute torque scale needs a known load)",
                  data={"joint": f})


def shifted(table, delay_s: float) -> np.ndarray:
    """The fitted torque δ seconds later in the stream, τ̂(t − δ) (T, F) (held at the ends)."""
    t = np.asarray(table["time_s"], float)
    tau = np.asarray(table["tau_fit"], float)
    return np.stack([np.interp(t - delay_s, t, tau[:, f]) for f in range(tau.shape[1])], axis=1)


def time_offset(table, delay_s: float) -> Effect:
    """Form δ_f of the stream offset: the column (τ̂(t − δ_f) − τ̂(t)) / δ_f, so the parameter is δ in s
    near δ_f (−dτ̂/dt as δ_f → 0; the exact shift keeps fast torque changes — a Coulomb step at a
    reversal — where the derivative's first order fails)."""

    def basis(_arm, _x, t):
        return ((shifted(t, delay_s) - np.asarray(t["tau_fit"], float)) / delay_s)[:, :, None]

    ms = delay_s * 1e3
    return Effect("time_offset", f"effort stream (δ {ms:+.0f} ms)", ("delta",), ("s",), OFFSET_PLAUSIBLE_S, "torque",
                  basis, 31 + int(abs(ms) > 10), "time_since_start_s",
                  "stamp efforts and positions with one clock (the same message header)",
                  data={"form": f"δ {ms:+.0f} ms", "delay_s": delay_s})


def joint_elasticity(table, f: int) -> Effect:
    tu, vu = units_of(table, f)
    name = table["joints"][f]
    pu = vu.split("/")[0]

    def basis(_arm, _x, t):
        tau = np.asarray(t["tau_rigid"], float)[:, f]  # the spring carries the link side's torque, not the friction
        dtau, ddtau = np.asarray(t["drigid"], float)[:, f], np.asarray(t["ddrigid"], float)[:, f]
        g = (np.asarray(t["dtau_dq"], float)[:, :, f] * tau[:, None] + np.asarray(t["dtau_dv"], float)[:, :, f]
             * dtau[:, None] + np.asarray(t["mass_matrix"], float)[:, :, f] * ddtau[:, None])
        return -g[:, :, None]

    return Effect("joint_elasticity", name, ("c",), (f"{pu}/{tu}",), COMPLIANCE_PLAUSIBLE, "torque", basis, 32,
                  f"load_{name}", f"excite {name} with faster reversals and under varied loads, or log its link-side "
                  "encoder", data={"joint": f, "sign": 1})


def library(table) -> list[Effect]:
    """Every drive and transmission term at every fitted joint, and the stream's time offset."""
    out: list[Effect] = []
    prismatic = np.asarray(table.get("prismatic", np.zeros(len(table["joints"]), bool)))
    for f in range(len(table["joints"])):
        if not prismatic[f]:
            out += [position_torque(table, f, n) for n in HARMONICS]
        out += [cable_spring(table, f), drive_scale(table, f), joint_elasticity(table, f)]
    return out + [time_offset(table, d) for d in OFFSET_FORMS_S]
