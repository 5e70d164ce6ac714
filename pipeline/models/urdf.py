"""URDF robots: parse a description (yourdfpy), pick the chain root → tip, write a calibrated URDF.

Parsing uses **yourdfpy** (a small, maintained URDF parser on lxml and numpy, which loads without
meshes and has its own forward kinematics, used in the tests as the independent reference).
The chain is the path of joints from the `root` link down to the `tip` link; revolute,
continuous, prismatic and fixed joints, any axis; limits kept (rad or m).  Mesh files are never
opened.
"""

from __future__ import annotations

import io
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError

MAX_DEPTH = 64  # element nesting of a URDF (robot/joint/origin is 3; vendor extensions add a few)
BOUND = 1e6  # |origin xyz (m) / rpy (rad) / axis|: anything larger is damage, not geometry
MOVABLE = ("revolute", "continuous", "prismatic")
KNOWN_TYPES = MOVABLE + ("fixed",)


@dataclass(frozen=True)
class UrdfJoint:
    """One joint of the chain: its origin (parent link frame → joint frame, 4×4), unit axis in
    the joint frame, and travel limits (rad or m; ±inf when the URDF has none)."""

    name: str
    type: str
    parent: str
    child: str
    origin: tuple  # 4×4 as nested tuples (hashable)
    axis: tuple[float, float, float]
    lower: float
    upper: float

    @property
    def movable(self) -> bool:
        return self.type in MOVABLE

    @property
    def origin_matrix(self) -> np.ndarray:
        return np.array(self.origin, float)


@dataclass(frozen=True)
class RobotDescription:
    """The chain of a URDF robot from `root` to `tip` and the URDF text it came from."""

    name: str
    root: str
    tip: str
    joints: tuple[UrdfJoint, ...]
    urdf: str
    source: str = ""

    @property
    def movable(self) -> tuple[UrdfJoint, ...]:
        return tuple(j for j in self.joints if j.movable)

    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.movable]


def _fail(source: str, what: str) -> RobocalError:
    return RobocalError(f"{source}: {what}")


def _xml_checks(text: str, source: str) -> None:
    """What the parser lets through but a chain cannot have: unknown joint types, joints naming
    links that do not exist, a link with two parents (a cycle or a graph, not a tree)."""
    try:
        root = ET.fromstring(text.encode() if isinstance(text, str) else text)
    except ET.ParseError as e:
        raise _fail(source, f"not valid URDF XML ({e})") from None
    if root.tag != "robot":
        raise _fail(source, f"root element is <{root.tag}>, expected <robot>")
    if not root.get("name"):
        raise _fail(source, "<robot> has no name attribute")
    stack = [(root, 0)]
    while stack:  # a URDF is a few elements deep; thousands is damage (and lxml would print a warning)
        el, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise _fail(source, f"<{el.tag}> is nested more than {MAX_DEPTH} elements deep: not a URDF")
        stack += [(c, depth + 1) for c in el]
    links: set = set()
    for ln in root.findall("link"):
        if ln.get("name") in links:
            raise _fail(source, f"link {ln.get('name')!r} is defined twice (<link name=...> must be unique)")
        links.add(ln.get("name"))
    joints: set = set()
    parent_of: dict[str, str] = {}
    for j in root.findall("joint"):
        name, typ = j.get("name"), j.get("type")
        if name in joints:
            raise _fail(source, f"joint {name!r} is defined twice (<joint name=...> must be unique)")
        joints.add(name)
        _origin_bound(j, source)
        if typ not in KNOWN_TYPES + ("floating", "planar"):
            raise _fail(source, f"joint {name!r} has unknown type {typ!r} (expected one of {', '.join(KNOWN_TYPES)})")
        p, c = j.find("parent"), j.find("child")
        if p is None or c is None:
            raise _fail(source, f"joint {name!r} lacks a <parent> or <child> element")
        pl, cl = p.get("link"), c.get("link")
        for role, ln in (("parent", pl), ("child", cl)):
            if ln not in links:
                raise _fail(source, f"joint {name!r}: {role} link {ln!r} is not defined (missing <link name={ln!r}>)")
        if cl in parent_of:
            raise _fail(source, f"link {cl!r} is the child of two joints ({parent_of[cl]!r} and {pl!r}): not a tree")
        parent_of[cl] = pl
    for start in parent_of:  # a cycle: walking up never reaches a link without a parent
        seen, ln = set(), start
        while ln in parent_of:
            if ln in seen:
                raise _fail(source, f"the joints form a cycle through link {ln!r}")
            seen.add(ln)
            ln = parent_of[ln]


