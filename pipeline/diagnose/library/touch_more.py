"""More of the arc-welder effect library (issue 18): couplings, link growth, face shape, wire.

Same `Effect` contract and sign conventions as `pipeline.diagnose.library.term` (a ``joint`` effect
is δq added to the encoder reading to get the true joint angle; a ``tip`` effect displaces the
true tip by D·θ in {W}):

- ``joint_coupling`` Ji->Jj: δq_j = κ·q_i (rad/rad), for neighbouring joints of the arm
  (J1..J4; the wrist pairs are `wrist_coupling`) — e.g. a J3 driven through a parallelogram;
- ``joint_coupling`` Ji->Jj (quadratic): δq_j = κ₂·(q_i − q̄_i)² (rad/rad²), q̄_i the campaign's mean
  angle of joint i: the second-order term of a coupling about the campaign (the linear term is the
  entry above) — a parallelogram or a belt whose transmission is not linear in the driving angle;
- ``coupling_difference`` Ji-Jj on Jj: δq_j = κ·(q_i − q_j) (rad/rad): an error linear in the
  relative angle of two parallel joints (J2, J3);
- ``thermal_growth``: every D-H length (a, d) grows by ε·L·t (1/s), or by ε·L·ΔT (1/K) when a
  temperature is recorded — the tip moves by ε·t·Σ L ∂p/∂L, pose-dependent, unlike the rigid
  `thermal_drift`; and as a first-order warm-up, ε·L·(1 − e^(−t/τ)) (1), τ on a grid over the
  campaign's duration T (T/8, T/4, T/2, T): ``links (warm-up τ = T/4)`` (τ in s: the finding's ``form``); and the
  same warm-ups of the long links alone (`link_groups`: nominal |a| + |d| ≥ ⅓ of the longest link):
  ``links (warm-up τ = T/4, long links)`` — the links that warm need not be all the links (one growth per link is
  beyond what a touch campaign detects at a plausible size).  The forms of one family: the held-out error chooses
  among them (`forms`);
- ``face_tilt`` (per face, m/m along each in-plane axis) and ``face_flatness`` (per face, m/m²,
  a bowl about the face's contacts' centre): the face is not the plane of the drawing (the
  true tip meets it displaced by D·θ along the face's axis);
- ``wire_stickout``: the welding wire's free length grows by s·t (m/s) along the wire (the tool
  z axis) — tool length varying from contact to contact as the wire is fed and burnt.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.term import Effect, Table, temperature_columns
from pipeline.models import serial_arm

NEIGHBOURS = ((0, 1), (1, 0), (1, 2), (2, 1), (2, 3), (3, 2))
WARM_UP_FRACTIONS = (0.125, 0.25, 0.5, 1.0)  # τ / campaign duration of the warm-up forms
MIN_LINK_M = 1e-3  # a link whose nominal D-H a and d are shorter than this grows by nothing measurable
LONG_LINK_FRACTION = 1 / 3  # a long link: at least this fraction of the longest (`link_groups`)
PLAUSIBLE = {"joint_coupling": 1e-2, "joint_coupling_quadratic": 1e-2, "thermal_growth_warm_up": 1e-3, "coupling_difference": 1e-2, "thermal_growth": 1e-6,
             "thermal_growth_K": 5e-5, "face_tilt": 2e-3, "face_flatness": 0.1, "wire_stickout": 1e-6}
ADVICE = {
    "joint_coupling": "move the driving joint alone over its range while the driven one stays put",
    "coupling_difference": "vary the two joints' relative angle independently of each one",
    "thermal_growth": "revisit far-apart poses early and late in the campaign (growth scales with reach)",
    "face_tilt": "spread the contacts over the whole face",
    "face_flatness": "spread the contacts over the whole face, centre and edges",
    "wire_stickout": "cut the wire to length before each block and log it; vary the wire direction",
}


def _joint(nj: int, j: int, col: np.ndarray) -> np.ndarray:
    out = np.zeros((col.shape[0], nj, 1))
    out[:, j, 0] = col
    return out


def _coupling(i: int, j: int):
    def basis(arm, x, t):
        return _joint(arm.n_joints, j, np.asarray(t["joint_positions"], float)[:, i])
    return basis


def _quadratic(i: int, j: int):
    def basis(arm, x, t):
        qi = np.asarray(t["joint_positions"], float)[:, i]
        return _joint(arm.n_joints, j, (qi - qi.mean()) ** 2)
    return basis


def _difference(i: int, j: int):
    def basis(arm, x, t):
        q = np.asarray(t["joint_positions"], float)
        return _joint(arm.n_joints, j, q[:, i] - q[:, j])
    return basis


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


def _in_plane(arm, x, t, face: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(on-face mask, u, v) in-plane coordinates of the tip (m) about the face's contacts' centre."""
    on = np.asarray(t["face"]).astype(str) == face
    ax = np.asarray(t["axis"], int)
    p = serial_arm.tip_position(x, np.asarray(t["joint_positions"], float))
    a0 = int(ax[on][0]) if on.any() else 2
    a, b = [k for k in range(3) if k != a0]
    u = np.where(on, p[:, a] - (p[on, a].mean() if on.any() else 0), 0.0)
    v = np.where(on, p[:, b] - (p[on, b].mean() if on.any() else 0), 0.0)
    return on, u, v


