"""Outputs ROS stacks load as they are: model.urdf with the instrument and tool frames as links, the
robot_calibration-style calibrated_parameters.yaml and the UR controller's calibration file, each
read back independently (yaml + ElementTree + yourdfpy) and checked against robocal's calibrated
kinematics to 1e-9 m.  Uses the real UR10e description (/work/shared/real-data/figaroh_ur10_pose;
skips where absent) and the UR10e campaign calibrated by `robocal calibrate`."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from conftest import run_cli

UR10 = Path("/work/shared/real-data/figaroh_ur10_pose")
needs_ur10 = pytest.mark.skipif(not UR10.is_dir(), reason=f"real data not here: {UR10}")
UR_MAP = {"shoulder": "shoulder_pan_joint", "upper_arm": "shoulder_lift_joint", "forearm": "elbow_joint",
          "wrist_1": "wrist_1_joint", "wrist_2": "wrist_2_joint", "wrist_3": "wrist_3_joint"}


def _arm():
    from pipeline.models import urdf
    from pipeline.models.urdf_arm import UrdfArm

    return UrdfArm(urdf.read(UR10 / "ur10_robot.urdf", "base_link", "tool0"))


def _perturbed(arm, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = arm.nominal_vector().copy()
    units = arm.parameter_units()
    for i, u in enumerate(units):
        x[i] += rng.normal(0, 2e-3) if u == "m" else rng.normal(0, 5e-3)
    return x


def _set_origin(j: ET.Element, xyz, rpy) -> None:
    o = j.find("origin")
    if o is None:
        o = ET.SubElement(j, "origin")
    o.set("xyz", " ".join(repr(float(v)) for v in xyz))
    o.set("rpy", " ".join(repr(float(v)) for v in rpy))


def _urdf_rpy(R: np.ndarray) -> list[float]:
    return list(Rotation.from_matrix(R).as_euler("ZYX"))[::-1]


def _fk(text: str, q: np.ndarray, frm: str, to: str) -> np.ndarray:
    import yourdfpy
    import io

    u = yourdfpy.URDF.load(io.BytesIO(text.encode()), load_meshes=False, build_collision_scene_graph=False,
                           load_collision_meshes=False)
    out = []
    for qi in q:
        u.update_cfg(dict(zip(list(UR_MAP.values()), qi)))
        out.append(u.get_transform(to, frm))
    return np.array(out)


def _robocal_chain(arm, x, q) -> np.ndarray:
    """robocal's root link → tip link poses (the registration and tool left out)."""
    names, F = arm.link_frames(x, q)
    return np.linalg.inv(F[:, 0]) @ F[:, -2]


@needs_ur10
@settings(max_examples=5, deadline=None)
@given(st.integers(0, 10_000))
def test_ur_calibration_file_round_trip(seed):
    """Write the UR file, read it with yaml, put it into the original URDF as ur_description does:
    yourdfpy's base_link → tool0 equals robocal's calibrated chain (joint offsets included)."""
    arm = _arm()
    x = _perturbed(arm, seed)
    files = arm.ros_files(x)
    doc = yaml.safe_load(files["ur_calibration.yaml"])
    kin = doc["kinematics"]
    assert set(kin) == set(UR_MAP) | {"hash"} and str(kin["hash"]).startswith("calib_")
    robot = ET.fromstring((UR10 / "ur10_robot.urdf").read_text().encode())
    joints = {j.get("name"): j for j in robot.findall("joint")}
    for key, joint in UR_MAP.items():
        e = kin[key]
        _set_origin(joints[joint], (e["x"], e["y"], e["z"]), (e["roll"], e["pitch"], e["yaw"]))
    q = np.random.default_rng(seed).uniform(-np.pi, np.pi, (6, 6))
    got = _fk(ET.tostring(robot, encoding="unicode"), q, "base_link", "tool0")
    np.testing.assert_allclose(got, _robocal_chain(arm, x, q), atol=1e-9)
    # robocal's own reader of the file gives the same origins
    from pipeline.models.ros_exports import load_ur_calibration

    back = load_ur_calibration(files["ur_calibration.yaml"])
    origins = arm.joint_origins(x)
    for key, joint in UR_MAP.items():
        np.testing.assert_allclose(back[key], origins[joint], atol=1e-12)