def _origin_bound(joint: ET.Element, source: str) -> None:
    """A joint's <origin> xyz (m) and rpy (rad), and its <axis>, must be numbers within ±BOUND."""
    for tag, attrs in (("origin", ("xyz", "rpy")), ("axis", ("xyz",))):
        el = joint.find(tag)
        for a in attrs:
            text = None if el is None else el.get(a)
            if text is None:
                continue
            try:
                v = [float(x) for x in text.split()]
            except ValueError:
                continue  # the parser's own message names it
            if any(not abs(x) <= BOUND for x in v):
                raise _fail(source, f"joint {joint.get('name')!r}: <{tag} {a}={text[:60]!r}>: beyond ±{BOUND:g} "
                                    "(m, rad) or not finite: not a robot's geometry")


def load_urdf_model(text: str, source: str = "<urdf>"):
    """The yourdfpy model of a URDF text (no meshes), with clear errors for what it rejects."""
    import yourdfpy

    _xml_checks(text, source)
    try:
        return yourdfpy.URDF.load(io.BytesIO(text.encode()), load_meshes=False, build_scene_graph=True,
                                  build_collision_scene_graph=False, load_collision_meshes=False)
    except Exception as e:  # the parser's own failures (malformed numbers, attributes)
        raise _fail(source, f"URDF could not be parsed ({type(e).__name__}: {e})") from None


def parse(text: str, root: str, tip: str, source: str = "<urdf>", allow_mimic: bool = False) -> RobotDescription:
    """The chain root → tip of a URDF text (see module docstring).  A `<mimic>` joint is refused
    unless `allow_mimic` (a tree model that drives it from the joint it mimics: `mimic_couplings`)."""
    robot = load_urdf_model(text, source)
    links = set(robot.link_map)
    for role, ln in (("root", root), ("tip", tip)):
        if ln not in links:
            near = ", ".join(sorted(links)[:12])
            raise _fail(source, f"--{role} link {ln!r} is not in the URDF (links: {near}{', …' if len(links) > 12 else ''})")
    by_child = {j.child: j for j in robot.robot.joints}
    path, ln = [], tip
    while ln != root:
        j = by_child.get(ln)
        if j is None:
            raise _fail(source, f"tip link {tip!r} is not below root link {root!r}")
        path.append(j)
        ln = j.parent
    joints = []
    for j in reversed(path):
        if j.mimic is not None and not allow_mimic:
            raise _fail(source, f"joint {j.name!r} mimics another joint: mimic joints are not supported in a chain")
        if j.type not in KNOWN_TYPES:
            raise _fail(source, f"joint {j.name!r} of type {j.type!r} cannot be part of a calibrated chain")
        origin = np.eye(4) if j.origin is None else np.asarray(j.origin, float)
        axis = np.array([1.0, 0, 0]) if j.axis is None else np.asarray(j.axis, float)
        if j.type in MOVABLE and not (np.all(np.isfinite(axis)) and np.linalg.norm(axis) > 0):
            raise _fail(source, f"joint {j.name!r} has a zero or non-finite axis")
        lo, hi = -np.inf, np.inf
        if j.type in ("revolute", "prismatic") and j.limit is not None:
            lo = -np.inf if j.limit.lower is None else float(j.limit.lower)
            hi = np.inf if j.limit.upper is None else float(j.limit.upper)
            if not (lo <= hi):
                raise _fail(source, f"joint {j.name!r} has limits lower {lo} > upper {hi}")
        if not np.all(np.isfinite(origin)):
            raise _fail(source, f"joint {j.name!r} has a non-finite origin")
        n = np.linalg.norm(axis) if j.type in MOVABLE else 1.0
        joints.append(UrdfJoint(j.name, j.type, j.parent, j.child, tuple(map(tuple, origin)),
                                tuple(float(a) for a in axis / n), lo, hi))
    if not any(j.movable for j in joints):
        raise _fail(source, f"the chain {root!r} → {tip!r} has no movable joint")
    return RobotDescription(name=robot.robot.name or "robot", root=root, tip=tip, joints=tuple(joints),
                            urdf=text, source=source)


