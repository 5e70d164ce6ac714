"""Noise-free campaigns of three URDF robots of different structure (6R with tilted axes, a
prismatic torso + 6R, a SCARA RRPR), each with each measurement type: the calibrated model agrees
with the truth within 1 µm at NEW configurations (up to the gauge the measurement type leaves free:
a rigid motion of the whole cell for point coincidence).  Plus forward kinematics against
yourdfpy's own to 1e-9 m and the parameter / angular Jacobians against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.identify.least_squares import FitOptions, fit
from pipeline.measurements.coincidence import CoincidenceModel
from pipeline.measurements.plane import Plane, PlaneModel
from pipeline.measurements.point import PointModel
from pipeline.measurements.pose import PoseModel
from pipeline.models import chain as ch
from pipeline.models import urdf, urdf_arm
from pipeline.plan.urdf_robot import configurations
from pipeline.simulate.urdf_robot import campaign, random_truth
from test_urdf_plan import URDF as R6

PR6 = """<robot name="torso_arm">
  <link name="base"/><link name="torso"/><link name="a1"/><link name="a2"/><link name="a3"/><link name="a4"/>
  <link name="a5"/><link name="a6"/><link name="flange"/>
  <joint name="torso_lift" type="prismatic"><parent link="base"/><child link="torso"/><origin xyz="0 0 0.6"/>
    <axis xyz="0 0 1"/><limit lower="0" upper="0.35" effort="1" velocity="1"/></joint>
  <joint name="arm_1" type="revolute"><parent link="torso"/><child link="a1"/><origin xyz="0.15 0.02 -0.15" rpy="0 0 -1.5708"/>
    <axis xyz="0 0 1"/><limit lower="0" upper="2.7" effort="1" velocity="1"/></joint>
  <joint name="arm_2" type="revolute"><parent link="a1"/><child link="a2"/><origin xyz="0.125 0.018 -0.031" rpy="1.5708 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-1.5" upper="1.0" effort="1" velocity="1"/></joint>
  <joint name="arm_3" type="revolute"><parent link="a2"/><child link="a3"/><origin xyz="0.089 0 0" rpy="-1.5708 0 1.5708"/>
    <axis xyz="0 0 1"/><limit lower="-3.4" upper="1.5" effort="1" velocity="1"/></joint>
  <joint name="arm_4" type="revolute"><parent link="a3"/><child link="a4"/><origin xyz="-0.02 -0.027 -0.222" rpy="-1.5708 -1.5708 0"/>
    <axis xyz="0 0 1"/><limit lower="-0.3" upper="2.3" effort="1" velocity="1"/></joint>
  <joint name="arm_5" type="revolute"><parent link="a4"/><child link="a5"/><origin xyz="-0.162 0.02 0.027" rpy="0 -1.5708 0"/>
    <axis xyz="0 0 1"/><limit lower="-2.0" upper="2.0" effort="1" velocity="1"/></joint>
  <joint name="arm_6" type="revolute"><parent link="a5"/><child link="a6"/><origin xyz="0 0 0.15" rpy="0 -1.5708 -1.5708"/>
    <axis xyz="0 0 1"/><limit lower="-1.4" upper="1.4" effort="1" velocity="1"/></joint>
  <joint name="flange_fixed" type="fixed"><parent link="a6"/><child link="flange"/><origin xyz="0 0 0.05" rpy="0 0 0.3"/></joint>
</robot>
"""

SCARA = """<robot name="scara">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/>
  <joint name="s1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.4"/><axis xyz="0 0 1"/>
    <limit lower="-2.5" upper="2.5" effort="1" velocity="1"/></joint>
  <joint name="s2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.35 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2.5" upper="2.5" effort="1" velocity="1"/></joint>
  <joint name="s3" type="prismatic"><parent link="l2"/><child link="l3"/><origin xyz="0.3 0 0"/><axis xyz="0 0 -1"/>
    <limit lower="0" upper="0.2" effort="1" velocity="1"/></joint>
  <joint name="s4" type="continuous"><parent link="l3"/><child link="l4"/><origin xyz="0 0 -0.05"/><axis xyz="0 0 1"/></joint>
  <link name="tcp"/>
  <joint name="tcp_fixed" type="fixed"><parent link="l4"/><child link="tcp"/><origin xyz="0.06 0.01 -0.03"/></joint>
</robot>
"""

R6T = R6.replace("</robot>", """  <link name="tcp"/>
  <joint name="tcp_fixed" type="fixed"><parent link="l6"/><child link="tcp"/><origin xyz="0.04 0.02 0.12"/></joint>
</robot>""")
ROBOTS = {"6R": (R6T, "b", "tcp"), "P+6R": (PR6, "base", "flange"), "SCARA": (SCARA, "base", "tcp")}


def arm_of(name: str) -> urdf_arm.UrdfArm:
    text, root, tip = ROBOTS[name]
    return urdf_arm.UrdfArm(urdf.parse(text, root, tip))


def rigid_residual(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance between point sets a and b after the best rigid motion of a onto b."""
    from scipy.spatial.transform import Rotation

    rot, _ = Rotation.align_vectors(b - b.mean(0), a - a.mean(0))
    return float(np.max(np.linalg.norm(rot.apply(a - a.mean(0)) + b.mean(0) - b, axis=1)))