@needs_ur10
def test_calibrated_parameters_yaml_applied_to_the_urdf_gives_the_calibrated_robot():
    """robot_calibration's convention, applied independently: origin xyz += (_x,_y,_z), origin
    rotation ·= rotvec(_a,_b,_c), reading += offset; the registration and tool as fixed frames."""
    arm = _arm()
    x = _perturbed(arm, 7)
    c = yaml.safe_load(arm.ros_files(x)["calibrated_parameters.yaml"])
    robot = ET.fromstring((UR10 / "ur10_robot.urdf").read_text().encode())
    joints = {j.get("name"): j for j in robot.findall("joint")}
    for j in arm.desc.movable:
        o = joints[j.name].find("origin")
        xyz = np.array([float(v) for v in o.get("xyz").split()]) + [c[f"{j.name}_{k}"] for k in "xyz"]
        R0 = Rotation.from_euler("ZYX", [float(v) for v in o.get("rpy").split()][::-1])
        R = R0 * Rotation.from_rotvec([c[f"{j.name}_{k}"] for k in "abc"])
        _set_origin(joints[j.name], xyz, _urdf_rpy(R.as_matrix()))
    q = np.random.default_rng(1).uniform(-np.pi, np.pi, (5, 6))
    offsets = np.array([c[j] for j in UR_MAP.values()])
    chain = _fk(ET.tostring(robot, encoding="unicode"), q + offsets, "base_link", "tool0")
    T = lambda p: np.block([[Rotation.from_rotvec([c[f"{p}_{k}"] for k in "abc"]).as_matrix(),  # noqa: E731
                             np.array([[c[f"{p}_{k}"]] for k in "xyz"])], [np.zeros((1, 3)), np.ones((1, 1))]])
    want_R, want_p = arm.forward(x, q)
    got = T("robocal_instrument") @ chain @ T("robocal_tool")
    np.testing.assert_allclose(got[:, :3, 3], want_p, atol=1e-9)
    np.testing.assert_allclose(got[:, :3, :3], want_R, atol=1e-9)


@needs_ur10
def test_real_ur10e_calibration_exports_load_in_the_stack(tmp_path):
    """`robocal calibrate` on the real UR10e campaign: model.urdf names the instrument and tool
    frames as links; ur_calibration.yaml put into the original URDF reproduces model.urdf's chain."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_real_data import import_args

    rec = tmp_path / "ur10.mcap"
    p = run_cli("import", "csv", *import_args("ur10", rec))
    assert p.returncode == 0, p.stderr
    p = run_cli("calibrate", rec, "--out", tmp_path / "cal")
    assert p.returncode == 0, p.stderr
    model = (tmp_path / "cal" / "model.urdf").read_text()
    links = {ln.get("name") for ln in ET.fromstring(model).findall("link")}
    assert {"robocal_instrument", "robocal_tool"} <= links
    kin = yaml.safe_load((tmp_path / "cal" / "ur_calibration.yaml").read_text())["kinematics"]
    robot = ET.fromstring((UR10 / "ur10_robot.urdf").read_text().encode())
    joints = {j.get("name"): j for j in robot.findall("joint")}
    for key, joint in UR_MAP.items():
        e = kin[key]
        _set_origin(joints[joint], (e["x"], e["y"], e["z"]), (e["roll"], e["pitch"], e["yaw"]))
    q = np.random.default_rng(2).uniform(-np.pi, np.pi, (8, 6))
    np.testing.assert_allclose(_fk(ET.tostring(robot, encoding="unicode"), q, "base_link", "tool0"),
                               _fk(model, q, "base_link", "tool0"), atol=1e-9)
    assert "robocal_tool_x" in yaml.safe_load((tmp_path / "cal" / "calibrated_parameters.yaml").read_text())


def test_not_a_ur_arm_gets_no_ur_file():
    from pipeline.models.ros_exports import ur_calibration_yaml, ur_joint_names

    assert ur_joint_names(["a", "b", "c", "d", "e", "f"]) is None
    assert ur_calibration_yaml(["j1"], {}) is None
    assert ur_joint_names([f"left_{j}" for j in UR_MAP.values()])["wrist_3"] == "left_wrist_3_joint"
