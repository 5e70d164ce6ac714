"""Thermal terms: the tip drifts, or the links grow, with time or with a recorded temperature.

- ``thermal_drift``: the tip (in the jig frame {W}) moves by v·t (m/s, t the time since the start of
  the recording), or by g·ΔT (m/K) when a temperature channel is recorded (ΔT its rise since the first
  reading, K), one term per sensor;
- ``thermal_growth``: every D-H length (a, d) grows by ε·L·t (1/s), or by ε·L·ΔT (1/K) when a
  temperature is recorded — the tip moves by ε·t·Σ L ∂p/∂L, pose-dependent, unlike the rigid drift;
  and as a first-order warm-up, ε·L·(1 − e^(−t/τ)) (1), τ on a grid over the campaign's duration T
  (T/8, T/4, T/2, T): ``links (warm-up τ = T/4)`` (τ in s: the finding's ``form``); and the same
  warm-ups of the long links alone (`link_groups`: nominal |a| + |d| ≥ ⅓ of the longest link):
  ``links (warm-up τ = T/4, long links)``.  The forms of one family: the held-out error chooses
  among them (`inference.forms`).

Tip bases are (n, 3, k) m per unit of θ, in {W}.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.term import Effect, Table
from pipeline.models import serial_arm

PLAUSIBLE_THERMAL_M_PER_K = 1e-4  # 100 µm/K: a 1 m steel link grows 12 µm/K, 2 m of aluminium 46 µm/K
PLAUSIBLE = {
    "thermal_drift": 2e-6,  # m/s (7 mm/h)
    "thermal_growth": 1e-6,  # 1/s
    "thermal_growth_K": 5e-5,  # 1/K
    "thermal_growth_warm_up": 1e-3,  # 1
}
ADVICE = {
    "thermal_drift": "interleave the faces in time (revisit each face early and late in the campaign)",
    "thermal_growth": "revisit far-apart poses early and late in the campaign (growth scales with reach)",
}
WARM_UP_FRACTIONS = (0.125, 0.25, 0.5, 1.0)  # τ / campaign duration of the warm-up forms
MIN_LINK_M = 1e-3  # a link whose nominal D-H a and d are shorter than this grows by nothing measurable
LONG_LINK_FRACTION = 1 / 3  # a long link: at least this fraction of the longest (`link_groups`)


# ----- rigid drift ----------------------------------------------------------------------------
def _drift(arm, x, t):
    ts = np.asarray(t["time_since_start_s"], float)
    return ts[:, None, None] * np.eye(3)[None]


def _drift_temperature(arm, x, t):
    """The tip moves by g·ΔT (ΔT: temperature rise since the first reading, K)."""
    dT = np.asarray(t["temperature_rise_K"], float)
    return dT[:, None, None] * np.eye(3)[None]


def _drift_column(column: str):
    def basis(arm, x, t):
        return np.asarray(t[column], float)[:, None, None] * np.eye(3)[None]
    return basis


def temperature_columns(table: Table) -> list[tuple[str, str]]:
    """(column, sensor) of each recorded temperature rise: ``temperature_rise_K`` (the first sensor)
    and ``temperature_rise_K@<sensor>`` (each other sensor, `adapters.touch_table`)."""
    out = []
    if "temperature_rise_K" in table:
        out.append(("temperature_rise_K", str(np.asarray(table["temperature_sensor"])[0])
                    if "temperature_sensor" in table else "sensor"))
    return out + [(k, k.split("@", 1)[1]) for k in table if k.startswith("temperature_rise_K@")]


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


def sensor_drift(column: str, sensor: str) -> Effect:
    """thermal_drift against a further temperature sensor's rise (`column`), m/K."""
    return Effect("thermal_drift", f"temperature {sensor}", ("drift_x", "drift_y", "drift_z"), ("m/K",) * 3,
                  PLAUSIBLE_THERMAL_M_PER_K, "tip", _drift_column(column), 70, column, ADVICE["thermal_drift"],
                  confounders=("face_offset",))


