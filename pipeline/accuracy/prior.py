"""Prior uncertainty of every model parameter: what is known about it before calibration.

A parameter held at its nominal value by the rank test is not known: it is as uncertain as
the robot's manufacturing and installation tolerance.  Each parameter gets a prior 1σ (SI)
from, in increasing precedence:

1. the default of its *kind* (`kind_of`: from its unit and name, so new models work too);
2. a model that states bounds (``lower``/``upper`` attributes, e.g. the scanner's Table 2):
   uniform within them, σ = (upper − lower)/√12; a model whose kinematics were measured, not
   read from joints (a camera campaign's flange poses from the controller: its ``_known
   kinematics`` group), has σ = 0 for them — the pose chain's geometry is exact by construction;
3. the robot model file's ``prior_sigma`` object (recording metadata): keys are parameter
   names, shell patterns (``J*.beta``) or kinds, values SI;
4. the command line (``--prior KEY=VALUE``, VALUE with an optional unit: ``0.5mm``, ``0.2deg``).
"""

from __future__ import annotations

import fnmatch
import re
from typing import Iterable, Mapping

import numpy as np

from pipeline.errors import RobocalError

DEG = np.pi / 180

#: Default prior 1σ per kind (SI).  Frame placements (a base on the floor, a tool on the
#: flange, a tracker's registration) are known less well than machined link geometry.
DEFAULTS: dict[str, float] = {
    "length": 2e-3,  # m: link lengths and offsets (machining and assembly)
    "angle": 1.0 * DEG,  # rad: joint offsets, twists, axis misalignments
    "frame_translation": 5e-3,  # m: base / tool / sensor placement
    "frame_rotation": 2.0 * DEG,  # rad
    "pixel": 10.0,  # px: principal point
    "target_offset": 1e-5,  # m: a measurement target's certified offset (a tracker SMR centred in its nest)
    "compliance": 2e-5,  # rad/(N·m): a joint held rigid may have a stiffness down to ≈ 5·10⁴ N·m/rad
    "load_compliance": 2e-7,  # rad/(N·m)²: its compliance changing by 2·10⁻⁷ per N·m of load (10 % over 10 N·m)
}
#: Prior 1σ of the gravity-compliance kinds per robot class (rad/(N·m), rad/(N·m)²): an industrial arm's joints
#: are stiff (≈ 5·10⁴ N·m/rad and up); a collaborative arm's harmonic drives softer (≈ 10⁴); a torque-controlled
#: arm (joint torque sensors in the drive train: DLR / KUKA LWR, Franka, humanoids' arms) softer still (≈ 2·10³).
ROBOT_CLASSES: dict[str, dict[str, float]] = {
    "industrial": {"compliance": 2e-5, "load_compliance": 2e-7},
    "collaborative": {"compliance": 1e-4, "load_compliance": 1e-6},
    "torque-controlled": {"compliance": 5e-4, "load_compliance": 5e-6},
}
RELATIVE_DEFAULT = 0.1  # any other unit: 10 % of |nominal| (1 where the nominal is 0)
FRAME_PREFIXES = ("base.", "tool.", "tracker.", "registration.", "hand_eye.")
TARGET_PREFIXES = ("reflector.", "target.", "smr.")

_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "rad": 1.0, "mrad": 1e-3, "deg": DEG, "°": DEG,
          "px": 1.0, "": 1.0}


def kind_of(name: str, unit: str) -> str:
    """Kind of a parameter from its unit and name (see DEFAULTS); 'relative' otherwise."""
    frame = name.startswith(FRAME_PREFIXES)
    if unit == "m" and name.startswith(TARGET_PREFIXES):
        return "target_offset"
    if unit == "m":
        return "frame_translation" if frame else "length"
    if unit == "rad":
        return "frame_rotation" if frame else "angle"
    if unit == "px":
        return "pixel"
    if unit.startswith("rad/(N") and unit.endswith("²"):
        return "load_compliance"
    if unit.startswith("rad/(N"):
        return "compliance"
    return "relative"


def parse_quantity(text: str, what: str = "value") -> float:
    """'0.1mm' → 1e-4, '0.2deg' → rad, '3e-4' → 3e-4 (SI when no unit)."""
    m = re.fullmatch(r"\s*([-+0-9.eE]+)\s*([a-zµ°]*)\s*", str(text))
    if not m or m.group(2) not in _UNITS:
        raise RobocalError(f"{what}: cannot read {text!r} (a number with an optional unit: m, mm, um, rad, deg, px)")
    try:
        return float(m.group(1)) * _UNITS[m.group(2)]
    except ValueError:
        raise RobocalError(f"{what}: cannot read {text!r} as a number") from None


