"""Effect library of the Delta robot measured by a laser tracker (seed 003), and its adapter.

Residual (3 per measurement, m, base frame {A}): r = M(β', θ) − (ᴬR_T p_T + ᴬt_T)
(`pipeline.systems.delta_tracker.TrackerModel`).  Each effect's signature S (n, 3, k) is the
change of r per unit parameter at the geometric solution x (sign conventions shared with
`pipeline.simulate.delta_tracker`, which injects the same physics into the TRUE robot):

- ``backlash@A<i>`` (rad): the arm lags the motor: θ_true = θ_enc − (b/2)·s_i, s_i the sign of
  actuator i's last motion (encoder stream) → S = ∂M/∂θ_i · (−s_i/2);
- ``actuator_scale@A<i>`` (1): θ_true = θ_enc·(1 + ε) → S = ∂M/∂θ_i · θ_i;
- ``axis_yaw@leg<i>``, ``axis_tilt@leg<i>`` (rad): the terms β' drops — actuator axis yaw Δγ_i
  about z_i and tilt Δα_i about x_i (`delta.full_jacobian` columns at the solution, extended
  terms 0).  The common yaw of the three axes is a rotation of {A} (the registration absorbs it);
  which single leg's yaw is absorbed depends on the campaign;
- ``unequal_rods@leg<i>`` (m): parallelogram rods l2+Δl2 ± d/2 (tilts the platform);
- ``thermal_drift@campaign`` (m/s ×3): the reflector seen by the tracker moves by v·t in {A}
  (t since the start of the recording) → S = t·I; with a recorded `/arm/temperature` channel
  ``thermal_drift@temperature <sensor>`` (m/K ×3) instead: it moves by g·ΔT → S = ΔT·I;
- ``tracker_scale@tracker`` (1): the tracker reads (1+s)·p about its own origin → S = ᴬR_T p_T.
  A uniform scale of the Delta's lengths (a, b, l1, l2, h) scales every platform position, so
  β' absorbs it entirely: a scale can only be told by a reference length (scale bar).

`adapter(model, table)` returns the `diagnose.Adapter` (library, signatures, lack-of-fit
variables: each actuator angle through ∂M/∂θ_i, time per axis of {A}).
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.term import Effect
from pipeline.diagnose.verdict import lack_of_fit
from pipeline.models import delta as dm

ACTUATORS = ("A1", "A2", "A3")
LEGS = ("leg1", "leg2", "leg3")

PLAUSIBLE = {
    "backlash": 2e-3,  # rad at the arm (0.11°)
    "actuator_scale": 5e-3,
    "axis_direction": 1e-2,  # rad (0.57°)
    "unequal_rods": 1e-3,  # m
    "thermal_drift": 2e-6,  # m/s (7 mm/h)
    "tracker_scale": 1e-4,  # 100 ppm
}

ADVICE = {
    "backlash": "approach each point from both sides of every actuator (robocal simulate delta-tracker --both-sides)",
    "actuator_scale": "spread the points over a wider range of each actuator's travel (taller, wider point set)",
    "axis_direction": "measure more points spread over the whole workspace, including its edges (e.g. --points 100)",
    "unequal_rods": "measure more points over the whole workspace so that the platform tilt varies (e.g. --points 100)",
    "thermal_drift": "revisit the points late in the campaign (two passes, --passes 2) or record a temperature",
    "tracker_scale": "measure a calibrated reference length (scale bar) or check the tracker against its "
                     "reference interferometer distance; a point campaign cannot tell a scale from the robot's lengths",
}


# ----- physics at the solution ------------------------------------------------------------
def dM_dtheta(model, x: np.ndarray, data) -> np.ndarray:
    """∂M/∂θ (n, 3 xyz, 3 actuators) m/rad of the reflector in {A} (the dtheta1 columns)."""
    names = model.parameter_names()
    J = model.jacobian(x, data)
    return J[:, :, [names.index(f"leg{i + 1}.dtheta1") for i in range(3)]]


def extended_columns(model, x: np.ndarray, data) -> np.ndarray:
    """∂M/∂(Δγ_i, Δα_i, d_i) (n, 3 xyz, 3 legs, 3) at x with the extended terms at 0 (or at
    their values when the model is extended)."""
    beta, _, h = model._split(x)
    B, X = dm.split(beta, model.extended)
    full = np.concatenate([B, X], axis=1).ravel()
    theta = np.atleast_2d(np.asarray(data["joint_positions"], float))
    p, R, _ = dm.full_forward(model.delta, full, theta, extended=True)
    J, _ = dm.full_jacobian(model.delta, full, theta, p, R, np.array([0.0, 0.0, -h]), extended=True)
    return J.reshape(theta.shape[0], 3, 3, 12)[..., 9:]


def context(model, x: np.ndarray, data, need_ext: bool = True) -> dict:
    """What the signatures are made of, computed once per x."""
    from pipeline.measurements.registration import registration_matrix

    _, reg, _ = model._split(x)
    R, _ = registration_matrix(reg)
    ctx = {"dM": dM_dtheta(model, x, data), "theta": np.asarray(data["joint_positions"], float),
           "sign": np.asarray(data["last_motion_sign"], float), "t": np.asarray(data["time_since_start_s"], float),
           "pA": np.asarray(data["point"], float) @ R.T}
    if "temperature_rise_K" in data:
        ctx["dT"] = np.asarray(data["temperature_rise_K"], float)
    if need_ext:
        ctx["ext"] = extended_columns(model, x, data)
    return ctx


def _backlash(i):
    return lambda c: (c["dM"][:, :, i] * (-0.5 * c["sign"][:, i])[:, None])[:, :, None]


def _scale(i):
    return lambda c: (c["dM"][:, :, i] * c["theta"][:, i][:, None])[:, :, None]


def _axis(i, comp):
    return lambda c: c["ext"][:, :, i, comp:comp + 1]


def _rods(i):
    return lambda c: c["ext"][:, :, i, 2:3]


def _drift(c):
    return c["t"][:, None, None] * np.eye(3)[None]


def _drift_temperature(c):
    return c["dT"][:, None, None] * np.eye(3)[None]


def _thermal(table, t) -> Effect:
    """thermal_drift against time, or against the recorded temperature rise when there is one."""
    if "temperature_rise_K" in table:
        from pipeline.diagnose.library.thermal import PLAUSIBLE_THERMAL_M_PER_K

        sensor = str(np.asarray(table["temperature_sensor"])[0])
        dT = np.asarray(table["temperature_rise_K"], float)
        return Effect("thermal_drift", f"temperature {sensor}", ("drift_x", "drift_y", "drift_z"), ("m/K",) * 3,
                      PLAUSIBLE_THERMAL_M_PER_K, "direct", _drift_temperature, 70, "temperature_rise_K",
                      ADVICE["thermal_drift"], data={"located": (f"temperature rise of {sensor} (K)", dT)})
    return Effect("thermal_drift", "campaign", ("drift_x", "drift_y", "drift_z"), ("m/s",) * 3,
                  PLAUSIBLE["thermal_drift"], "direct", _drift, 70, "time", ADVICE["thermal_drift"],
                  data={"located": ("time since start (s)", t)})


def _tracker_scale(c):
    return c["pA"][:, :, None]


# ----- the library ------------------------------------------------------------------------
def library(model, table) -> list[Effect]:
    """Every candidate effect of a Delta + laser-tracker campaign (module docstring).  The
    extended terms are candidates only when the geometric model is the simplified β'."""
    P = PLAUSIBLE
    th = np.asarray(table["joint_positions"], float)
    sg = np.asarray(table["last_motion_sign"], float)
    t = np.asarray(table["time_since_start_s"], float)
    lib: list[Effect] = []
    for i, a in enumerate(ACTUATORS):
        lib.append(Effect("backlash", a, (f"backlash_{a}",), ("rad",), P["backlash"], "direct", _backlash(i), 20,
                          f"q_{a}", ADVICE["backlash"], data={"located": (f"last motion sign of {a}", sg[:, i])}))
    for i, a in enumerate(ACTUATORS):
        lib.append(Effect("actuator_scale", a, (f"scale_{a}",), ("1",), P["actuator_scale"], "direct", _scale(i), 30,
                          f"q_{a}", ADVICE["actuator_scale"], data={"located": (f"{a} (rad)", th[:, i])}))
    if not model.extended:
        for name, comp, prio in (("axis_yaw", 0, 40), ("axis_tilt", 1, 45)):
            for i, leg in enumerate(LEGS):
                lib.append(Effect(name, leg, (f"{leg}.{('dgamma', 'dalpha')[comp]}",), ("rad",), P["axis_direction"],
                                  "direct", _axis(i, comp), prio, f"q_{ACTUATORS[i]}", ADVICE["axis_direction"],
                                  data={"located": (f"{ACTUATORS[i]} (rad)", th[:, i])}))
        for i, leg in enumerate(LEGS):
            lib.append(Effect("unequal_rods", leg, (f"{leg}.dl2_diff",), ("m",), P["unequal_rods"], "direct",
                              _rods(i), 50, f"q_{ACTUATORS[i]}", ADVICE["unequal_rods"],
                              data={"located": (f"{ACTUATORS[i]} (rad)", th[:, i])}))
    lib.append(_thermal(table, t))
    dist = np.linalg.norm(np.asarray(table["point"], float), axis=1)
    lib.append(Effect("tracker_scale", "tracker", ("tracker_scale",), ("1",), P["tracker_scale"], "direct",
                      _tracker_scale, 80, "range", ADVICE["tracker_scale"],
                      data={"located": ("tracker range (m)", dist)}))
    return lib