# ----- growth of the links --------------------------------------------------------------------
def _length_columns(arm, x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Σ_L L·∂p/∂L (n, 3) m over every joint's D-H a and d."""
    _, J = serial_arm.tip_jacobian(x, q)
    idx = [6 + 5 * j + m for j in range(arm.n_joints) for m in (1, 2)]  # θ, d, a, α, β per joint
    return np.einsum("nip,p->ni", J[:, :, idx], np.asarray(x, float)[idx])


def _growth(column: str):
    def basis(arm, x, t):
        tau = np.asarray(t[column], float)
        return (tau[:, None] * _length_columns(arm, x, np.asarray(t["joint_positions"], float)))[:, :, None]
    return basis


def _warm_up(tau_s: float):
    def basis(arm, x, t):
        w = 1.0 - np.exp(-np.asarray(t["time_since_start_s"], float) / tau_s)
        return (w[:, None] * _length_columns(arm, x, np.asarray(t["joint_positions"], float)))[:, :, None]
    return basis


def _group_columns(x: np.ndarray, q: np.ndarray, groups: tuple[tuple[int, ...], ...]) -> np.ndarray:
    """(n, 3, len(groups)) m: per group of joints, Σ L·∂p/∂L over their D-H a and d (θ, d, a, α, β per joint)."""
    _, J = serial_arm.tip_jacobian(x, q)
    x = np.asarray(x, float)
    idx = [[6 + 5 * j + m for j in g for m in (1, 2)] for g in groups]
    return np.stack([np.einsum("nip,p->ni", J[:, :, ix], x[ix]) for ix in idx], axis=2)


def _warm_up_groups(tau_s: float, groups: tuple[tuple[int, ...], ...]):
    def basis(arm, x, t):
        w = 1.0 - np.exp(-np.asarray(t["time_since_start_s"], float) / tau_s)
        return w[:, None, None] * _group_columns(x, np.asarray(t["joint_positions"], float), groups)
    return basis


def link_groups(arm) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(long, short) joint indices: the links whose nominal D-H length (|a| + |d|) is at least
    `LONG_LINK_FRACTION` of the longest (the upper arm and forearm of an anthropomorphic arm), the others
    of length ≥ `MIN_LINK_M`."""
    L = np.array([abs(j.a) + abs(j.d) for j in arm.joints])
    long_ = tuple(int(j) for j in np.flatnonzero(L >= LONG_LINK_FRACTION * L.max()))
    return long_, tuple(int(j) for j in np.flatnonzero((L >= MIN_LINK_M) & (L < LONG_LINK_FRACTION * L.max())))


def growth_terms(arm, table: Table, lookup: bool) -> list[Effect]:
    """The ``thermal_growth`` candidates of the module docstring: per temperature sensor when the table
    carries a temperature, else against time and as warm-ups (every link, then the long links alone)."""
    J = [j.name for j in arm.joints]
    P, lib = PLAUSIBLE, []
    if "temperature_rise_K" in table:
        for col, sensor in temperature_columns(table):  # the first sensor, then each other one
            lib.append(Effect("thermal_growth", "links (temperature)" if col == "temperature_rise_K" else
                              f"links (temperature {sensor})", ("growth_per_K",), ("1/K",), P["thermal_growth_K"],
                              "tip", _growth(col), 72, col, ADVICE["thermal_growth"]))
    elif "time_since_start_s" in table or lookup:
        lib.append(Effect("thermal_growth", "links", ("growth_rate",), ("1/s",), P["thermal_growth"], "tip",
                          _growth("time_since_start_s"), 72, "time", ADVICE["thermal_growth"]))
        t = np.asarray(table.get("time_since_start_s", np.zeros(0)), float)
        span = float(np.max(t)) if t.size else 0.0
        for frac in WARM_UP_FRACTIONS if span > 0 else ():
            tau = frac * span
            lib.append(Effect("thermal_growth", f"links (warm-up τ = {'T' if frac == 1 else f'T/{1 / frac:.0f}'})", ("growth_warm_up",), ("1",),
                              P["thermal_growth_warm_up"], "tip", _warm_up(tau), 73, "time",
                              ADVICE["thermal_growth"], data={"form": {"tau_s": tau, "campaign_duration_s": span}}))
        # the same warm-ups of the long links alone (the links that warm need not be all the links; a
        # growth per link or per group is beyond the campaign's detectable size): forms of the same family,
        # kept only when the held-out error asks for them (`inference.forms`)
        long_, short = link_groups(arm)
        for frac in WARM_UP_FRACTIONS if span > 0 and long_ and short else ():
            tau = frac * span
            lib.append(Effect("thermal_growth", f"links (warm-up τ = {'T' if frac == 1 else f'T/{1 / frac:.0f}'}, "
                              "long links)", ("growth_warm_up_long",), ("1",),
                              P["thermal_growth_warm_up"], "tip", _warm_up_groups(tau, (long_,)), 73, "time",
                              ADVICE["thermal_growth"], data={"form": {
                                  "tau_s": tau, "campaign_duration_s": span, "links": [J[j] for j in long_]}}))
    return lib