def _along_axis(t, cols: np.ndarray) -> np.ndarray:
    """(n, 3, k) with the columns on each row's measured axis."""
    ax = np.asarray(t["axis"], int)
    D = np.zeros((ax.size, 3, cols.shape[1]))
    D[np.arange(ax.size), ax, :] = cols
    return D


def _tilt(face: str):
    def basis(arm, x, t):
        on, u, v = _in_plane(arm, x, t, face)
        return _along_axis(t, np.stack([u, v], axis=1))
    return basis


def _flatness(face: str):
    def basis(arm, x, t):
        on, u, v = _in_plane(arm, x, t, face)
        w = u**2 + v**2
        w = np.where(on, w - (w[on].mean() if on.any() else 0), 0.0)
        return _along_axis(t, w[:, None])
    return basis


def _stickout(arm, x, t):
    F = serial_arm.frames(x, np.asarray(t["joint_positions"], float))
    wire = F[:, -1, :3, 2]  # the tool z axis in {W}
    return (np.asarray(t["time_since_start_s"], float)[:, None] * wire)[:, :, None]


def more_effects(arm, table: Table, min_on_face: int = 8) -> list[Effect]:
    """The candidates of the module docstring for a touch campaign's table (a table of face ids
    only — the simulator's look-up of an effect by name — gets every candidate)."""
    lookup = "joint_positions" not in table
    min_on_face = 1 if lookup else min_on_face
    J = [j.name for j in arm.joints]
    P, lib = PLAUSIBLE, []
    for i, j in NEIGHBOURS:
        if max(i, j) < arm.n_joints:
            lib.append(Effect("joint_coupling", f"{J[i]}->{J[j]}", (f"coupling_{J[i]}_{J[j]}",), ("rad/rad",),
                              P["joint_coupling"], "joint", _coupling(i, j), 62, f"q_{J[i]}", ADVICE["joint_coupling"]))
            lib.append(Effect("joint_coupling", f"{J[i]}->{J[j]} (quadratic)", (f"coupling2_{J[i]}_{J[j]}",),
                              ("rad/rad^2",), P["joint_coupling_quadratic"], "joint", _quadratic(i, j), 63,
                              f"q_{J[i]}", ADVICE["joint_coupling"]))
    if arm.n_joints >= 3:
        for i, j in ((1, 2), (2, 1)):
            lib.append(Effect("coupling_difference", f"{J[i]}-{J[j]} on {J[j]}", (f"diff_{J[i]}_{J[j]}",),
                              ("rad/rad",), P["coupling_difference"], "joint", _difference(i, j), 64, f"q_{J[i]}",
                              ADVICE["coupling_difference"]))
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
        # kept only when the held-out error asks for them (`forms`)
        long_, short = link_groups(arm)
        for frac in WARM_UP_FRACTIONS if span > 0 and long_ and short else ():
            tau = frac * span
            lib.append(Effect("thermal_growth", f"links (warm-up τ = {'T' if frac == 1 else f'T/{1 / frac:.0f}'}, "
                              "long links)", ("growth_warm_up_long",), ("1",),
                              P["thermal_growth_warm_up"], "tip", _warm_up_groups(tau, (long_,)), 73, "time",
                              ADVICE["thermal_growth"], data={"form": {
                                  "tau_s": tau, "campaign_duration_s": span, "links": [J[j] for j in long_]}}))
    if "time_since_start_s" in table or lookup:
        lib.append(Effect("wire_stickout", "wire", ("stickout_rate",), ("m/s",), P["wire_stickout"], "tip", _stickout,
                          76, "time", ADVICE["wire_stickout"]))
    faces, counts = np.unique(np.asarray(table["face"]).astype(str), return_counts=True)
    for f, c in zip(faces, counts):
        if c >= min_on_face:
            lib.append(Effect("face_tilt", str(f), (f"tilt_u_{f}", f"tilt_v_{f}"), ("m/m", "m/m"), P["face_tilt"], "tip",
                              _tilt(str(f)), 92, "face", ADVICE["face_tilt"]))
            lib.append(Effect("face_flatness", str(f), (f"bowl_{f}",), ("1/m",), P["face_flatness"], "tip",
                              _flatness(str(f)), 94, "face", ADVICE["face_flatness"]))
    return lib
