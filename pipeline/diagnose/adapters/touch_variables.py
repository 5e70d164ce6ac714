"""Lack of fit where the physics lives: more variables for the touch campaign.

Besides each joint angle, time, temperature and approach speed (`lack_of_fit.touch_variables`):

- ``face <id> position``: where on its face a contact lies (2-D: five Gaussian bumps over the
  face's contacts, centred within the face so that a face offset — the library's — is not
  tested here; a dent, a bump or a tilt of the face is);  `values` the first in-plane axis;
- ``q_Ji→Jj``: joint i's angle acting through joint j (pairs of neighbouring joints and J4/J6):
  a coupling of any form, e.g. a parallelogram-driven J3 whose error depends on J2's angle;
- ``payload_kg``: an error that changes with the payload, through any joint;
- ``search_direction``: a constant per search direction (±x, ±y, ±z of the jig);
- ``time_since_start_s→growth`` (and ``temperature_rise_K→growth``): a function of time (or of the
  temperature rise) acting through the link lengths (all D-H a, d scaled together) — thermal
  growth of the links, which a rigid drift of the tip does not capture.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.verdict.lack_of_fit import Variable, smooth_variable
from pipeline.models import serial_arm

PAIRS = ((0, 1), (1, 0), (1, 2), (2, 1), (2, 3), (3, 2), (3, 4), (4, 3), (4, 5), (5, 4), (3, 5), (5, 3))
MIN_ON_FACE = 8  # contacts a face needs for its position to be tested


def face_position(tip: np.ndarray, table) -> list[Variable]:
    """One variable per face with ≥ MIN_ON_FACE contacts (module docstring); tip (n, 3) in {W}."""
    faces = np.asarray(table["face"]).astype(str)
    ax = np.asarray(table["axis"], int)
    out = []
    for f in sorted(set(faces)):
        on = faces == f
        if on.sum() < MIN_ON_FACE:
            continue
        a, b = [i for i in range(3) if i != int(ax[on][0])]
        u, v = tip[on, a], tip[on, b]
        su, sv = np.ptp(u) / 2, np.ptp(v) / 2
        if su <= 1e-6 or sv <= 1e-6:
            continue
        cu, cv = u.mean(), v.mean()
        centres = [(cu, cv), (cu - su / 2, cv - sv / 2), (cu + su / 2, cv - sv / 2), (cu - su / 2, cv + sv / 2),
                   (cu + su / 2, cv + sv / 2)]
        rho = max(su, sv) / 1.5
        phi = np.stack([np.exp(-0.5 * ((u - x) ** 2 + (v - y) ** 2) / rho**2) for x, y in centres], axis=1)
        phi -= phi.mean(axis=0)  # within the face: its offset is the library's face_offset
        cols = np.zeros((faces.size, phi.shape[1]))
        cols[on] = phi
        values = np.full(faces.size, cu)
        values[on] = u
        out.append(Variable(f"face {f} position", f"m along {'xyz'[a]}", values, cols,
                            np.linspace(u.min(), u.max(), 8), float(np.ptp(u) / 7), on.astype(float)[:, None],
                            local=_local_bumps(u, v, on, max(su, sv)), place=f))
    return out


def _local_bumps(u: np.ndarray, v: np.ndarray, on: np.ndarray, half: float) -> np.ndarray:
    """(n, S) narrow 2-D Gaussian bumps on a face, one centred at each of its contacts (u, v m in-plane), radii 1/8 to
    1/3 of the face's touched extent (`half` its half-range), each less its mean over the face (its offset
    is face_offset's): a dent or a local bump there, the local alternative to a whole-face flatness."""
    d2 = (u[:, None] - u[None]) ** 2 + (v[:, None] - v[None]) ** 2
    phi = np.hstack([np.exp(-0.5 * d2 / (f * half) ** 2) for f in (0.25, 1 / 3, 0.5, 2 / 3)])
    phi -= phi.mean(axis=0)
    cols = np.zeros((on.size, phi.shape[1]))
    cols[on] = phi
    return cols


def cross_joints(q: np.ndarray, Jq_axis: np.ndarray, names: list[str]) -> list[Variable]:
    """q_Ji→Jj: bumps of joint i's angle through joint j's Jacobian row."""
    out = []
    for i, j in PAIRS:
        if max(i, j) < q.shape[1]:
            v = smooth_variable(f"q_{names[i]}→{names[j]}", "rad", q[:, i], Jq_axis[:, j:j + 1], K=6)
            if v is not None:
                out.append(v)
    return out


def payload(table, Jq_axis: np.ndarray) -> Variable | None:
    """The payload's deviation from its mean through every joint (n, n_joints) columns."""
    if "payload_kg" not in table:
        return None
    p = np.asarray(table["payload_kg"], float)
    if np.ptp(p) <= 0:
        return None
    g = (p - p.mean())[:, None] * Jq_axis
    return Variable("payload_kg", "kg", p, g, np.unique(p), float(np.ptp(p)), Jq_axis, categorical=True)


def search_direction(table) -> Variable | None:
    """A constant per search direction: code 2·axis + (normal pointing −)."""
    if "normal_sign" not in table:
        return None
    code = 2 * np.asarray(table["axis"], int) + (np.asarray(table["normal_sign"], float) < 0)
    levels = np.unique(code)
    if levels.size < 2:
        return None
    cols = (code[:, None] == levels[None]).astype(float)
    return Variable("search_direction", "code 2·axis + (normal −)", code.astype(float), cols, levels.astype(float),
                    1.0, np.ones((code.size, 1)), categorical=True)


def growth(x: np.ndarray, table, names: list[str]) -> list[Variable]:
    """Time (and temperature rise) through the link lengths (all D-H a and d scaled together)."""
    _, J = serial_arm.tip_jacobian(x, table["joint_positions"])
    ax = np.asarray(table["axis"], int)
    Jr = J[np.arange(ax.size), ax]
    pnames = [f"{j}.{k}" for j in names for k in ("d", "a")]
    idx = [6 + 5 *  # parameter layout: base 6, then θ, d, a, α, β per joint
            names.index(nm.split(".")[0]) + (1 if nm.endswith(".d") else 2) for nm in pnames]
    g = (Jr[:, idx] @ x[idx])[:, None]
    out = []
    cols = [("time_since_start_s", "s"), ("temperature_rise_K", "K")]
    cols += [(k, "K") for k in table if k.startswith("temperature_rise_K@")]  # several sensors
    for col, unit in cols:
        if col in table:
            v = smooth_variable(f"{col}→growth", unit, np.asarray(table[col], float), g, K=6)
            if v is not None:
                out.append(v)
    return out


def touch_extra(x: np.ndarray, table, names: list[str]) -> list[Variable]:
    """Every variable of the module docstring for a touch campaign at geometric parameters x."""
    q = np.asarray(table["joint_positions"], float)
    ax = np.asarray(table["axis"], int)
    rows = np.arange(ax.size)
    _, Jq = serial_arm.joint_jacobian(x, q)
    Jq_axis = Jq[rows, ax]
    tip = serial_arm.tip_position(x, q)
    out = face_position(tip, table) + cross_joints(q, Jq_axis, names)
    out += [v for v in (payload(table, Jq_axis), search_direction(table)) if v is not None]
    return out + growth(x, table, names)
