"""A payload a command is given (`--payload KG@LINK[:X,Y,Z]` of `run`, `calibrate`, `compensate`),
checked against the robot before anything is fitted or solved.

Refused, one `RobocalError` line naming the option and the element:

* a link the URDF lacks; gravity terms not asked for, or a URDF without ``<inertial>`` masses;
* a mass beyond the whole robot's (the sum of the URDF's link masses): no robot carries more than
  itself — such a number is a unit mistake (g for kg) or damage;
* a centre of mass farther from its link than the robot is long (`robot_size`: the sum of every joint
  origin's length, at least `MIN_SIZE_M`);
* a link none of whose ancestors is a movable joint of the measured chains (root → each tip; the root
  itself, a link above it or off every chain): its weight loads no joint the calibration models.

A payload on a link off the measured chains that still hangs from one of their joints (TIAGo's head
from the torso lift) is physics the model does take — through the whole-tree gravity — and is said in
one warning line naming the joints it loads.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from pipeline.errors import RobocalError
from pipeline.recording.schemas import META_URDF

MIN_SIZE_M = 1.0  # a centre of mass within a metre of its link is accepted whatever the robot's size


def _floats(text: str | None, n: int) -> list[float]:
    try:
        v = [float(x) for x in (text or "").split()]
    except ValueError:
        return [0.0] * n
    return v if len(v) == n else [0.0] * n


def robot_facts(urdf: str) -> tuple[dict[str, tuple[str, str, str]], float, float]:
    """({child link: (joint, joint type, parent link)}, total link mass kg, size m: the sum of every joint
    origin's length) of a URDF text."""
    root = ET.fromstring(urdf)
    parent: dict[str, tuple[str, str, str]] = {}
    size = 0.0
    for j in root.iter("joint"):
        c, p = j.find("child"), j.find("parent")
        if c is not None and p is not None:
            parent[c.get("link")] = (j.get("name"), j.get("type"), p.get("link"))
        o = j.find("origin")
        xyz = _floats(None if o is None else o.get("xyz"), 3)
        size += math.sqrt(sum(x * x for x in xyz)) if all(math.isfinite(x) for x in xyz) else 0.0
    mass = 0.0
    for m in root.iter("mass"):
        v = _floats(m.get("value"), 1)[0]
        mass += v if math.isfinite(v) and v > 0 else 0.0
    return parent, mass, size


def _up(parent: dict, link: str) -> list[tuple[str, str]]:
    """(joint, type) from `link` up to the top of the tree."""
    out, seen = [], set()
    while link in parent and link not in seen:
        seen.add(link)
        j, kind, link = parent[link]
        out.append((j, kind))
    return out


def _chains(parent: dict, root: str, tips: list[str]) -> tuple[set[str], list[str]]:
    """(links of the chains root → each tip, their movable joints in order)."""
    links, movable = {root}, []
    for tip in tips:
        link = tip
        while link != root and link in parent:
            links.add(link)
            j, kind, link = parent[link]
            if kind != "fixed" and j not in movable:
                movable.append(j)
    return links, movable


def check_payloads(urdf: str, root: str, tips: list[str], items, load: tuple, where: str) -> list[str]:
    """The payloads (`items` as typed, `load` parsed: (kg, link, (x, y, z))) against the robot: one-line
    errors (module docstring); returns the warnings (a payload off the measured chains that still loads
    some of their joints)."""
    parent, mass, size = robot_facts(urdf)
    size = max(size, MIN_SIZE_M)
    on_chain, movable = _chains(parent, root, tips)
    warnings = []
    for item, (kg, link, com) in zip(items, load):
        if mass > 0 and kg > mass:
            raise RobocalError(f"{where}--payload {item!r}: {kg:g} kg is more than the whole robot the URDF describes "
                               f"({mass:.4g} kg): not a payload it carries (grams given as kg?)")
        d = math.sqrt(sum(c * c for c in com))
        if d > size:
            raise RobocalError(f"{where}--payload {item!r}: centre of mass {d:.4g} m from link {link!r}, farther than "
                               f"the robot is long ({size:.3g} m, its joint origins end to end): not a payload it "
                               "carries (mm given as m?)")
        loaded = [j for j, kind in _up(parent, link) if j in movable]
        chains = f"{root} → {', '.join(tips)}"
        if not loaded:
            raise RobocalError(f"{where}--payload {item!r}: link {link!r} hangs from none of the measured chains' "
                               f"movable joints ({chains}): its weight loads nothing the calibration models")
        if link not in on_chain:
            warnings.append(f"--payload {item!r}: link {link!r} is on no measured chain ({chains}); through the "
                            f"tree it loads {', '.join(loaded)}")
    return warnings


def check_physics_input(path, physics: str | None, payload) -> list[str]:
    """Before any stage runs (`robocal run`, `calibrate`): the --physics value and the --payload items
    against the recording's URDF — a payload on a link the URDF lacks, gravity terms asked by name or a
    payload on a URDF without inertials, and `check_payloads` — one `RobocalError` line naming the
    element; returns the warnings.  Other systems: nothing."""
    from pipeline.physics import compliance
    from pipeline.physics.gravity import has_inertials
    from pipeline.recording.reader import read_recording

    mode, families = compliance.parse_spec(physics)
    load = compliance.parse_payload(payload)
    meta = read_recording(path, topics=set()).metadata.get(META_URDF)
    if not (isinstance(meta, dict) and isinstance(meta.get("urdf"), str)):
        return []
    try:
        links = {lk.get("name") for lk in ET.fromstring(meta["urdf"]).iter("link")}
    except ET.ParseError:
        return []  # the load says what is wrong with the description
    for item, (_, link, _) in zip(payload or (), load):
        if link not in links:
            raise RobocalError(f"{path}: --payload {item!r}: link {link!r} is not in the URDF "
                               f"(links: {', '.join(sorted(links)[:12])}{', …' if len(links) > 12 else ''})")
    gravity = tuple(f for f in families if f in compliance.GRAVITY)
    if load and not gravity:
        raise RobocalError(f"{path}: --payload {payload[0]!r} needs gravity terms (--physics auto or a list with "
                           f"{' or '.join(compliance.GRAVITY)})")
    if (load or mode == "fixed" and gravity) and not has_inertials(meta["urdf"]):
        what = f"gravity terms ({', '.join(gravity)})" if mode == "fixed" and gravity else f"--payload {payload[0]!r}"
        raise RobocalError(f"{path}: metadata robocal.urdf: no link has an <inertial> mass, which {what} needs "
                           "(use --physics none, no --payload)")
    tips = meta.get("tips") or [meta.get("tip")]
    if not load or not isinstance(meta.get("root"), str) or not all(isinstance(t, str) for t in tips):
        return []
    return check_payloads(meta["urdf"], meta["root"], list(tips), payload, load, f"{path}: ")
