"""Diagnosis of a URDF robot with any generic measurement type (`pipeline.measurements`).

What a URDF campaign lets robocal test without a robot-specific library: effects that act through
a joint reading, whatever the measurement type —

* ``joint_scale@J``: the joint reads (1 + s)·q (a gear-ratio or encoder-count error);
* ``encoder_eccentricity@J`` (revolute joints): it reads q + a·sin q + b·cos q (a once-per-turn
  error of an encoder mounted off-centre, or a bent shaft);

* ``joint_compliance@J`` (a URDF with `<inertial>` masses): it deflects by c·τ under the gravity
  torque τ of the links it carries (`urdf_gravity`; c = 1/k, k the joint stiffness, rad/(N·m));
  where the encoder stream carries measured efforts (``joint_efforts``, the drive's torque on the
  link at standstill, N·m) the torque is the measured one instead, τ = −effort (source "measured
  torque"): it includes payloads and tools the URDF does not describe, and needs no inertials;
  motor currents (``joint_currents``, A) serve the same way, converted with the campaign's torque
  constants where it states them (source "motor current × torque constant"), else fitted per ampere
  (``J.compliance_per_ampere``, rad/A = c·k, source "motor current");

and the lack-of-fit test against smooth functions of every joint reading and of the measurement
order, which locates structure no term names.  A camera's corners are clustered by image (they share
the robot's pose error at it: the tests run under that random-effects model, as the scanner's stripes
by pose); a camera whose flange poses were measured (``kinematics_known``: the "joints" are the pose's
x, y, z, yaw, pitch, roll) has no joint reading for a reading error to act on — no candidate terms.  Each effect's signature is the residual's
derivative with respect to the joint reading (central differences of the model's own residuals,
so it holds for points, poses, planes and coincidence alike) times the form of the error.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.term import Effect
from pipeline.diagnose.library.urdf_gravity import gravity_torques
from pipeline.diagnose.verdict import lack_of_fit
from pipeline.physics.gravity import has_inertials
from pipeline.progress import step

PLAUSIBLE = {"joint_scale": 1e-2, "encoder_eccentricity": 5e-3, "joint_compliance": 1e-4,
             "joint_compliance_per_ampere": 1e-2}  # rad/A: 1e-4 rad/(N·m) × a torque constant up to 100 N·m/A
ADVICE = {
    "joint_compliance": "measure the same points with the arm stretched and folded (gravity torque varied)",
    "joint_scale": "measure over a wider range of this joint's travel",
    "encoder_eccentricity": "measure over at least half a turn of this joint, spread evenly",
}
_H = 1e-6  # rad or m: central-difference step of the joint-reading derivative


def joint_derivative(model, x: np.ndarray, data) -> np.ndarray:
    """d residual / d joint reading, (n, residual_dim, n_joints), by central differences."""
    q = np.asarray(data["joint_positions"], float)
    out = np.empty((q.shape[0], model.residual_dim, q.shape[1]))
    names = list(model.kin.joint_names)
    for j in range(q.shape[1]):
        step(f"signatures: joint {j + 1} of {q.shape[1]} ({names[j] if j < len(names) else j})")
        dq = np.zeros_like(q)
        dq[:, j] = _H
        hi = model.residuals(x, {**data, "joint_positions": q + dq})
        lo = model.residuals(x, {**data, "joint_positions": q - dq})
        out[:, :, j] = (hi - lo) / (2 * _H)
    return out


def _rows(data) -> np.ndarray:
    """Measurement rows (coincidence distance rows carry no joint reading)."""
    n = len(data["joint_positions"])
    return np.asarray(data.get("kind", np.zeros(n, int))) == 0


def read_joints(model) -> list:
    """The joints of the recording's readings (`UrdfJoint`), in column order: a chain's movable joints,
    or a tree's joints but the coupled ones."""
    kin = model.kin
    if hasattr(kin, "all_joints"):
        read = set(kin.joint_names)
        return [j for j in kin.all_joints if j.name in read]
    return list(kin.desc.movable)


