"""Effort → joint torque: the conversion a recording declares for its drives' effort readings.

A controller logs an *effort* per joint: a torque in N·m (a force in N for a prismatic joint, ROS
``JointState.effort``'s convention) or a raw drive value (a motor current, a controller unit).  A
recording says which in its campaign metadata ``effort`` (docs/reference/recording-format.md)::

    {"unit": "N·m"}                                   efforts are joint torques already
    {"unit": "raw", "scale": {J: k}, "offset": {J: c}, "mix": {J: {K: f}}}
    {"unit": "unknown"}                                nothing declared: no torque can be fitted

with τ_J = k_J · Σ_K f_JK · e_K + c_J (N·m, N): `scale` k (N·m per raw unit: gear ratio × motor
constant), `offset` c (N·m; e.g. the weight a prismatic lift's drive does not report), `mix` the raw
readings a joint's torque combines (a differential wrist: τ6 = k(e7 − e6), τ7 = k(e6 + e7); default
f_JJ = 1).  ``fit_joints`` names the joints whose torque is fitted and scored (the others' efforts are
not trusted, their motion still enters the model).  Everything here is pure: `parse_*` read the
command line's words, `check` a metadata document, `matrix` / `to_torque` apply it, vectorised.
"""

from __future__ import annotations

import re

import numpy as np

from pipeline.errors import RobocalError

UNITS = ("N·m", "raw", "unknown")
_NUM = r"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_FACTOR = rf"(?:{_NUM}|pi)(?:\*(?:{_NUM}|pi))?(?:/(?:{_NUM}|pi))?"  # 45, 1/32, pi/2, 2*pi, 32/45
_VALUE = re.compile(rf"\s*([+-]?)({_FACTOR})\s*")
_TERM = re.compile(rf"([+-]?)(?:({_FACTOR})\*)?([A-Za-z_][\w./:]*)?")
GRAVITY = 9.81  # m/s², the value FIGAROH and robot controllers use for a lift's weight offset


def number(text: str) -> float | None:
    """A number as a calibration engineer writes it: ``0.5``, ``-1e-3``, ``1/32`` (a gear ratio's
    inverse), ``pi/2``, ``-2*pi``, ``32/45``; None when `text` is not one."""
    m = _VALUE.fullmatch(text)
    if m is None:
        return None
    num, _, den = m.group(2).partition("/")
    a, _, b = num.partition("*")
    val = [np.pi if w == "pi" else float(w) for w in (a, b or "1", den or "1")]
    if val[2] == 0:
        return None
    return (-1.0 if m.group(1) == "-" else 1.0) * val[0] * val[1] / val[2]


def parse_pairs(option: str, items: list[str], joints: list[str], words: tuple[str, ...] = ()) -> dict[str, float | str]:
    """``J=K,J2=K2`` (repeatable) → {joint: number} (or one of `words`); one line for a joint the
    chain lacks or a value that is not a number."""
    out: dict[str, float | str] = {}
    for item in items:
        for part in (p.strip() for p in item.split(",") if p.strip()):
            name, sep, val = part.partition("=")
            name, val = name.strip(), val.strip()
            if not sep or not name:
                raise RobocalError(f"{option} {part!r}: expected JOINT=VALUE")
            if name not in joints:
                raise RobocalError(f"{option} {part!r}: {name!r} is not a joint of the chain ({', '.join(joints)})")
            if val in words:
                out[name] = val
                continue
            v = number(val)
            if v is None:
                raise RobocalError(f"{option} {part!r}: {val!r} is not a number (e.g. 0.5, 1/32, pi/2)"
                                   + (f" (or {', '.join(words)})" if words else ""))
            if not np.isfinite(v):
                raise RobocalError(f"{option} {part!r}: {val!r} is not a finite number")
            out[name] = v
    return out


def parse_mix(items: list[str], joints: list[str], option: str = "--effort-mix",
              example: str = "arm_6_joint=-arm_6_joint+arm_7_joint") -> dict[str, dict[str, float]]:
    """``J=-A+B`` (repeatable; a factor ``2*A``, ``32/45*A``) → {J: {A: -1, B: 1}}: the raw readings
    joint J's value combines."""
    out: dict[str, dict[str, float]] = {}
    for text in items:
        name, sep, rhs = text.partition("=")
        name, rhs = name.strip(), rhs.replace(" ", "")
        terms: dict[str, float] = {}
        pos = 0
        while sep and pos < len(rhs):
            m = _TERM.match(rhs, pos)
            if m is None or m.end() == pos or not m.group(3):
                break
            terms[m.group(3)] = terms.get(m.group(3), 0.0) + (-1.0 if m.group(1) == "-" else 1.0) * (
                number(m.group(2)) if m.group(2) else 1.0)
            pos = m.end()
        if not sep or not name or not terms or pos != len(rhs):
            raise RobocalError(f"{option} {text!r}: expected JOINT=EXPR, a linear combination of joints' raw "
                               f"readings (e.g. {example})")
        for k in (name, *terms):
            if k not in joints:
                raise RobocalError(f"{option} {text!r}: {k!r} is not a joint of the chain ({', '.join(joints)})")
        out[name] = terms
    return out


