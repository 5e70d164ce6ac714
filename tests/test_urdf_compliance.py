"""Gravity compliance of a URDF robot: a joint of finite stiffness deflects under the gravity
torque of the links it carries (`<inertial>` masses of the URDF).  The campaign's deflections come from
the independent generator `independent_drive`: its own forward kinematics of the URDF text (4×4 products) and the
gravity torques as −∂V/∂q of the potential energy V = Σ m·G·z_com by central differences (the
diagnosis sums cross products instead: `pipeline.diagnose.library.urdf_gravity`)."""

from __future__ import annotations

import independent_drive as gen
import numpy as np
import pytest
from r6_robot import URDF
from test_urdf_diagnose import point_campaign

from pipeline.diagnose import Settings, diagnose
from pipeline.diagnose.library.urdf_gravity import gravity_torques
from pipeline.diagnose.adapters.urdf_robot import adapter
from pipeline.models import urdf, urdf_arm
from pipeline.plan.urdf_robot import configurations


def campaign(compliance: dict[int, float], seed: int, n: int = 120, noise: float = 2e-5):
    """A point campaign whose true joints are the readings deflected under gravity (the independent
    generator `independent_drive`: `compliance` {joint index: rad/(N·m)}, no payload)."""
    c = np.zeros(6)
    for j, v in compliance.items():
        c[j] = v
    return point_campaign(lambda q: gen.deflected(q, c), seed, n, noise, text=URDF)


def test_gravity_torques_agree_with_the_potential_energy():
    desc = urdf.parse(URDF, "b", "l6")
    q = configurations(urdf_arm.UrdfArm(desc), 6, 4)
    assert np.allclose(gravity_torques(desc, q), -gen.holding_efforts(q), atol=1e-5)  # torque = −∂V/∂q
    assert np.allclose(gravity_torques(desc, q)[:, 0], 0, atol=1e-9)  # j1's axis is vertical: no gravity torque


@pytest.mark.parametrize("seed", [0, 1])
def test_joint_stiffness_is_found_named_and_estimated(seed):
    """j2 at 2e-6 rad/(N·m) (k = 5e5 N·m/rad: ~0.1 mrad under its ~60 N·m): found, named, estimated."""
    model, table = campaign({1: 2e-6}, seed)
    doc = diagnose(model, table, settings=Settings(n_boot=10, sign_flips=0), adapter=adapter(model, table, held=()))
    (f,) = [f for f in doc["findings"] if f["effect"] == "joint_compliance"]
    assert f["location"] == "j2" and len(doc["findings"]) == 1, doc["findings"]
    v, s = f["parameters"][0]["value"], f["parameters"][0]["std"]
    assert abs(v - 2e-6) < max(0.2 * 2e-6, 4 * s)
    assert doc["holdout_rms_after_m"] < doc["holdout_rms_before_m"]


def test_a_rigid_robot_with_inertials_gives_no_compliance_finding():
    model, table = campaign({}, 7)
    doc = diagnose(model, table, settings=Settings(n_boot=10, sign_flips=0), adapter=adapter(model, table, held=()))
    assert doc["findings"] == []
    assert {c["effect"] for c in doc["candidates"]} >= {"joint_compliance"}
