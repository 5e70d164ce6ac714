"""Gravity compliance of a URDF robot (issue 18): a joint of finite stiffness deflects under the gravity
torque of the links it carries (`<inertial>` masses of the URDF).  The campaign's deflections come from
an independent generator here: its own forward kinematics of the URDF text (4×4 products) and the
gravity torques as −∂V/∂q of the potential energy V = Σ m·G·z_com by central differences (the
diagnosis sums cross products instead: `pipeline.diagnose.urdf_gravity`)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from r6_robot import INERTIAL, URDF
from test_urdf_diagnose import point_campaign

from pipeline.diagnose.diagnose import Settings, diagnose
from pipeline.diagnose.urdf_gravity import gravity_torques
from pipeline.diagnose.urdf_robot import adapter
from pipeline.models import urdf, urdf_arm
from pipeline.plan.urdf_robot import configurations

G = 9.80665
# ----- the independent generator: own FK of the URDF text, torques from the potential energy -----
def _rpy(r, p, y):
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], [-sp, cp * sr, cp * cr]])


def _potential(q: np.ndarray) -> np.ndarray:
    """V(q) = Σ m·G·z of every link's centre of mass (n,), J, from the URDF text alone."""
    root = ET.fromstring(URDF)
    V = np.zeros(q.shape[0])
    for i in range(q.shape[0]):
        T, k = np.eye(4), 0
        for j in root.findall("joint"):
            o = j.find("origin")
            A = np.eye(4)
            A[:3, :3] = _rpy(*[float(v) for v in o.get("rpy", "0 0 0").split()])
            A[:3, 3] = [float(v) for v in o.get("xyz").split()]
            ax = np.array([float(v) for v in j.find("axis").get("xyz").split()])
            th = q[i, k]
            K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
            R = np.eye(4)
            R[:3, :3] = np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K
            T = T @ A @ R
            k += 1
            m, c = INERTIAL[j.find("child").get("link")]
            V[i] += m * G * (T @ np.r_[[float(v) for v in c.split()], 1.0])[2]
    return V


def torques(q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """−∂V/∂q (n, 6) N·m by central differences."""
    return np.stack([-(_potential(q + h * e) - _potential(q - h * e)) / (2 * h) for e in np.eye(q.shape[1])], axis=1)


def campaign(compliance: dict[int, float], seed: int, n: int = 120, noise: float = 2e-5):
    c = np.zeros(6)
    for j, v in compliance.items():
        c[j] = v

    def deflected(q: np.ndarray) -> np.ndarray:
        q_true = q.copy()
        for _ in range(3):  # the deflection moves the links it is computed from: a fixed point
            q_true = q + torques(q_true) * c
        return q_true

    return point_campaign(deflected, seed, n, noise, text=URDF)


def test_gravity_torques_agree_with_the_potential_energy():
    desc = urdf.parse(URDF, "b", "l6")
    q = configurations(urdf_arm.UrdfArm(desc), 6, 4)
    assert np.allclose(gravity_torques(desc, q), torques(q), atol=1e-5)
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