def parse_overrides(items: Iterable[str]) -> dict[str, float]:
    """`KEY=VALUE` strings (command line) → {key: σ SI}."""
    out = {}
    for it in items:
        key, sep, val = it.partition("=")
        if not sep or not key.strip():
            raise RobocalError(f"--prior {it!r}: expected NAME=SIGMA (e.g. base.x=5mm, angle=0.5deg)")
        out[key.strip()] = parse_quantity(val, f"--prior {key.strip()}")
    return out


def _apply(sigma: np.ndarray, source: list[str], names: list[str], kinds: list[str],
           overrides: Mapping[str, float], label: str) -> None:
    for key, val in overrides.items():
        v = float(val)
        if not np.isfinite(v) or v < 0:
            raise RobocalError(f"{label}: prior for {key!r} must be a finite σ ≥ 0, got {val!r}")
        hit = [i for i, (n, k) in enumerate(zip(names, kinds)) if n == key or k == key or fnmatch.fnmatchcase(n, key)]
        if not hit:
            raise RobocalError(f"{label}: prior {key!r} matches no parameter or kind "
                               f"(kinds: {', '.join(sorted(set(kinds)))})")
        for i in hit:
            sigma[i], source[i] = v, label


def prior_sigma(model, overrides_file: Mapping[str, float] | None = None,
                overrides_cli: Mapping[str, float] | None = None,
                robot_class: str | None = None) -> tuple[np.ndarray, list[str], list[str]]:
    """(σ per parameter (P,) SI, kind per parameter, where each σ came from); `robot_class` (a key of
    `ROBOT_CLASSES`, default industrial) sets the compliance kinds' defaults."""
    names, units = model.parameter_names(), model.parameter_units()
    nominal = np.asarray(model.nominal(), float)
    kinds = [kind_of(n, u) for n, u in zip(names, units)]
    by_class = ROBOT_CLASSES.get(robot_class or "industrial", {})
    sigma = np.array([by_class.get(k, DEFAULTS.get(k, RELATIVE_DEFAULT * (abs(v) or 1.0)))
                      for k, v in zip(kinds, nominal)])
    source = [f"class {robot_class}:{k}" if robot_class and k in by_class else "default:" + k for k in kinds]
    lo, hi = getattr(model, "lower", None), getattr(model, "upper", None)
    if lo is not None and hi is not None:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        k = min(lo.size, len(names))
        sigma[:k] = (hi[:k] - lo[:k]) / np.sqrt(12.0)
        source[:k] = ["model bounds (uniform)"] * k
    groups = model.groups() if callable(getattr(model, "groups", None)) else {}
    for n in groups.get("_known kinematics", ()):
        i = names.index(n)
        sigma[i], source[i] = 0.0, "known (measured poses)"
    _apply(sigma, source, names, kinds, overrides_file or {}, "robot model file prior_sigma")
    _apply(sigma, source, names, kinds, overrides_cli or {}, "--prior")
    return sigma, kinds, source


def check_class(text: str | None) -> str:
    """`text` if it is auto or a robot class; else a one-line error naming them."""
    t = (text or "auto").strip().lower()
    if t != "auto" and t not in ROBOT_CLASSES:
        raise RobocalError(f"--robot-class {text!r}: expected auto or {', '.join(ROBOT_CLASSES)}")
    return t


def choose_class(model, x: np.ndarray, free: np.ndarray, asked: str = "auto") -> dict | None:
    """{class, asked, reason, compliance_sigma} of the prior a run judges the robot's compliances by; None for a
    model without compliance terms.  ``auto``: the stiffest class under which every estimated compliance lies within
    3 prior σ — an estimate far beyond an industrial arm's prior says the robot is of a softer class, not that each
    of its joints is implausible; a robot softer than every class keeps the softest and its estimates are named."""
    names, units = model.parameter_names(), model.parameter_units()
    comp = [i for i, (n, u) in enumerate(zip(names, units)) if kind_of(n, u) == "compliance" and free[i]]
    if not comp and not any(kind_of(n, u) == "compliance" for n, u in zip(names, units)):
        return None
    if asked != "auto":
        return {"class": asked, "asked": asked, "reason": f"--robot-class {asked}",
                "compliance_sigma": ROBOT_CLASSES[asked]["compliance"]}
    top = float(np.max(np.abs(np.asarray(x, float)[comp]))) if comp else 0.0
    for name, kinds in ROBOT_CLASSES.items():
        if top <= 3.0 * kinds["compliance"]:
            why = ("no compliance estimated" if not comp else f"its largest estimated compliance {top:.3g} rad/(N·m) "
                   f"lies within 3σ of this class's prior ({kinds['compliance']:.3g})")
            return {"class": name, "asked": "auto", "reason": f"auto: {why}", "compliance_sigma": kinds["compliance"]}
    name = list(ROBOT_CLASSES)[-1]
    return {"class": name, "asked": "auto", "compliance_sigma": ROBOT_CLASSES[name]["compliance"],
            "reason": f"auto: its largest estimated compliance {top:.3g} rad/(N·m) is beyond every class's prior: the "
                      f"softest kept"}