def signatures(model, x: np.ndarray, data, effects) -> list[np.ndarray]:
    """Signature (n, 3, k_e) m/unit of each effect at geometric parameters x."""
    if not effects:
        return []
    ctx = context(model, x, data, need_ext=any(e.name in ("axis_yaw", "axis_tilt", "unequal_rods") for e in effects))
    return [np.asarray(e.basis(ctx), float) for e in effects]


def variables(model, x: np.ndarray, table) -> list[lack_of_fit.Variable]:
    """Lack-of-fit variables (rows = flattened residual rows, n·3): each actuator angle (an
    angle-dependent error acts through ∂M/∂θ_i) and time since start (per axis of {A})."""
    th = np.asarray(table["joint_positions"], float)
    n = th.shape[0]
    dM = dM_dtheta(model, x, table)
    out = []
    for i, a in enumerate(ACTUATORS):
        v = lack_of_fit.smooth_variable(f"q_{a}", "rad", np.repeat(th[:, i], 3), dM[:, :, i].reshape(n * 3, 1))
        if v is not None:
            out.append(v)
    t = np.asarray(table["time_since_start_s"], float)
    v = lack_of_fit.smooth_variable("time_since_start_s", "s", np.repeat(t, 3), np.tile(np.eye(3), (n, 1)), K=6)
    if v is not None:
        out.append(v)
    if "temperature_rise_K" in table:
        dT = np.asarray(table["temperature_rise_K"], float)
        v = lack_of_fit.smooth_variable("temperature_rise_K", "K", np.repeat(dT, 3), np.tile(np.eye(3), (n, 1)), K=6)
        if v is not None:
            out.append(v)
    return out