def _urdf(model) -> str:
    return model.kin.urdf if hasattr(model.kin, "all_joints") else model.kin.desc.urdf


def library(model, table) -> list[Effect]:
    q = np.asarray(table["joint_positions"], float)
    joints = read_joints(model)
    lib: list[Effect] = []
    for j, jt in enumerate(joints):
        lib.append(Effect("joint_scale", jt.name, (f"{jt.name}.scale",), ("1",), PLAUSIBLE["joint_scale"], "direct",
                          ("scale", j), 30, f"q_{jt.name}", ADVICE["joint_scale"],
                          data={"located": (f"{jt.name}", q[:, j])}))
        if jt.type != "prismatic":
            lib.append(Effect("encoder_eccentricity", jt.name, (f"{jt.name}.ecc_sin", f"{jt.name}.ecc_cos"),
                              ("rad", "rad"), PLAUSIBLE["encoder_eccentricity"], "direct", ("eccentricity", j), 40,
                              f"q_{jt.name}", ADVICE["encoder_eccentricity"],
                              data={"located": (f"{jt.name} (rad)", q[:, j])}))
    kind = _torque_kind(model, table)
    if kind is not None:
        what, what_unit, basis, source, par, unit, plausible = kind
        tau = load_torques(model, table)
        for j, jt in enumerate(joints):
            if jt.type != "prismatic" and np.ptp(tau[:, j]) > 0:
                lib.append(Effect("joint_compliance", jt.name, (f"{jt.name}.{par}",), (unit,), plausible, "direct",
                                  (basis, j), 10, f"q_{jt.name}", ADVICE["joint_compliance"],
                                  data={"located": (f"{what} on {jt.name} ({what_unit})", tau[:, j]), "source": source}))
    return lib


def _torque_kind(model, table) -> tuple | None:
    """(located variable, its unit, basis, source, parameter, unit, plausible) of the compliance candidates: from the
    measured torque, the motor current, the URDF inertials — the first the table / URDF has — or None."""
    if "joint_efforts" in table:
        source = str(table["torque_source"][0]) if "torque_source" in table else "measured torque"
        return ("measured torque", "N·m", "compliance_measured", source, "compliance", "rad/(N*m)",
                PLAUSIBLE["joint_compliance"])
    if "joint_currents" in table:
        return ("motor current", "A", "compliance_current", "motor current", "compliance_per_ampere", "rad/A",
                PLAUSIBLE["joint_compliance_per_ampere"])
    if has_inertials(_urdf(model)):
        return ("gravity torque", "N·m", "compliance", "URDF inertials", "compliance", "rad/(N*m)",
                PLAUSIBLE["joint_compliance"])
    return None


def load_torques(model, data) -> np.ndarray:
    """The torque (n, J) each joint's compliance acts on: the measured one, −effort N·m (the drive holds
    the link against its load), where the table has ``joint_efforts``; else −current (A) where it has
    ``joint_currents``; else the URDF's gravity torques (N·m)."""
    if "joint_efforts" in data:
        return -np.asarray(data["joint_efforts"], float)
    if "joint_currents" in data:
        return -np.asarray(data["joint_currents"], float)
    q = np.asarray(data["joint_positions"], float)
    if hasattr(model.kin, "all_joints"):  # a tree: the whole tree's load on each read joint
        from pipeline.physics.compliance import loads

        col = [i for i, j in enumerate(model.kin.all_joints) if j.name in set(model.kin.joint_names)]
        return loads(model.kin, q, getattr(model, "payload", ())).axial[:, col]
    return gravity_torques(model.kin.desc, q)