@pytest.mark.parametrize("robot", sorted(ROBOTS))
@pytest.mark.parametrize("measure", ["point", "pose", "plane", "plane-unknown", "coincidence"])
def test_noise_free_campaign_recovers_the_truth_at_new_configurations(robot, measure):
    arm = arm_of(robot)
    rng = np.random.default_rng(11)
    if measure in ("point", "pose"):
        model = PointModel(arm) if measure == "point" else PoseModel(arm)
        truth = random_truth(model, rng, 2e-3, 5e-3)
        table, _ = campaign(model, truth, 80, 1, measure)
    elif measure.startswith("plane"):
        probe = PlaneModel(arm)
        truth_k = random_truth(probe, rng, 2e-3, 5e-3, registration=False)
        table, tr = campaign(probe, truth_k, 150, 1, "plane")
        known = measure == "plane"
        planes = tuple(Plane(p["name"], tuple(p["normal"]), p["offset"], known) for p in tr.planes)
        model = PlaneModel(arm, planes=planes)
        names = [p.name for p in planes]
        table = {"joint_positions": table["joint_positions"],
                 "plane": np.array([names.index(s) for s in table["plane"]])}
        truth = np.concatenate([truth_k, [v for p in planes if not known for v in (0, 0, p.offset)]])
    else:
        probe = CoincidenceModel(arm, groups_=tuple(f"socket{i}" for i in range(4)))
        truth = random_truth(probe, rng, 2e-3, 5e-3, registration=False)
        table, tr = campaign(probe, truth, 120, 1, "coincidence", n_groups=4)
        model = probe
        table = {"joint_positions": table["joint_positions"],
                 "group": np.array([int(s[-1]) for s in table["group"]])}
    assert len(table["joint_positions"]) >= 40  # the campaign reached its planes / sockets
    held = () if measure in ("point", "pose") else tuple(n for n in model.parameter_names() if n.startswith("tool."))
    f = fit(model, table, FitOptions(fixed=held))  # plane, coincidence: the tool is known (a free one collapses)
    assert np.sqrt(np.mean(f.residuals_after**2)) < 1e-9
    qn = configurations(arm, 200, 99)
    p_fit, *_ = model.tool(f.x, qn)
    p_true, *_ = model.tool(truth, qn)
    if measure == "coincidence":
        err = rigid_residual(p_fit, p_true)  # the cell's placement is not measured
    elif measure == "plane-unknown":
        err = rigid_residual(p_fit, p_true)  # unknown planes leave the frame free
    else:
        err = float(np.max(np.linalg.norm(p_fit - p_true, axis=1)))
    assert err < 1e-6, (robot, measure, err)


@pytest.mark.parametrize("robot", sorted(ROBOTS))
def test_forward_kinematics_matches_yourdfpy(robot):
    from pipeline.models.urdf import load_urdf_model

    text, root, tip = ROBOTS[robot]
    arm = arm_of(robot)
    q = configurations(arm, 20, 3)
    R, p = arm.forward(arm.vector(), q)
    u = load_urdf_model(text)
    for i in range(len(q)):
        u.update_cfg(dict(zip(arm.joint_names, q[i])))
        T = u.get_transform(tip, root)
        np.testing.assert_allclose(T[:3, 3], p[i], atol=1e-9)
        np.testing.assert_allclose(T[:3, :3], R[i], atol=1e-9)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), robot=st.sampled_from(sorted(ROBOTS)))
def test_parameter_and_angular_jacobians_match_finite_differences(seed, robot):
    arm = arm_of(robot)
    rng = np.random.default_rng(seed)
    x = arm.vector() + rng.normal(0, 0.05, arm.vector().size)
    q = configurations(arm, 4, seed)
    c = arm.chain()
    p, Jp, R, Jw = ch.jacobian(c, x, q, angular=True)
    h = 1e-7
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        Rp, pp = ch.forward(c, x + e, q)
        Rm, pm = ch.forward(c, x - e, q)
        np.testing.assert_allclose((pp - pm) / (2 * h), Jp[:, :, i], atol=1e-7)
        dR = (Rp - Rm) / (2 * h) @ np.swapaxes(R, 1, 2)  # [δω]×
        w = np.stack([dR[:, 2, 1], dR[:, 0, 2], dR[:, 1, 0]], axis=1)
        np.testing.assert_allclose(w, Jw[:, :, i], atol=1e-7)


def test_simulate_urdf_cli_calibrates_to_the_noise_floor(tmp_path):
    """`robocal simulate urdf` → `robocal calibrate`: residuals at the stated 0.02 mm noise (per axis), by the
    default model choice a recording of this single-chain robot takes whatever its origin (shrinkage)."""
    import json

    from conftest import run_cli

    u = tmp_path / "r.urdf"
    u.write_text(PR6)
    rec = tmp_path / "sim.mcap"
    proc = run_cli("simulate", "urdf", "--urdf", u, "--root", "base", "--tip", "flange", "--measure", "point",
                   "--poses", "60", "--noise-mm", "0.02", "--out", rec, "--truth", tmp_path / "truth.json")
    assert proc.returncode == 0, proc.stderr
    assert "base.x" in json.loads((tmp_path / "truth.json").read_text())["parameters"]
    proc = run_cli("calibrate", rec, "--out", tmp_path / "cal")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "cal" / "results.json").read_text())
    assert doc["model_choice"]["route"] == "shrinkage", doc["model_choice"]  # the data decide, not "simulated"
    assert doc["rms_before_m"] > 5 * 2e-5  # the errors are visible before calibration
    assert 0.7 * 2e-5 < doc["holdout_rms_m"] < 1.5 * 2e-5
