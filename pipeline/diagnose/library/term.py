"""The effect library: compact parametric models of physics a geometric calibration leaves out.

Each `Effect` is a named, located model with a few physical parameters θ.  Its *signature*
``S(x, table)`` (n, k) is the change of the measurement model's residual (model − measured,
m) per unit of θ at geometric parameters x — a Jacobian column block the identification can
append.  Effects act in one of three places:

- ``joint``: the true joint angle is the encoder reading plus δq = G(x, table)·θ, with
  G (n, n_joints, k) rad per unit; the signature is the tip's joint Jacobian along the
  measured axis times G.  (Compliance, backlash, scale, harmonics, wrist coupling.)
- ``tip``: the true tip is displaced by D(table)·θ in the jig frame {W}, D (n, 3, k).
  (Thermal drift, trigger pretravel, trigger latency.)
- ``coordinate``: the true face coordinate differs from the drawing (jig face offset).

Sign conventions (shared with `pipeline.simulate.effects`, which injects the same physics
into the *true* robot): compliance δq_k = c·τ_k with τ_k the gravity torque about joint k
(N·m, lumped masses of the robot model file + payload at the tool tip, gravity −z of {W});
backlash δq_k = −(b/2)·s_k with s_k the sign of joint k's last motion (the load lags the
motor); eccentricity δq_k = a·cos q_k + b·sin q_k; transmission error δq_k = a·cos 2q_k +
b·sin 2q_k; scale δq_k = ε·q_k; wrist coupling δq_j = κ·q_i; pretravel: the trigger fires
after the wire has travelled d past contact along the search direction (−face normal);
latency: the encoders latch t_l after contact while the arm moves at its approach velocity;
thermal drift: the tip moves by v·t (t since the start of the recording), or by g·ΔT when a
temperature channel is recorded (ΔT its rise since the first reading); face offset: the
machined face lies δ along its axis from the drawing value.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from pipeline.models import serial_arm
from pipeline.models.serial_arm import SerialArm

G_M_S2 = 9.80665
GRAVITY_W = np.array([0.0, 0.0, -G_M_S2])  # jig frame {W}: z up (the block sits level)

Table = Mapping[str, np.ndarray]


@dataclass(frozen=True)
class Effect:
    """One candidate effect at one location (see module docstring).

    `plausible` is the largest physically plausible |θ| (units of `units`); `tolerance` is
    a size below which the effect is immaterial (e.g. the jig's machining tolerance), used as
    an interval null hypothesis.  `variable` names what its signature is a function of, so
    lack-of-fit structure can be matched to findings.  Lower `priority` wins ties.
    """

    name: str
    location: str
    parameters: tuple[str, ...]
    units: tuple[str, ...]
    plausible: float
    where: str  # "joint" | "tip" | "coordinate"
    basis: Callable[[SerialArm, np.ndarray, Table], np.ndarray]
    priority: int
    variable: str
    advice: str
    tolerance: float = 0.0
    confounders: tuple[str, ...] = ()  # effect names whose union may absorb this one
    data: dict = field(default_factory=dict, compare=False)

    @property
    def label(self) -> str:
        return f"{self.name}@{self.location}"

    @property
    def k(self) -> int:
        return len(self.parameters)

    @property
    def family(self) -> tuple[str, str, str]:
        """(name, place, variable) shared by the forms of one effect (`forms`): the location up to a
        form in brackets, e.g. joint_coupling J2->J3 and J2->J3 (quadratic)."""
        return self.name, str(self.location).split(" (")[0], self.variable


# ----- physics helpers ------------------------------------------------------------------
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


def axis_rows(table: Table) -> tuple[np.ndarray, np.ndarray]:
    ax = np.asarray(table["axis"], int)
    return np.arange(ax.size), ax


def tip_speed_vector(x: np.ndarray, table: Table) -> np.ndarray:
    """Tip velocity (n,3) m/s in {W} just before each contact: J_q · q̇_approach."""
    _, Jq = serial_arm.joint_jacobian(x, table["joint_positions"])
    return np.einsum("nij,nj->ni", Jq, table["approach_joint_velocity"])


# ----- bases (n, n_joints, k) for joint effects, (n, 3, k) for tip effects ------------------
def _one_joint(j: int, nj: int, cols: np.ndarray) -> np.ndarray:
    out = np.zeros((cols.shape[0], nj, cols.shape[1]))
    out[:, j, :] = cols
    return out


def _compliance(j):
    def basis(arm, x, t):
        tau = gravity_torque(arm, x, t["joint_positions"], t.get("payload_kg", arm.payload_kg))
        return _one_joint(j, arm.n_joints, tau[:, j:j + 1])
    return basis


def _backlash(j):
    def basis(arm, x, t):
        return _one_joint(j, arm.n_joints, -0.5 * np.asarray(t["last_motion_sign"], float)[:, j:j + 1])
    return basis


def _scale(j):
    def basis(arm, x, t):
        return _one_joint(j, arm.n_joints, t["joint_positions"][:, j:j + 1])
    return basis


def _harmonic(j, order):
    def basis(arm, x, t):
        qj = t["joint_positions"][:, j]
        return _one_joint(j, arm.n_joints, np.stack([np.cos(order * qj), np.sin(order * qj)], axis=1))
    return basis


def _coupling(src, dst):
    def basis(arm, x, t):
        return _one_joint(dst, arm.n_joints, t["joint_positions"][:, src:src + 1])
    return basis


def _bump(j, centre, width):
    """Out-of-library test effect (simulator only): a Gaussian bump in joint j's transmission."""
    def basis(arm, x, t):
        qj = t["joint_positions"][:, j]
        return _one_joint(j, arm.n_joints, np.exp(-0.5 * ((qj - centre) / width) ** 2)[:, None])
    return basis


def _drift(arm, x, t):
    ts = np.asarray(t["time_since_start_s"], float)
    return ts[:, None, None] * np.eye(3)[None]


# ----- thermal drift: against time, or against a recorded temperature ---------------------
PLAUSIBLE_THERMAL_M_PER_K = 1e-4  # 100 µm/K: a 1 m steel link grows 12 µm/K, 2 m of aluminium 46 µm/K


def _drift_temperature(arm, x, t):
    """The tip moves by g·ΔT (ΔT: temperature rise since the first reading, K)."""
    dT = np.asarray(t["temperature_rise_K"], float)
    return dT[:, None, None] * np.eye(3)[None]


def temperature_columns(table: Table) -> list[tuple[str, str]]:
    """(column, sensor) of each recorded temperature rise: ``temperature_rise_K`` (the first sensor)
    and ``temperature_rise_K@<sensor>`` (each other sensor, `diagnose.table`)."""
    out = []
    if "temperature_rise_K" in table:
        out.append(("temperature_rise_K", str(np.asarray(table["temperature_sensor"])[0])
                    if "temperature_sensor" in table else "sensor"))
    return out + [(k, k.split("@", 1)[1]) for k in table if k.startswith("temperature_rise_K@")]


def _drift_column(column: str):
    def basis(arm, x, t):
        return np.asarray(t[column], float)[:, None, None] * np.eye(3)[None]
    return basis


def thermal_drift_effect(table: Table) -> Effect:
    """thermal_drift: the tip (in {W}) moves by v·t (m/s, time since start) — or, when the table
    carries a recorded temperature (``temperature_rise_K``), by g·ΔT (m/K) located on that sensor."""
    if "temperature_rise_K" in table:
        sensor = str(np.asarray(table["temperature_sensor"])[0]) if "temperature_sensor" in table else "sensor"
        return Effect("thermal_drift", f"temperature {sensor}", ("drift_x", "drift_y", "drift_z"), ("m/K",) * 3,
                      PLAUSIBLE_THERMAL_M_PER_K, "tip", _drift_temperature, 70, "temperature_rise_K",
                      ADVICE["thermal_drift"], confounders=("face_offset",))
    return Effect("thermal_drift", "campaign", ("drift_x", "drift_y", "drift_z"), ("m/s",) * 3,
                  PLAUSIBLE["thermal_drift"], "tip", _drift, 70, "time", ADVICE["thermal_drift"],
                  confounders=("face_offset",))


def _pretravel(arm, x, t):
    """Tip, as the model should place it, is d back along the face normal from the latch."""
    sign = np.asarray(t["normal_sign"], float)
    n = sign.size
    D = np.zeros((n, 3, 1))
    D[np.arange(n), np.asarray(t["axis"], int), 0] = sign
    return D


def _latency(arm, x, t):
    """The encoders latch t_l late: the contact was where the arm was t_l earlier."""
    return -tip_speed_vector(x, t)[:, :, None]


def _face(face_id):
    def basis(arm, x, t):
        return -(np.asarray(t["face"]).astype(str) == face_id).astype(float)[:, None]
    return basis


# ----- signatures ---------------------------------------------------------------------------
def signature(effect: Effect, arm: SerialArm, x: np.ndarray, table: Table, Jq: np.ndarray | None = None) -> np.ndarray:
    """Residual change per unit parameter, (n, k) m/unit, at geometric parameters x.
    `Jq` (n, 3, n_joints): the joint Jacobian at x, when the caller has it already."""
    rows, ax = axis_rows(table)
    B = effect.basis(arm, x, table)
    if effect.where == "joint":
        if Jq is None:
            _, Jq = serial_arm.joint_jacobian(x, table["joint_positions"])
        return np.einsum("nj,njk->nk", Jq[rows, ax], B)
    if effect.where == "tip":
        return B[rows, ax]
    return B  # coordinate: already (n, k)


def joint_offsets(effects_and_values, arm: SerialArm, x: np.ndarray, table: Table) -> np.ndarray:
    """Total δq (n, n_joints) rad of joint effects with values θ (simulator and re-simulation)."""
    n = np.asarray(table["joint_positions"]).shape[0]
    dq = np.zeros((n, arm.n_joints))
    for e, theta in effects_and_values:
        if e.where == "joint":
            dq += np.einsum("njk,k->nj", e.basis(arm, x, table), np.atleast_1d(np.asarray(theta, float)))
    return dq


# ----- the library ------------------------------------------------------------------------
ADVICE = {
    "joint_compliance": "add a second payload and reach the same points with the arm stretched and folded",
    "backlash": "approach each pose from both sides of the joint (reverse the joint before the search)",
    "joint_scale": "move the joint over a wider range of its travel",
    "encoder_eccentricity": "spread the poses over a full turn of the joint",
    "transmission_error": "spread the poses over at least half a turn of the joint",
    "wrist_coupling": "vary the driving wrist joint independently of the driven one",
    "thermal_drift": "interleave the faces in time (revisit each face early and late in the campaign)",
    "trigger_pretravel": "touch faces whose normals point in opposite directions",
    "trigger_latency": "vary the search speed (e.g. 5, 10 and 20 mm/s)",
    "face_offset": "touch the face from poses far apart in joint space",
}

# (effect name, plausible |θ|, units of θ)
PLAUSIBLE = {
    "joint_compliance": 1e-4,  # rad/(N·m): 1e4 N·m/rad, a very soft joint
    "backlash": 2e-3,  # rad (0.11°)
    "joint_scale": 5e-3,
    "encoder_eccentricity": 2e-3,  # rad
    "transmission_error": 2e-3,  # rad
    "wrist_coupling": 1e-2,  # rad/rad
    "thermal_drift": 2e-6,  # m/s (7 mm/h)
    "trigger_pretravel": 2e-3,  # m
    "trigger_latency": 0.05,  # s
    "face_offset": 1e-3,  # m
}


MIN_SPEED_SPREAD = 1.5  # approach speeds must span this ratio for latency to be told from pretravel


def touch_library(arm: SerialArm, table: Table, jig_tolerance_m: float = 2e-5) -> list[Effect]:
    """Every candidate effect of the arc-welder touch campaign (module docstring)."""
    nj = arm.n_joints
    J = [j.name for j in arm.joints]
    P = PLAUSIBLE
    lib: list[Effect] = []
    for j in range(nj):
        lib.append(Effect("joint_compliance", J[j], (f"compliance_{J[j]}",), ("rad/(N*m)",), P["joint_compliance"],
                          "joint", _compliance(j), 10, f"q_{J[j]}", ADVICE["joint_compliance"]))
    for j in range(nj):
        lib.append(Effect("backlash", J[j], (f"backlash_{J[j]}",), ("rad",), P["backlash"], "joint", _backlash(j),
                          20, f"q_{J[j]}", ADVICE["backlash"]))
    for j in range(nj):
        lib.append(Effect("joint_scale", J[j], (f"scale_{J[j]}",), ("1",), P["joint_scale"], "joint", _scale(j),
                          30, f"q_{J[j]}", ADVICE["joint_scale"]))
    for j in range(nj):
        lib.append(Effect("encoder_eccentricity", J[j], (f"ecc_cos_{J[j]}", f"ecc_sin_{J[j]}"), ("rad", "rad"),
                          P["encoder_eccentricity"], "joint", _harmonic(j, 1), 40, f"q_{J[j]}",
                          ADVICE["encoder_eccentricity"]))
    for j in range(nj):
        lib.append(Effect("transmission_error", J[j], (f"te2_cos_{J[j]}", f"te2_sin_{J[j]}"), ("rad", "rad"),
                          P["transmission_error"], "joint", _harmonic(j, 2), 50, f"q_{J[j]}",
                          ADVICE["transmission_error"]))
    if nj >= 6:
        for src, dst in ((3, 4), (3, 5), (4, 5)):
            lib.append(Effect("wrist_coupling", f"{J[src]}->{J[dst]}", (f"coupling_{J[src]}_{J[dst]}",), ("rad/rad",),
                              P["wrist_coupling"], "joint", _coupling(src, dst), 60, f"q_{J[src]}",
                              ADVICE["wrist_coupling"]))
    lib.append(thermal_drift_effect(table))
    for col, sensor in temperature_columns(table)[1:]:  # several sensors: a drift against each
        lib.append(Effect("thermal_drift", f"temperature {sensor}", ("drift_x", "drift_y", "drift_z"), ("m/K",) * 3,
                          PLAUSIBLE_THERMAL_M_PER_K, "tip", _drift_column(col), 70, col, ADVICE["thermal_drift"],
                          confounders=("face_offset",)))
    lib.append(Effect("trigger_pretravel", "touch sensor", ("pretravel",), ("m",), P["trigger_pretravel"], "tip",
                      _pretravel, 80, "approach", ADVICE["trigger_pretravel"]))
    speed = np.linalg.norm(tip_speed_vector(arm.vector(), table), axis=1) if "approach_joint_velocity" in table else None
    spread = float(np.percentile(speed, 90) / max(np.percentile(speed, 10), 1e-12)) if speed is not None else 1.0
    blocked = {} if spread >= MIN_SPEED_SPREAD else {
        "blocked": f"the approach speed hardly varies (90th/10th percentile ratio {spread:.2f}): latency acts "
                   f"like pretravel", "absorbed_by": "trigger_pretravel"}
    lib.append(Effect("trigger_latency", "touch sensor", ("latency",), ("s",), P["trigger_latency"], "tip", _latency,
                      85, "approach", ADVICE["trigger_latency"], confounders=("trigger_pretravel",), data=blocked))
    for f in sorted(set(np.asarray(table["face"]).astype(str))):
        lib.append(Effect("face_offset", f, (f"offset_{f}",), ("m",), P["face_offset"], "coordinate", _face(f), 90,
                          "face", ADVICE["face_offset"], tolerance=jig_tolerance_m))
    from pipeline.diagnose.library.touch_more import more_effects  # couplings, link growth, face shape, wire

    return lib + more_effects(arm, table)


def bump_effect(arm: SerialArm, joint: int, centre_rad: float, width_rad: float = 0.15) -> Effect:
    """A localised bump in one joint's transmission — deliberately NOT in the library."""
    name = arm.joints[joint].name
    return Effect("bump", f"{name}:{centre_rad:g}", (f"bump_{name}",), ("rad",), 1e-2, "joint",
                  _bump(joint, centre_rad, width_rad), 999, f"q_{name}", "")


def effect_by_name(arm: SerialArm, table: Table, name: str, location: str | None,
                   jig_tolerance_m: float = 2e-5) -> Effect:
    """The library entry `name@location` (location may be omitted when unique)."""
    if name == "bump":
        j, _, c = (location or "").partition(":")
        names = [jj.name for jj in arm.joints]
        if j not in names:
            raise ValueError(f"bump needs @JOINT:CENTRE_RAD, e.g. bump=2e-4@J2:0.6 (got {location!r})")
        return bump_effect(arm, names.index(j), float(c or 0.0))
    return pick(touch_library(arm, table, jig_tolerance_m), name, location)


def pick(lib: list[Effect], name: str, location: str | None) -> Effect:
    """The entry `name@location` of an effect library (location may be omitted when unique);
    ValueError listing the options otherwise."""
    hits = [e for e in lib if e.name == name and (location is None or e.location == location)]
    if len(hits) != 1:
        options = sorted({e.label for e in lib if e.name == name}) or sorted({e.name for e in lib})
        raise ValueError(f"effect {name}@{location}: expected one match, options: {', '.join(options)}")
    return hits[0]