def signatures(model, x: np.ndarray, data, effects, derivative=joint_derivative) -> list[np.ndarray]:
    """Signature (n, residual_dim, k_e) of each effect at parameters x, m per unit; `derivative(model, x, data)`
    the joint derivative (`joint_derivative`, or a memo of it)."""
    if not effects:
        return []
    D = derivative(model, x, data)
    q = np.asarray(data["joint_positions"], float)
    live = _rows(data)[:, None]
    tau = load_torques(model, data) if any(e.basis[0].startswith("compliance") for e in effects) else None
    out = []
    for e in effects:
        kind, j = e.basis
        g = D[:, :, j] * live
        if kind == "scale":
            out.append((g * q[:, j:j + 1])[:, :, None])
        elif kind.startswith("compliance"):
            out.append((g * tau[:, j:j + 1])[:, :, None])
        else:
            out.append(np.stack([g * np.sin(q[:, j:j + 1]), g * np.cos(q[:, j:j + 1])], axis=2))
    return out


def variables(model, x: np.ndarray, table, derivative=joint_derivative) -> list:
    """Lack-of-fit variables: each joint reading (acting through d residual / d q) and the
    measurement order (a drift, per residual axis)."""
    q = np.asarray(table["joint_positions"], float)
    n, k = q.shape[0], model.residual_dim
    D = derivative(model, x, table) * _rows(table)[:, None, None]
    out = []
    for j, name in enumerate(model.kin.joint_names):
        v = lack_of_fit.smooth_variable(f"q_{name}", "rad", np.repeat(q[:, j], k), D[:, :, j].reshape(n * k, 1))
        if v is not None:
            out.append(v)
    t = np.asarray(table["time_since_start_s"], float)
    v = lack_of_fit.smooth_variable("time_since_start_s", "s", np.repeat(t, k), np.tile(np.eye(k), (n, 1)), K=6)
    if v is not None:
        out.append(v)
    return out


LOAD_R2 = 0.5  # a joint reading "tracks" its load when a smooth function of it explains this share of the load


def load_tracking(q: np.ndarray, tau: np.ndarray) -> float:
    """R² of the load τ (n,) on a smooth function of the joint reading q (n,) (cubic + first harmonic):
    how far structure along q cannot be told from structure along the load; 0 for a constant load."""
    if np.ptp(tau) <= 1e-9 * max(1.0, float(np.abs(tau).max())) or q.size < 8:
        return 0.0
    u = (q - q.mean()) / (np.ptp(q) or 1.0)
    B = np.column_stack([np.ones_like(q), u, u**2, u**3, np.sin(q), np.cos(q)])
    coef, *_ = np.linalg.lstsq(B, tau, rcond=None)
    r = tau - B @ coef
    return float(1.0 - (r @ r) / float(((tau - tau.mean()) ** 2).sum()))


def load_advice(model, table):
    """`Adapter.advice`: structure located along a joint reading that tracks that joint's load (gravity
    torque from the URDF inertials, or the measured torque) is load-dependent, not a transmission error."""
    kind = _torque_kind(model, table)
    if kind is None:
        return None
    q = np.asarray(table["joint_positions"], float)
    names = [j.name for j in read_joints(model)]
    cache: dict[str, str | None] = {}

    def advice(variable: str) -> str | None:
        if not variable.startswith("q_") or "→" in variable or variable[2:] not in names:
            return None
        if variable not in cache:
            j = names.index(variable[2:])
            r2 = load_tracking(q[:, j], load_torques(model, table)[:, j])
            cache[variable] = None if r2 < LOAD_R2 else (
                f"load-dependent (compliance/backlash under gravity): the structure along {variable[2:]} tracks its "
                f"{kind[0]} (R² {r2:.2f}); measure the same points with the load changed at the same angle (a "
                "payload, the other joints moved) and approach each posture from both directions; calibrate with "
                "--physics auto to let a compliance term take it")
        return cache[variable]

    return advice


