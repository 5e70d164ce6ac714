"""A joint driven by others: q_c = Σ f_k · q_k + offset (`--coupled "J=EXPR"`, a recording's campaign
``coupled``, a URDF ``<mimic>``), parsed and checked against the physics of the joints it links.

Rules (each broken one is a one-line `RobocalError` naming the option or metadata and the joint):

* the driving joints are movable joints of the chains, none of them coupled itself (no chain of
  couplings, no cycle);
* units follow the joints: a factor is in (unit of the driven joint) / (unit of the driver) — rad/rad,
  m/m, m/rad or rad/m.  Between a prismatic and a revolute joint the factor must carry its unit in
  brackets, ``torso_lift=0.01[m/rad]*arm_1`` (a bare number there is ambiguous: m/rad, mm/deg…); a
  unit that does not match the joints' types is an error; the offset may carry ``[rad]`` or ``[m]``;
* every factor and offset lies within a physical bound (`FACTOR_MAX`, `OFFSET_MAX`): a coupled
  joint moving 10⁷ times its driver, or 1e308 m/rad, is damage, not a transmission.
"""

from __future__ import annotations

import math
import re

from pipeline.errors import RobocalError

# |factor| of a coupling, by (driven unit, driver unit): a gear ratio between two joints of a robot is
# well under 100 (differential wrists ±1, finger tendons 0.5–2); a pulley or pinion turning a
# prismatic joint moves under 1 m per rad; a lead screw turns under 10⁴ rad per m (0.6 mm pitch)
FACTOR_MAX = {("rad", "rad"): 100.0, ("m", "m"): 100.0, ("m", "rad"): 1.0, ("rad", "m"): 1e4}
OFFSET_MAX = {"rad": 2 * math.pi, "m": 10.0}  # |offset|: one turn; ten metres
_NUM = r"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_TERM = re.compile(rf"([+-]?)(?:({_NUM})(?:\[([a-z/]+)\])?\*?)?([A-Za-z_][\w./:]*)?")


def unit_of(joint_type: str) -> str:
    """'m' for a prismatic joint, 'rad' for a revolute or continuous one."""
    return "m" if joint_type == "prismatic" else "rad"


def parse_coupling_units(text: str) -> tuple[str, dict[str, float], float, dict[str, str]]:
    """``"J=-A-B"``, ``"J=0.5*A+0.1"``, ``"J=0.01[m/rad]*A"`` → (J, {A: factor}, offset, {A or "": unit as
    written}): a joint driven by a linear combination of others plus a constant (SI)."""
    name, sep, rhs = str(text).partition("=")
    name, rhs = name.strip(), rhs.replace(" ", "")
    terms: dict[str, float] = {}
    units: dict[str, str] = {}
    offset, pos = 0.0, 0
    while sep and name and pos < len(rhs):
        m = _TERM.match(rhs, pos)
        if m is None or m.end() == pos or not (m.group(2) or m.group(4)):
            break
        sign = -1.0 if m.group(1) == "-" else 1.0
        factor = float(m.group(2)) if m.group(2) else 1.0
        key = m.group(4) or ""
        if m.group(3):
            if units.get(key, m.group(3)) != m.group(3):
                raise RobocalError(f"--coupled {text!r}: {key or 'the offset'} is given in two units")
            units[key] = m.group(3)
        if key:
            terms[key] = terms.get(key, 0.0) + sign * factor
        else:
            offset += sign * factor
        pos = m.end()
    if not sep or not name or not terms or pos != len(rhs):
        raise RobocalError(f"--coupled {text!r}: expected JOINT=EXPR, a linear combination of joints "
                           "(e.g. torso_3=-torso_1-torso_2, j=0.5*a+0.1, lift=0.01[m/rad]*a)")
    if name in terms:
        raise RobocalError(f"--coupled {text!r}: joint {name!r} is driven by itself (a cycle)")
    return name, terms, offset, units


def parse_coupling(text: str) -> tuple[str, dict[str, float], float]:
    """(J, {A: factor}, offset) of a ``--coupled`` text (`parse_coupling_units` without the units)."""
    return parse_coupling_units(text)[:3]


def check_units(text: str, types: dict[str, str]) -> None:
    """A ``--coupled`` text's units against the joint types ({joint: URDF type}): a factor between a
    prismatic and a revolute joint carries its unit, and every unit written matches the joints."""
    name, terms, _, units = parse_coupling_units(text)
    uc = unit_of(types.get(name, "revolute"))
    for k in terms:
        uk = unit_of(types.get(k, "revolute"))
        want = f"{uc}/{uk}"
        if k in units and units[k] != want:
            raise RobocalError(f"--coupled {text!r}: the factor of {k!r} is given in {units[k]}, but "
                               f"{name!r} ({types.get(name)}, {uc}) driven by {k!r} ({types.get(k)}, {uk}) takes {want}")
        if uc != uk and k not in units:
            raise RobocalError(f"--coupled {text!r}: couples {types.get(name)} {name!r} ({uc}) to {types.get(k)} "
                               f"{k!r} ({uk}): give the factor's unit, e.g. {name}=0.01[{want}]*{k}")
    if "" in units and units[""] != uc:
        raise RobocalError(f"--coupled {text!r}: the offset is given in {units['']}, but {name!r} moves in {uc}")


def check_coupling(coupled: dict, movable: set, where_: str, types: dict[str, str] | None = None) -> None:
    """Each coupled joint ({joint: ({driver: factor}, offset)}) is driven by movable joints that are not
    coupled themselves (no chain, no cycle); with `types` ({joint: URDF type}) every factor and offset is
    finite and within its physical bound (`FACTOR_MAX`, `OFFSET_MAX` by the joints' units)."""
    for c, (terms, offset) in coupled.items():
        for k in terms:
            if k not in movable:
                raise RobocalError(f"{where_}: coupled joint {c!r} names unknown joint {k!r}")
            if k in coupled:
                raise RobocalError(f"{where_}: coupled joint {c!r} is driven by {k!r}, itself coupled "
                                   "(a cycle or a chain of couplings)")
        if types is None:
            continue
        uc = unit_of(types.get(c, "revolute"))
        for k, f in terms.items():
            bound = FACTOR_MAX[uc, unit_of(types.get(k, "revolute"))]
            if not (math.isfinite(f) and abs(f) <= bound):
                raise RobocalError(f"{where_}: coupled joint {c!r}: factor {f:.6g} of {k!r} is beyond ±{bound:g} "
                                   f"{uc}/{unit_of(types.get(k, 'revolute'))}: not a physical transmission")
        if not (math.isfinite(offset) and abs(offset) <= OFFSET_MAX[uc]):
            raise RobocalError(f"{where_}: coupled joint {c!r}: offset {offset:.6g} is beyond ±{OFFSET_MAX[uc]:.4g} "
                               f"{uc}")
