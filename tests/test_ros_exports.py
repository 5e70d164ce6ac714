"""Outputs ROS stacks load as they are: model.urdf with the instrument and tool frames as named joints,
calibrated_parameters.yaml applied by robot_calibration's own rule (`robot_calibration_rule`, a
re-implementation of its ``updateURDF`` written from its source) and the UR controller's calibration
file with its hash formed as the UR client library forms it, each read back independently (yaml +
ElementTree + yourdfpy; the hash against g++'s ``std::hash``) and checked against robocal's calibrated
kinematics.  Uses the real UR10e description (../shared/real-data/figaroh_ur10_pose; skips where
absent) and the UR10e campaign calibrated by `robocal calibrate`."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import run_cli

import robot_calibration_rule as rc

UR10 = Path(__file__).resolve().parents[1].parent / "shared" / "real-data" / "figaroh_ur10_pose"
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


ROBOCAL_JOINTS = [("robocal_instrument_joint", "base_link", "robocal_instrument"),
                  ("robocal_tool_joint", "tool0", "robocal_tool")]


def _by_the_rule(offsets_text: str, q: np.ndarray, frm: str = "robocal_instrument", to: str = "robocal_tool"):
    """The nominal UR10e URDF (its robocal joints at identity) updated by robot_calibration's rule, and
    its `frm` → `to` poses at readings q (each joint read plus its calibration rising)."""
    nominal = rc.with_identity_joints((UR10 / "ur10_robot.urdf").read_text(), ROBOCAL_JOINTS)
    updated = rc.update_urdf(nominal, rc.load_offsets(offsets_text))
    return updated, _fk(updated, [list(rc.kinematics_config(updated, dict(zip(UR_MAP.values(), qi))).values())
                                  for qi in q], frm, to)


@needs_ur10
@settings(max_examples=4, deadline=None)
@given(st.integers(0, 10_000))
def test_calibrated_parameters_applied_by_robot_calibrations_rule(seed):
    """updateURDF's rule (frame offsets right-multiplied onto the origins, joint offsets as
    <calibration rising>) on the nominal URDF gives robocal's calibrated instrument → tool pose, and
    model.urdf's, to 1 µm / 1 µrad (the rule writes 8 decimals)."""
    arm = _arm()
    x = _perturbed(arm, seed)
    files = arm.ros_files(x)
    c = rc.load_offsets(files["calibrated_parameters.yaml"])
    assert {f"{j.name}_{k}" for j in arm.desc.movable for k in rc.FRAME_KEYS} <= set(c)
    assert {f"{n}_{k}" for n, _, _ in ROBOCAL_JOINTS for k in rc.FRAME_KEYS} <= set(c)
    q = np.random.default_rng(seed).uniform(-np.pi, np.pi, (5, 6))
    updated, got = _by_the_rule(files["calibrated_parameters.yaml"], q)
    assert all(ET.fromstring(updated).find(f"joint[@name='{j}']/calibration") is not None for j in UR_MAP.values())
    want_R, want_p = arm.forward(x, q)
    np.testing.assert_allclose(got[:, :3, 3], want_p, atol=1e-6)
    np.testing.assert_allclose(got[:, :3, :3], want_R, atol=1e-6)
    np.testing.assert_allclose(got, _fk(files["model.urdf"], q, "robocal_instrument", "robocal_tool"), atol=1e-6)


def test_ur_hash_is_std_hash_of_the_streamed_values(tmp_path):
    """The hash is ``"calib_" + std::to_string(std::hash<std::string>{}(ss.str()))`` of the values
    streamed with ``ss << value`` (the UR client library's KinematicsInfo::toHash): compiled with g++
    and run on the same values (skips without g++)."""
    import shutil
    import subprocess

    from pipeline.models.ros_exports import ur_hash

    gxx = shutil.which("g++")
    if gxx is None:
        pytest.skip("g++ not here")
    values = [0.1807, -0.6127, -0.57155, 0.17415, 0.11985, 0.11655, 1.5707963267948966, -2.4147806894359e-07,
              439.140974079901, 0.0, -0.0, 1e-12, 123456.789, -3.0]
    src = tmp_path / "h.cpp"
    src.write_text("#include <iostream>\n#include <sstream>\n#include <string>\nint main(){double v;std::stringstream ss;"
                   "while(std::cin>>v) ss<<v;std::cout<<\"calib_\"<<std::to_string(std::hash<std::string>{}(ss.str()));}\n")
    subprocess.run([gxx, "-O0", "-o", str(tmp_path / "h"), str(src)], check=True)
    for vals in (values, values[:1], values[:5], []):
        out = subprocess.run([str(tmp_path / "h")], input=" ".join(repr(v) for v in vals), capture_output=True,
                             text=True, check=True).stdout
        assert ur_hash(vals) == out, vals