def adapter(model, table, held: tuple[str, ...] | None = None):
    """`diagnose.Adapter`; the geometric baseline holds what the held-out model selection did not
    keep (`pipeline.identify.complexity`; run here unless `held` is given), so the diagnosis starts
    from the calibration robocal reports, not from a model the data do not support."""
    from pipeline.diagnose.adapters.adapter import Adapter
    from pipeline.identify.complexity import select

    if held is None:
        held = select(model, table).fixed if model.groups() else ()
    last: dict = {}

    def derivative(model, x, data):  # the signatures and the lack-of-fit variables at one x share it
        key = np.asarray(x, float).tobytes()
        if last.get("key") != key or last.get("data") is not data:
            last.update(key=key, data=data, D=joint_derivative(model, x, data))
        return last["D"]

    camera = getattr(model, "residual_unit", "m") == "px"
    lib = [] if camera and getattr(model, "kinematics_known", False) else library(model, table)
    return Adapter(library=lib, held=tuple(held), advice=load_advice(model, table),
                   signatures=lambda x, data, effects: signatures(model, x, data, effects, derivative),
                   variables=lambda x: variables(model, x, table, derivative),
                   time_s=np.asarray(table["time_since_start_s"], float),
                   located=lambda e: e.data.get("located"), frozen_refit=True,
                   cluster=np.asarray(table["image"]) if camera else None,
                   cluster_basis=(lambda x: image_pose_basis(model, x, table)) if camera else None)


def image_pose_basis(model, x: np.ndarray, table) -> np.ndarray:
    """How one image's pose error reaches its corners, (n, 2, 6) px per unit: the residual's derivative with
    respect to the chain's base frame (board ↔ robot for eye-in-hand, camera ↔ robot for eye-to-hand) —
    a rigid error of the board-camera pose at that image (`pipeline.camera.uncertainty`)."""
    ib = model.parameter_names().index("base.x")
    return np.asarray(model.jacobian(x, table), float)[:, :, ib:ib + 6]


def from_recording(rec, stream=None, physics: dict | None = None):
    """(model, diagnosis table, info) of a URDF recording: its measurements with the time since
    the first one (the measurement order where a table came without times) and, where the encoder
    stream carries drive state, ``joint_efforts`` (N·m) and ``commanded_positions`` (rad) at each
    measurement (`pipeline.ingest.drive`).  `stream`: the encoder stream when already decoded."""
    from pipeline.ingest import drive, streams
    from pipeline.recording.schemas import META_CAMPAIGN
    from pipeline.systems import urdf_robot

    if physics:  # the run's gravity-term choice: the same model as identify's
        from pipeline.physics.compliance import parse_payload

        model, table = urdf_robot.load(rec, physics.get("physics"), parse_payload(physics.get("payload")))
    else:
        model, table = urdf_robot.load(rec)
    t = np.asarray(table["timestamp_ns"], np.int64)
    tab = dict(table)
    own = np.asarray(table["kind"]) == 0 if "kind" in table else np.ones(t.size, bool)  # rows measured, not derived
    t0 = int(t[own].min()) if own.any() else 0  # derived rows (known distances) carry no time of their own: 0 s
    tab["time_since_start_s"] = np.where(own, (t - t0) * 1e-9, 0.0)
    if stream is None and rec.messages.raw.get(streams.JOINT_STATE):
        stream = streams.joint_stream(rec)
    if stream is not None:
        window = drive.window_of(rec.meta(META_CAMPAIGN), rec.path)
        tab |= drive.at_measurements(stream, t, list(model.kin.joint_names), rec.path,
                                     urdf_robot.channel_for(rec), float(window))
        k = rec.meta(META_CAMPAIGN).get(drive.TORQUE_CONSTANTS)
        if "joint_currents" in tab and "joint_efforts" not in tab and k is not None:
            tab["joint_efforts"] = drive.efforts_from_currents(tab["joint_currents"], list(model.kin.joint_names),
                                                               k if isinstance(k, dict) else {}, rec.path)
            tab["torque_source"] = np.full(len(t), "motor current × torque constant", object)
    return model, tab, {"system": urdf_robot.SYSTEM}
