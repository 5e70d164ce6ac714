"""The calibrated URDF chain in the files ROS stacks load as they are (beside model.urdf).

- `ur_calibration_yaml`: for a Universal Robots arm (its six joints ``shoulder_pan_joint`` …
  ``wrist_3_joint``, any prefix), the controller calibration file ur_robot_driver / ur_description
  take as ``kinematics_params_file`` (the format ur_calibration writes):
  ``kinematics: {shoulder: {x, y, z, roll, pitch, yaw}, upper_arm, forearm, wrist_1, wrist_2,
  wrist_3, hash}`` — each entry the origin of one joint (parent link → joint frame; m, URDF rpy
  rad), shoulder ↔ shoulder_pan_joint, upper_arm ↔ shoulder_lift_joint, forearm ↔ elbow_joint,
  wrist_k ↔ wrist_k_joint.  A joint offset is folded into its origin's rotation (the joint axis is
  z: Rot(z, q + θ₀) = Rot(z, θ₀)·Rot(z, q)).  ``hash`` names this calibration
  (``calib_robocal_<16 hex of the values>``); the driver compares it with the controller's own
  checksum and warns when they differ, which they do: this is not the factory calibration.
- `offsets_yaml`: the identified corrections in robot_calibration's style, one flat mapping:
  ``<joint>: offset`` (rad, added to the reading) and, per frame (each joint origin,
  ``robocal_instrument``: the instrument → root link registration, ``robocal_tool``: tip → tool),
  ``<frame>_x/_y/_z`` (m, origin translation correction) and ``<frame>_a/_b/_c`` (rad, rotation
  correction as a rotation vector, applied after the nominal rotation).
- `load_ur_calibration` reads a UR file back; `apply_ur_calibration` puts it into a URDF text.
"""

from __future__ import annotations

import hashlib
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
    digest = hashlib.sha256(np.asarray(values, float).tobytes()).hexdigest()[:16]
    rows.append(f"  hash: calib_robocal_{digest}")
    return "\n".join(rows) + "\n"


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


def offsets_yaml(arm, x: np.ndarray) -> str:
    """robot_calibration-style corrections of a `UrdfArm` at parameters x (see module docstring)."""
    from scipy.spatial.transform import Rotation

    names = arm.parameter_names()
    nominal = arm.nominal_vector()
    val = {n: float(v) for n, v in zip(names, np.asarray(x, float))}
    rows = [f"# robocal calibrated parameters of {arm.desc.name} ({arm.desc.root} → {arm.desc.tip}); "
            "m and rad; corrections to the URDF"]

    def frame(label: str, head: str, rot: tuple[str, str, str]) -> None:
        d = [val[f"{head}.{k}"] - float(nominal[names.index(f"{head}.{k}")]) for k in "xyz"]
        rv = Rotation.from_euler("XYZ" if rot[0] == "rx" else "ZYX",
                                 [val[f"{head}.{k}"] for k in (rot if rot[0] == "rx" else rot[::-1])]).as_rotvec()
        rows.extend(f"{label}_{k}: {_num(v)}" for k, v in zip("xyz", d))
        rows.extend(f"{label}_{k}: {_num(v)}" for k, v in zip("abc", rv))

    for j in arm.desc.movable:
        if f"{j.name}.offset" in val:
            rows.append(f"{j.name}: {_num(val[f'{j.name}.offset'])}")
        frame(j.name, j.name, ("rx", "ry", "rz"))
    frame("robocal_instrument", "base", ("roll", "pitch", "yaw"))
    frame("robocal_tool", "tool", ("roll", "pitch", "yaw"))
    return "\n".join(rows) + "\n"


def prefix_of(joint_names: list[str]) -> str:
    """The prefix before ``shoulder_pan_joint`` (UR arms with a tf_prefix)."""
    m = re.match(r"^(.*)shoulder_pan_joint$", joint_names[0]) if joint_names else None
    return m.group(1) if m else ""
