"""robot_calibration's rule for applying a calibrated_parameters.yaml to a URDF, re-implemented for
the tests from its source (``robot_calibration/src/optimization/offsets.cpp``: ``loadOffsetYAML``,
``updateURDF``; ``rotation_from_axis_magnitude`` of its chain model; KDL's ``Rotation::RPY``,
``GetRPY`` and ``Quaternion``), sharing no code with robocal's writer.

- the offsets file is read line by line as ``str >> param >> value``: a first word ending in ``:``
  and a number after it, anything else skipped;
- for each ``<joint>`` of the URDF: a non-zero ``<joint>`` value is added to the joint's
  ``<calibration rising=…>`` (created when absent); a frame offset ``<joint>_x/_y/_z/_a/_b/_c``
  (missing ones 0) is right-multiplied onto its ``<origin>``, ``origin = origin · offset``, the
  rotation from the axis-magnitude vector (a, b, c), written back with 8 decimals (``std::fixed``,
  ``setprecision(8)``) as xyz and KDL's ``GetRPY``;
- `kinematics_config`: the joint readings a model of the updated URDF uses: the reading plus the
  joint's ``<calibration rising>`` (robot_calibration's chain model: ``position + offsets.get(name)``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np

FRAME_KEYS = ("x", "y", "z", "a", "b", "c")


def load_offsets(text: str) -> dict[str, float]:
    """``loadOffsetYAML``: name → value of the lines ``name: value``."""
    out = {}
    for line in text.splitlines():
        words = line.split()
        if len(words) < 2:
            continue
        try:
            value = float(words[1])
        except ValueError:
            continue
        out[words[0][:-1]] = value
    return out


def kdl_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    ca, sa, cb, sb, cc, sc = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
    return np.array([[ca * cb, ca * sb * sc - sa * cc, ca * sb * cc + sa * sc],
                     [sa * cb, sa * sb * sc + ca * cc, sa * sb * cc - ca * sc],
                     [-sb, cb * sc, cb * cc]])


def kdl_get_rpy(R: np.ndarray) -> tuple[float, float, float]:
    d = R.reshape(-1)
    pitch = math.atan2(-d[6], math.sqrt(d[0] ** 2 + d[3] ** 2))
    if abs(pitch) > math.pi / 2 - 1e-12:
        return 0.0, pitch, math.atan2(-d[1], d[4])
    return math.atan2(d[7], d[8]), pitch, math.atan2(d[3], d[0])


def kdl_quaternion(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def rotation_from_axis_magnitude(x: float, y: float, z: float) -> np.ndarray:
    m = math.sqrt(x * x + y * y + z * z)
    if m == 0.0:
        return kdl_quaternion(0.0, 0.0, 0.0, 1.0)
    s = math.sin(m / 2)
    return kdl_quaternion(x / m * s, y / m * s, z / m * s, math.cos(m / 2))


def _fixed8(v) -> str:
    return " ".join(f"{float(a):.8f}" for a in v)


def update_urdf(urdf: str, offsets: dict[str, float]) -> str:
    """``updateURDF``: the URDF text with the offsets applied (module docstring)."""
    robot = ET.fromstring(urdf.encode())
    for joint in robot.findall("joint"):
        name = joint.get("name")
        offset = offsets.get(name, 0.0)
        if offset != 0.0:
            cal = joint.find("calibration")
            if cal is None:
                ET.SubElement(joint, "calibration", {"rising": "%g" % offset})
            elif cal.get("rising") is not None:
                cal.set("rising", "%g" % (offset + float(cal.get("rising"))))
        if not any(f"{name}_{k}" in offsets for k in FRAME_KEYS):
            continue
        c = [offsets.get(f"{name}_{k}", 0.0) for k in FRAME_KEYS]
        F = np.eye(4)
        F[:3, 3] = c[:3]
        F[:3, :3] = rotation_from_axis_magnitude(*c[3:])
        o = joint.find("origin")
        if o is None:
            O = F
            o = ET.SubElement(joint, "origin")
        else:
            O = np.eye(4)
            xyz, rpy = (o.get("xyz") or "").split(), (o.get("rpy") or "").split()
            if len(xyz) == 3:
                O[:3, 3] = [float(v) for v in xyz]
            if len(rpy) == 3:
                O[:3, :3] = kdl_rpy(*[float(v) for v in rpy])
            O = O @ F
        o.set("xyz", _fixed8(O[:3, 3]))
        o.set("rpy", _fixed8(kdl_get_rpy(O[:3, :3])))
    return ET.tostring(robot, encoding="unicode")


def kinematics_config(urdf: str, q: dict[str, float]) -> dict[str, float]:
    """The joint values a robot model of `urdf` uses at readings `q`: each plus its calibration rising."""
    rising = {j.get("name"): float(j.find("calibration").get("rising")) for j in ET.fromstring(urdf.encode()).findall("joint")
              if j.find("calibration") is not None and j.find("calibration").get("rising") is not None}
    return {n: v + rising.get(n, 0.0) for n, v in q.items()}


def with_identity_joints(urdf: str, joints: list[tuple[str, str, str]]) -> str:
    """`urdf` with fixed joints (name, parent link, child link) at identity origins added: the URDF the
    robocal joints' offsets apply to (their nominal origin is the identity)."""
    robot = ET.fromstring(urdf.encode())
    for name, parent, child in joints:
        ET.SubElement(robot, "link", {"name": child})
        j = ET.SubElement(robot, "joint", {"name": name, "type": "fixed"})
        ET.SubElement(j, "parent", {"link": parent})
        ET.SubElement(j, "child", {"link": child})
        ET.SubElement(j, "origin", {"xyz": "0 0 0", "rpy": "0 0 0"})
    return ET.tostring(robot, encoding="unicode")