def declaration(joints: list[str], scale: dict, offset: dict, mix: dict, fit_joints: list[str],
                unit: str | None = None) -> dict:
    """The campaign's ``effort`` document from the command line's words: raw units with a scale where
    one is given, N·m where `unit` says so, else ``unknown``."""
    if unit not in (None, "N·m", "Nm", "raw", "unknown"):
        raise RobocalError(f"--effort-units {unit!r}: expected Nm (efforts are joint torques) or raw")
    unit = "N·m" if unit == "Nm" else unit
    if unit is None:
        unit = "raw" if scale else "unknown"
    bad = [j for j in fit_joints if j not in joints]
    if bad:
        raise RobocalError(f"--effort-joints: {', '.join(bad)} not in the chain ({', '.join(joints)})")
    doc: dict = {"unit": unit, "fit_joints": list(fit_joints or joints)}
    if unit == "raw":
        missing = [j for j in doc["fit_joints"] if j not in scale]
        if missing:
            raise RobocalError(f"--effort-scale has no constant for fitted joint(s) {', '.join(missing)} "
                               "(N·m per raw unit; or leave them out with --effort-joints)")
        doc |= {"scale": {j: float(scale[j]) for j in joints if j in scale}}
    elif scale:
        raise RobocalError(f"--effort-scale with --effort-units {unit}: constants convert raw efforts only")
    if offset:
        doc["offset"] = dict(offset)
    if mix:
        doc["mix"] = {j: dict(t) for j, t in mix.items()}
    return doc


def check(doc, joints: list[str], where_: str) -> dict:
    """The campaign's ``effort`` document checked against the chain's joints; one line naming the
    field that is wrong.  Returns it with defaults filled in (``fit_joints`` all joints)."""
    if not isinstance(doc, dict) or doc.get("unit") not in UNITS:
        raise RobocalError(f"{where_}: effort.unit {None if not isinstance(doc, dict) else doc.get('unit')!r} is "
                           f"not one of {', '.join(UNITS)}")
    fit = doc.get("fit_joints", joints)
    if not isinstance(fit, list) or not fit or any(j not in joints for j in fit):
        raise RobocalError(f"{where_}: effort.fit_joints {fit!r} must list joints of the chain ({', '.join(joints)})")
    for key in ("scale", "offset"):
        v = doc.get(key, {})
        if not isinstance(v, dict) or any(j not in joints or isinstance(x, bool) or not isinstance(x, (int, float))
                                          or not np.isfinite(x) for j, x in v.items()):
            raise RobocalError(f"{where_}: effort.{key} must map joints of the chain to finite numbers")
    mix = doc.get("mix", {})
    if not isinstance(mix, dict) or any(j not in joints or not isinstance(t, dict) or not t or any(
            k not in joints or not isinstance(f, (int, float)) or not np.isfinite(f) for k, f in t.items())
            for j, t in mix.items()):
        raise RobocalError(f"{where_}: effort.mix must map joints to {{joint: factor}} of joints of the chain")
    if doc["unit"] == "raw" and (missing := [j for j in fit if j not in doc.get("scale", {})]):
        raise RobocalError(f"{where_}: effort.scale has no constant for fitted joint(s) {', '.join(missing)}")
    return {**doc, "fit_joints": list(fit)}


def require_units(doc: dict, where_: str) -> None:
    """One line when the recording does not say what its efforts are (no torque can be fitted)."""
    if doc.get("unit") == "unknown":
        raise RobocalError(f"{where_}: effort units unknown: the recording declares no effort → torque conversion "
                           "(import with --effort-scale JOINT=K,… for raw drive values, or --effort-units Nm; motor "
                           "constants unknown: the reductions alone, every parameter then in that common unknown unit)")


def matrix(doc: dict, joints: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(M (J, J), c (J,)) with τ = M e + c for efforts e in `joints` order (identity for N·m)."""
    n = len(joints)
    if doc.get("unit") == "N·m":
        return np.eye(n), np.array([float(doc.get("offset", {}).get(j, 0.0)) for j in joints])
    return scaled_mix(doc, joints, default_scale=0.0)


def scaled_mix(doc: dict, joints: list[str], default_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """(M (J, J), c (J,)) of a per-joint declaration {scale, offset, mix} (joint names → numbers; mix: joint →
    {joint: factor}) in `joints` order: out_J = scale_J · Σ_K mix_JK · raw_K + offset_J, a joint without a mix
    taking its own reading, without a scale `default_scale`, without an offset 0 (efforts and positions alike)."""
    n = len(joints)
    idx = {j: i for i, j in enumerate(joints)}
    mix = np.eye(n)
    for j, terms in (doc.get("mix") or {}).items():
        mix[idx[j]] = 0.0
        for k, f in terms.items():
            mix[idx[j], idx[k]] = float(f)
    scale = np.array([float((doc.get("scale") or {}).get(j, default_scale)) for j in joints])
    offset = np.array([float((doc.get("offset") or {}).get(j, 0.0)) for j in joints])
    return scale[:, None] * mix, offset


def to_torque(effort: np.ndarray, doc: dict, joints: list[str]) -> np.ndarray:
    """Joint torques (T, J) N·m (N prismatic) of efforts (T, J) in `joints` order."""
    M, c = matrix(doc, joints)
    return np.asarray(effort, float) @ M.T + c