def mimic_couplings(text: str, source: str = "<urdf>") -> dict[str, tuple[dict[str, float], float]]:
    """{joint: ({mimicked joint: multiplier}, offset rad)} of the URDF's `<mimic>` elements."""
    robot = load_urdf_model(text, source)
    out = {}
    for j in robot.robot.joints:
        if j.mimic is not None:
            mult = 1.0 if j.mimic.multiplier is None else float(j.mimic.multiplier)
            off = 0.0 if j.mimic.offset is None else float(j.mimic.offset)
            out[j.name] = ({str(j.mimic.joint): mult}, off)
    return out


def read(path: str | Path, root: str, tip: str) -> RobotDescription:
    """`parse` of a URDF file; a missing or unreadable file is a one-line error."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise RobocalError(f"{path}: cannot read URDF ({e.__class__.__name__}: {e})") from None
    return parse(text, root, tip, source=str(path))


# ----- rotations (URDF rpy: R = Rz(yaw)·Ry(pitch)·Rx(roll)) -------------------------------------
def rpy_of(R: np.ndarray) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw of a rotation matrix (at pitch ±90° scipy sets roll to 0 and puts
    the rotation in yaw: the angles still give back the matrix exactly)."""
    import warnings

    from scipy.spatial.transform import Rotation

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        yaw, pitch, roll = Rotation.from_matrix(R).as_euler("ZYX")
    return float(roll), float(pitch), float(yaw)


def matrix_of_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()


def _fmt(v: float) -> str:
    return repr(float(v))


def write_calibrated(desc: RobotDescription, origins: dict[str, np.ndarray], base: np.ndarray | None,
                     tool: np.ndarray | None, instrument_link: str = "robocal_instrument",
                     tool_link: str = "robocal_tool") -> str:
    """The URDF text with the chain's joint origins replaced (`origins`: joint name → 4×4) and,
    when given, the instrument frame (`base`: instrument → root, 4×4, written as a fixed child of
    the root, root → instrument = base⁻¹) and the tool frame (tip → tool_link, `tool`).
    Everything else of the robot (other links, inertials, meshes, extensions) is kept as is."""
    tree = ET.ElementTree(ET.fromstring(desc.urdf.encode()))
    robot = tree.getroot()
    for j in robot.findall("joint"):
        T = origins.get(j.get("name"))
        if T is None:
            continue
        o = j.find("origin")
        if o is None:
            o = ET.SubElement(j, "origin")
        o.set("xyz", " ".join(_fmt(v) for v in T[:3, 3]))
        o.set("rpy", " ".join(_fmt(v) for v in rpy_of(T[:3, :3])))

    def fixed(parent: str, child: str, T: np.ndarray) -> None:
        ET.SubElement(robot, "link", {"name": child})
        j = ET.SubElement(robot, "joint", {"name": f"{child}_joint", "type": "fixed"})
        ET.SubElement(j, "parent", {"link": parent})
        ET.SubElement(j, "child", {"link": child})
        ET.SubElement(j, "origin", {"xyz": " ".join(_fmt(v) for v in T[:3, 3]),
                                    "rpy": " ".join(_fmt(v) for v in rpy_of(T[:3, :3]))})

    if base is not None:  # a child of the root (the root may have a parent already): root → instrument = base⁻¹
        fixed(desc.root, instrument_link, np.linalg.inv(base))
    if tool is not None:
        fixed(desc.tip, tool_link, tool)
    ET.indent(tree, space="  ")
    return ET.tostring(robot, encoding="unicode") + "\n"
