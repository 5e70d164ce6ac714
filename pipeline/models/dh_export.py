"""Seed 000's D-H + Hayati arm written out for other tools: a URDF and a D-H table (CSV).

Joint i of the URDF has origin ``C_{i−1} · Rz(theta_offset_i)`` and axis z, with C₀ the base
transform (jig frame → base) and C_i = Tx(a_i)·Tz(d_i)·Rx(alpha_i)·Ry(beta_i); the tool is a
fixed joint ``C_n · tool``.  Forward kinematics of the URDF from link ``jig`` to ``tool``
equals `serial_arm.forward` (test).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from pipeline.models import serial_arm
from pipeline.models.transforms import hrot, trans
from pipeline.models.urdf import rpy_of


def _origin(el: ET.Element, T: np.ndarray) -> None:
    ET.SubElement(el, "origin", {"xyz": " ".join(repr(float(v)) for v in T[:3, 3]),
                                 "rpy": " ".join(repr(float(v)) for v in rpy_of(T[:3, :3]))})


def to_urdf(arm: serial_arm.SerialArm) -> str:
    b, t = arm.base, arm.tool
    C = trans(b["x"], b["y"], b["z"]) @ hrot("z", b["rz"]) @ hrot("x", b["rx"]) @ hrot("y", b["ry"])
    robot = ET.Element("robot", {"name": arm.name.replace(" ", "_")})
    ET.SubElement(robot, "link", {"name": "jig"})
    parent = "jig"
    for j in arm.joints:
        child = f"link_{j.name}"
        ET.SubElement(robot, "link", {"name": child})
        el = ET.SubElement(robot, "joint", {"name": j.name, "type": "revolute"})
        ET.SubElement(el, "parent", {"link": parent})
        ET.SubElement(el, "child", {"link": child})
        _origin(el, C @ hrot("z", j.theta_offset))
        ET.SubElement(el, "axis", {"xyz": "0 0 1"})
        ET.SubElement(el, "limit", {"lower": repr(j.lower), "upper": repr(j.upper), "effort": "0", "velocity": "0"})
        C = trans(j.a, 0, j.d) @ hrot("x", j.alpha) @ hrot("y", j.beta)
        parent = child
    ET.SubElement(robot, "link", {"name": "tool"})
    el = ET.SubElement(robot, "joint", {"name": "tool_joint", "type": "fixed"})
    ET.SubElement(el, "parent", {"link": parent})
    ET.SubElement(el, "child", {"link": "tool"})
    _origin(el, C @ trans(t["x"], t["y"], t["z"]) @ hrot("z", t["rz"]) @ hrot("y", t["ry"]) @ hrot("x", t["rx"]))
    tree = ET.ElementTree(robot)
    ET.indent(tree, space="  ")
    return ET.tostring(robot, encoding="unicode") + "\n"


def dh_table_csv(arm: serial_arm.SerialArm) -> str:
    """joint, theta_offset_rad, d_m, a_m, alpha_rad, beta_rad, lower_rad, upper_rad."""
    rows = ["joint,theta_offset_rad,d_m,a_m,alpha_rad,beta_rad,lower_rad,upper_rad"]
    rows += [",".join([j.name] + [repr(float(v)) for v in (j.theta_offset, j.d, j.a, j.alpha, j.beta, j.lower, j.upper)])
             for j in arm.joints]
    return "\n".join(rows) + "\n"
