"""The calibrated URDF chain in the files ROS stacks load as they are (beside model.urdf).

- `ur_calibration_yaml`: for a Universal Robots arm (its six joints ``shoulder_pan_joint`` …
  ``wrist_3_joint``, any prefix), the controller calibration file ur_robot_driver / ur_description
  take as ``kinematics_params_file`` (the format ur_calibration writes):
  ``kinematics: {shoulder: {x, y, z, roll, pitch, yaw}, upper_arm, forearm, wrist_1, wrist_2,
  wrist_3, hash}`` — each entry the origin of one joint (parent link → joint frame; m, URDF rpy
  rad), shoulder ↔ shoulder_pan_joint, upper_arm ↔ shoulder_lift_joint, forearm ↔ elbow_joint,
  wrist_k ↔ wrist_k_joint.  A joint offset is folded into its origin's rotation (the joint axis is
  z: Rot(z, q + θ₀) = Rot(z, θ₀)·Rot(z, q)).  ``hash`` is in the driver's form ``calib_<uint64>``,
  formed as the UR client library forms the controller's checksum (`ur_hash`: libstdc++'s
  ``std::hash<std::string>`` of the values written one after the other as a C++ stream writes a
  double) but of robocal's values: it names this calibration and never equals the controller's
  factory checksum, so the driver's start-up check says the two differ — as they do (the
  controller's own Cartesian kinematics keep the factory calibration).
- `offsets_yaml`: the corrections in robot_calibration's convention (its
  ``OptimizationOffsets::updateURDF``), one ``name: value`` line each, names = URDF joint names:
  ``<joint>: θ₀`` (rad or m) a joint-position offset (the model reads q + θ₀; updateURDF writes it to
  the joint's ``<calibration rising=…>``), and ``<joint>_x/_y/_z`` (m) ``<joint>_a/_b/_c`` (rad, an
  axis-magnitude rotation vector) a frame offset right-multiplied onto the joint's origin,
  ``origin = origin · offset``: the translation in the joint's own (nominal origin) frame.  The
  registration and the tool are the fixed joints ``robocal_instrument_joint`` (root link →
  ``robocal_instrument``) and ``robocal_tool_joint`` (tip link → ``robocal_tool``) of model.urdf,
  whose nominal origins are the identity: their offsets are their calibrated origins.
- `load_ur_calibration` reads a UR file back; `apply_ur_calibration` puts it into a URDF text.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import numpy as np

from pipeline.errors import RobocalError
from pipeline.models.urdf import rpy_of

UR_JOINTS = (("shoulder", "shoulder_pan_joint"), ("upper_arm", "shoulder_lift_joint"), ("forearm", "elbow_joint"),
             ("wrist_1", "wrist_1_joint"), ("wrist_2", "wrist_2_joint"), ("wrist_3", "wrist_3_joint"))
KEYS = ("x", "y", "z", "roll", "pitch", "yaw")


def _num(v: float) -> str:
    return repr(float(v))


def ur_joint_names(joint_names: list[str]) -> dict[str, str] | None:
    """UR file entry → the chain's joint name, when the chain's movable joints are a UR arm's six
    (one common prefix); else None."""
    if len(joint_names) != 6:
        return None
    prefix = joint_names[0][: -len(UR_JOINTS[0][1])] if joint_names[0].endswith(UR_JOINTS[0][1]) else None
    if prefix is None or [prefix + j for _, j in UR_JOINTS] != list(joint_names):
        return None
    return {k: prefix + j for k, j in UR_JOINTS}


def ur_calibration_yaml(joint_names: list[str], origins: dict[str, np.ndarray]) -> str | None:
    """The UR kinematics file of calibrated joint origins (joint name → 4×4), or None when the
    chain is not a UR arm."""
    names = ur_joint_names(joint_names)
    if names is None:
        return None
    rows, values = ["kinematics:"], []
    for key, joint in names.items():
        T = np.asarray(origins[joint], float)
        v = list(T[:3, 3]) + list(rpy_of(T[:3, :3]))
        values += v
        rows.append(f"  {key}:")
        rows += [f"    {k}: {_num(x)}" for k, x in zip(KEYS, v)]
    rows.append(f"  hash: {ur_hash(values)}")
    return "\n".join(rows) + "\n"


_MASK = (1 << 64) - 1
_MUL = 0xC6A4A7935BD1E995


def _shift_mix(v: int) -> int:
    return v ^ (v >> 47)


def cpp_string_hash(data: bytes, seed: int = 0xC70F6907) -> int:
    """libstdc++'s ``std::hash<std::string>`` on a 64-bit platform (``_Hash_bytes``, a MurmurHash64A
    variant, with the seed ``std::hash`` passes), as an unsigned 64-bit integer."""
    n = len(data)
    h = (seed ^ (n * _MUL)) & _MASK
    aligned = n & ~7
    for i in range(0, aligned, 8):
        k = _shift_mix((int.from_bytes(data[i:i + 8], "little") * _MUL) & _MASK) * _MUL & _MASK
        h = ((h ^ k) * _MUL) & _MASK
    if n & 7:
        h = ((h ^ int.from_bytes(data[aligned:], "little")) * _MUL) & _MASK
    h = (_shift_mix(h) * _MUL) & _MASK
    return _shift_mix(h)


def cpp_stream(v: float) -> str:
    """A double as ``std::ostream << double`` writes it by default (precision 6, ``%g``)."""
    return "%g" % float(v)


def ur_hash(values) -> str:
    """``calib_<uint64>``: the UR client library's checksum rule (``KinematicsInfo::toHash``: every value
    streamed in turn, ``std::hash`` of the text) applied to `values`."""
    return f"calib_{cpp_string_hash(''.join(cpp_stream(v) for v in values).encode())}"


def load_ur_calibration(text: str, source: str = "<calibration.yaml>") -> dict[str, np.ndarray]:
    """UR file entry (shoulder … wrist_3) → its joint origin (4×4); a malformed file is a one-line error."""
    import yaml

    from pipeline.models.urdf import matrix_of_rpy

    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise RobocalError(f"{source}: not YAML ({e.__class__.__name__})") from None
    kin = doc.get("kinematics") if isinstance(doc, dict) else None
    if not isinstance(kin, dict):
        raise RobocalError(f"{source}: no 'kinematics' mapping")
    out = {}
    for key, _ in UR_JOINTS:
        e = kin.get(key)
        if not isinstance(e, dict) or not all(isinstance(e.get(k), (int, float)) for k in KEYS):
            raise RobocalError(f"{source}: kinematics.{key} must hold numbers {', '.join(KEYS)}")
        T = np.eye(4)
        T[:3, :3] = matrix_of_rpy(e["roll"], e["pitch"], e["yaw"])
        T[:3, 3] = (e["x"], e["y"], e["z"])
        out[key] = T
    return out


def apply_ur_calibration(urdf_text: str, calibration: dict[str, np.ndarray], prefix: str = "") -> str:
    """The URDF text with the UR joints' origins set from a loaded calibration (as ur_description's
    macro does with kinematics_params_file)."""
    robot = ET.fromstring(urdf_text.encode())
    joints = {j.get("name"): j for j in robot.findall("joint")}
    for key, joint in UR_JOINTS:
        j = joints.get(prefix + joint)
        if j is None:
            raise RobocalError(f"URDF has no joint {prefix + joint!r}")
        o = j.find("origin")
        if o is None:
            o = ET.SubElement(j, "origin")
        T = calibration[key]
        o.set("xyz", " ".join(_num(v) for v in T[:3, 3]))
        o.set("rpy", " ".join(_num(v) for v in rpy_of(T[:3, :3])))
    return ET.tostring(robot, encoding="unicode")


INSTRUMENT_JOINT = "robocal_instrument_joint"
TOOL_JOINT = "robocal_tool_joint"


def offsets_yaml(arm, x: np.ndarray) -> str:
    """The corrections of a `UrdfArm` at parameters x in robot_calibration's convention (module docstring):
    for each movable joint, the frame offset C = [R₀ᵀ(t − t₀), Rx·Ry·Rz] with origin · C = the calibrated
    origin (t₀, R₀ the URDF's own) and the joint-position offset θ₀; for the two robocal joints their
    calibrated origins (instrument: root → instrument = base⁻¹; tool: tip → tool)."""
    from scipy.spatial.transform import Rotation

    names = arm.parameter_names()
    val = {n: float(v) for n, v in zip(names, np.asarray(x, float))}
    rows = [f"# robocal calibrated parameters of {arm.desc.name} ({arm.desc.root} → {arm.desc.tip}), "
            "robot_calibration's convention: m and rad"]

    def frame(joint: str, T: np.ndarray) -> None:
        rows.extend(f"{joint}_{k}: {_num(v)}" for k, v in zip("xyz", T[:3, 3]))
        rows.extend(f"{joint}_{k}: {_num(v)}" for k, v in zip("abc", Rotation.from_matrix(T[:3, :3]).as_rotvec()))

    for j in arm.desc.movable:
        if f"{j.name}.offset" in val:
            rows.append(f"{j.name}: {_num(val[f'{j.name}.offset'])}")
        T0 = np.asarray(j.origin, float)
        C = np.eye(4)
        C[:3, 3] = T0[:3, :3].T @ (np.array([val[f"{j.name}.{k}"] for k in "xyz"]) - T0[:3, 3])
        C[:3, :3] = Rotation.from_euler("XYZ", [val[f"{j.name}.r{k}"] for k in "xyz"]).as_matrix()
        frame(j.name, C)
    base, tool = arm.frames_of(np.asarray(x, float))
    frame(INSTRUMENT_JOINT, np.linalg.inv(base))
    frame(TOOL_JOINT, tool)
    return "\n".join(rows) + "\n"


def prefix_of(joint_names: list[str]) -> str:
    """The prefix before ``shoulder_pan_joint`` (UR arms with a tf_prefix)."""
    m = re.match(r"^(.*)shoulder_pan_joint$", joint_names[0]) if joint_names else None
    return m.group(1) if m else ""