@pytest.fixture(scope="module")
def ur10_calibrated(tmp_path_factory) -> Path:
    """The real UR10e campaign through the CLI: `robocal import csv` then `robocal calibrate`."""
    import sys

    if not UR10.is_dir():
        pytest.skip(f"real data not here: {UR10}")
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_real_data import import_args

    d = tmp_path_factory.mktemp("ur10")
    rec = d / "ur10.mcap"
    p = run_cli("import", "csv", *import_args("ur10", rec))
    assert p.returncode == 0, p.stderr
    p = run_cli("calibrate", rec, "--out", d / "cal")
    assert p.returncode == 0, p.stderr
    return d / "cal"


def test_real_ur10e_calibrated_parameters_by_robot_calibrations_rule(ur10_calibrated):
    """The real UR10e's calibrated_parameters.yaml, applied to the nominal URDF by robot_calibration's
    rule, gives model.urdf's instrument → tool and base_link → tool0 poses to ≤ 1 µm."""
    text = (ur10_calibrated / "calibrated_parameters.yaml").read_text()
    model = (ur10_calibrated / "model.urdf").read_text()
    joints = {j.get("name") for j in ET.fromstring(model).findall("joint")}
    for name in rc.load_offsets(text):  # every name a joint of model.urdf, or a joint's frame offset
        assert name in joints or (name.rsplit("_", 1)[0] in joints and name[-1] in "xyzabc"), name
    q = np.random.default_rng(3).uniform(-np.pi, np.pi, (8, 6))
    _, got = _by_the_rule(text, q)
    want = _fk(model, q, "robocal_instrument", "robocal_tool")
    assert np.max(np.linalg.norm(got[:, :3, 3] - want[:, :3, 3], axis=1)) <= 1e-6
    np.testing.assert_allclose(got[:, :3, :3], want[:, :3, :3], atol=1e-6)
    _, chain = _by_the_rule(text, q, "base_link", "tool0")
    assert np.max(np.linalg.norm(chain[:, :3, 3] - _fk(model, q, "base_link", "tool0")[:, :3, 3], axis=1)) <= 1e-6


def test_real_ur10e_calibration_exports_load_in_the_stack(ur10_calibrated):
    """`robocal calibrate` on the real UR10e campaign: model.urdf names the instrument and tool
    frames as joints; ur_calibration.yaml put into the original URDF reproduces model.urdf's chain;
    its hash is in the driver's form calib_<uint64>."""
    model = (ur10_calibrated / "model.urdf").read_text()
    joints = {j.get("name"): j for j in ET.fromstring(model).findall("joint")}
    assert joints["robocal_instrument_joint"].find("child").get("link") == "robocal_instrument"
    assert joints["robocal_tool_joint"].find("parent").get("link") == "tool0"
    kin = yaml.safe_load((ur10_calibrated / "ur_calibration.yaml").read_text())["kinematics"]
    h = str(kin["hash"])
    assert h.startswith("calib_") and h[6:].isdigit() and int(h[6:]) < 2 ** 64
    robot = ET.fromstring((UR10 / "ur10_robot.urdf").read_text().encode())
    joints = {j.get("name"): j for j in robot.findall("joint")}
    for key, joint in UR_MAP.items():
        e = kin[key]
        _set_origin(joints[joint], (e["x"], e["y"], e["z"]), (e["roll"], e["pitch"], e["yaw"]))
    q = np.random.default_rng(2).uniform(-np.pi, np.pi, (8, 6))
    np.testing.assert_allclose(_fk(ET.tostring(robot, encoding="unicode"), q, "base_link", "tool0"),
                               _fk(model, q, "base_link", "tool0"), atol=1e-9)


def test_not_a_ur_arm_gets_no_ur_file():
    from pipeline.models.ros_exports import ur_calibration_yaml, ur_joint_names

    assert ur_joint_names(["a", "b", "c", "d", "e", "f"]) is None
    assert ur_calibration_yaml(["j1"], {}) is None
    assert ur_joint_names([f"left_{j}" for j in UR_MAP.values()])["wrist_3"] == "left_wrist_3_joint"
