"""Friction terms a rigid-body dynamics model with viscous + Coulomb + offset friction leaves out
(torques in N·m, N for a prismatic joint; velocities rad/s, m/s).

Each term acts on one fitted joint's torque and is linear in its parameters: its basis
``B = basis(None, None, table)`` is (T, F, k) torque per unit parameter at each of T samples and F
fitted joints (zero outside the term's joint), so the measured torque is the model's plus B·θ.  The
table is the dynamics diagnosis table (`pipeline.diagnose.adapters.dynamics`): ``time_s`` (T,), the
fitted joints' filtered velocity ``v`` (T, F), the model's rigid-body torque ``tau_rigid`` (T, F)
(inertia, Coriolis and gravity: the load), the Coulomb smoothing width ``coulomb_width`` and the
joint names ``joints`` (F,).  s(v) = tanh(v / width) is the model's own Coulomb sign.

- ``stribeck@J``: the breakaway bump f_s·exp(−(v/v_s)²)·s(v) above Coulomb at low speed (f_s > 0: static
  friction above the sliding one; found below, it is not that physics); forms
  v_s = 3 %, 10 % and 30 % of the joint's largest speed (the held-out error picks one);
- ``asymmetric_coulomb@J``: a Coulomb level that differs with the direction of motion, beyond what
  the offset takes: f_a·|s(v)| acts only while the joint moves (the offset acts at rest too), so
  only rests could tell them apart — and where the model has Coulomb friction the rows of a joint at rest
  are not fitted (its torque there is stiction's): then the gate finds it absorbed by the joint's offset,
  which carries it, and says so;
- ``load_friction@J``: Coulomb friction proportional to the transmitted torque, μ·|τ_rigid|·s(v)
  (gear meshing and bearing friction grow with the load);
- ``friction_drift@J``: Coulomb and viscous friction changing over the session (a warming gearbox),
  [Δf_c·g(t)·s(v), Δf_v·g(t)·v] with g linear in time from −½ to +½ over the session, or a first-order
  warm-up 1 − e^(−t/τ) (τ a third of the session) about its mean.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.term import Effect

STRIBECK_SHARES = (0.03, 0.1, 0.3)  # v_s as a share of the joint's largest |v|
WARMUP_SHARE = 1 / 3  # the warm-up's time constant as a share of the session
MU_PLAUSIBLE = 0.3  # load-dependent friction: at most this share of the transmitted torque


def sign(table, f: int) -> np.ndarray:
    """The model's Coulomb sign s(v) of fitted joint f (T,)."""
    v = np.asarray(table["v"], float)[:, f]
    w = float(table["coulomb_width"])
    return np.sign(v) if w <= 0 else np.tanh(v / w)


def on_joint(table, f: int, cols: np.ndarray) -> np.ndarray:
    """Basis (T, F, k) acting on fitted joint f only, with columns `cols` (T, k)."""
    T, F = np.asarray(table["v"]).shape
    out = np.zeros((T, F, cols.shape[1]))
    out[:, f, :] = cols
    return out


def torque_scale(table, f: int) -> float:
    """The joint's torque scale (N·m): the largest |measured torque| (what any friction term stays below)."""
    return float(np.max(np.abs(np.asarray(table["tau"], float)[:, f])))


def units_of(table, f: int) -> tuple[str, str]:
    """(torque unit, velocity unit) of fitted joint f."""
    prismatic = bool(np.asarray(table.get("prismatic", np.zeros(len(table["joints"]), bool)))[f])
    return ("N", "m/s") if prismatic else ("N·m", "rad/s")


def _time_shape(table, form: str) -> np.ndarray:
    """g(t) (T,): linear from −½ to +½ over the session, or the warm-up 1 − e^(−t/τ) about its mean."""
    t = np.asarray(table["time_s"], float)
    span = max(float(t[-1] - t[0]), 1e-9)
    u = (t - t[0]) / span
    g = u - 0.5 if form == "linear" else 1.0 - np.exp(-u / WARMUP_SHARE)
    return g - g.mean()


def stribeck(table, f: int, share: float) -> Effect:
    v = np.asarray(table["v"], float)[:, f]
    vs = max(share * float(np.max(np.abs(v))), 1e-6)
    tu, vu = units_of(table, f)
    name = table["joints"][f]

    def basis(_arm, _x, t):
        vv = np.asarray(t["v"], float)[:, f]
        return on_joint(t, f, (np.exp(-(vv / vs) ** 2) * sign(t, f))[:, None])

    return Effect("stribeck", f"{name} (v_s {vs:.3g} {vu})", ("f_s",), (tu,), torque_scale(table, f), "torque",
                  basis, 10, f"v_{name}", f"move {name} slowly in both directions, at several constant low speeds",
                  data={"joint": f, "form": f"v_s {vs:.3g} {vu}", "v_s": vs, "sign": 1})


def asymmetric_coulomb(table, f: int) -> Effect:
    tu, _ = units_of(table, f)
    name = table["joints"][f]

    def basis(_arm, _x, t):
        return on_joint(t, f, np.abs(sign(t, f))[:, None])

    band = float(np.asarray(table.get("coulomb_level", np.zeros(len(table["joints"]))), float)[f])
    return Effect("asymmetric_coulomb", name, ("f_a",), (tu,), torque_scale(table, f), "torque", basis, 11,
                  f"v_{name}", f"{name}'s offset carries it while {name} moves (a Coulomb level higher one way by 2·f_a is "
                  f"an offset f_a); held at rest {name} does not carry it: hold {name} still for a second or more, "
                  "several times, to separate them", tolerance=band, data={"joint": f})


def load_friction(table, f: int) -> Effect:
    name = table["joints"][f]

    def basis(_arm, _x, t):
        return on_joint(t, f, (np.abs(np.asarray(t["tau_rigid"], float)[:, f]) * sign(t, f))[:, None])

    return Effect("load_friction", name, ("mu",), ("1",), MU_PLAUSIBLE, "torque", basis, 12, f"load_{name}",
                  f"move {name} at the same speeds under light and heavy loads (arm folded and stretched, a payload)",
                  data={"joint": f, "sign": 1})


def friction_drift(table, f: int, form: str) -> Effect:
    tu, vu = units_of(table, f)
    name = table["joints"][f]
    span = float(np.ptp(np.asarray(table["time_s"], float)))

    def basis(_arm, _x, t):
        g = _time_shape(t, form)
        vv = np.asarray(t["v"], float)[:, f]
        return on_joint(t, f, np.stack([g * sign(t, f), g * vv], axis=1))

    label = "linear in time" if form == "linear" else f"warm-up, τ {WARMUP_SHARE * span:.3g} s"
    return Effect("friction_drift", f"{name} ({label})", ("delta_fc", "delta_fv"), (tu, f"{tu}·s/{vu.split('/')[0]}"),
                  torque_scale(table, f), "torque", basis, 13 if form == "linear" else 14, "time_since_start_s",
                  "log the drive or gearbox temperature; repeat the same excitation cold and warm",
                  data={"joint": f, "form": label})


def library(table) -> list[Effect]:
    """Every friction term at every fitted joint."""
    out: list[Effect] = []
    for f in range(len(table["joints"])):
        out += [stribeck(table, f, s) for s in STRIBECK_SHARES]
        out += [asymmetric_coulomb(table, f), load_friction(table, f)]
        out += [friction_drift(table, f, form) for form in ("linear", "warmup")]
    return out