def adapter(model, table, lib: list[Effect] | None = None):
    """`diagnose.Adapter` of a Delta + tracker diagnosis table (`add_context`)."""
    from pipeline.diagnose.adapters.adapter import Adapter

    lib = library(model, table) if lib is None else lib
    return Adapter(library=lib,
                   signatures=lambda x, data, effects: signatures(model, x, data, effects),
                   variables=lambda x: variables(model, x, table),
                   time_s=np.asarray(table["time_since_start_s"], float),
                   located=lambda e: e.data.get("located"))


def add_context(table: dict, stream_t: np.ndarray, stream_q: np.ndarray) -> dict:
    """A copy of a tracker table with ``last_motion_sign`` (n, 3) and ``time_since_start_s`` (n,)."""
    from pipeline.ingest.context import last_motion_sign

    t_ns = np.asarray(table["timestamp_ns"], np.int64)
    out = dict(table)
    out["last_motion_sign"] = last_motion_sign(stream_t, stream_q, t_ns)
    out["time_since_start_s"] = (t_ns - stream_t[0]) * 1e-9
    return out


def from_recording(rec, stream=None):
    """(TrackerModel, diagnosis table, info) of a delta-tracker recording; `stream` (a
    `JointStream` already decoded, e.g. by the ingest stage) saves decoding it again."""
    from pipeline.diagnose.adapters.touch_table import add_temperature
    from pipeline.ingest.streams import joint_stream
    from pipeline.ingest.temperature import temperature_stream
    from pipeline.systems import delta_tracker as dt

    model, table = dt.load(rec)
    stream = joint_stream(rec) if stream is None else stream
    tab = add_context(table, stream.t_ns, stream.q)
    temp = temperature_stream(rec)
    if temp is not None:
        tab = add_temperature(tab, temp, rec.path, dt.MEASUREMENT_CHANNEL)
    return model, tab, {"system": dt.SYSTEM}
