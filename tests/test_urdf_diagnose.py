"""Diagnosis of a URDF robot (generic adapter): a joint's scale error injected into the true robot
(joint reads q, turns (1 + s)·q) is found and named; a clean campaign gives no finding.  The
campaign is made here from the kinematics (not from the diagnosis's signature functions)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.diagnose.diagnose import Settings, diagnose
from pipeline.diagnose.urdf_robot import adapter
from pipeline.measurements.point import PointModel
from pipeline.models import urdf, urdf_arm
from pipeline.plan.urdf_robot import configurations
from test_urdf_plan import URDF


def campaign(scale: float, seed: int, n: int = 120, noise: float = 2e-5):
    arm = urdf_arm.UrdfArm(urdf.parse(URDF, "b", "l6"))
    model = PointModel(arm)
    rng = np.random.default_rng(seed)
    truth = model.nominal() + rng.normal(0, 5e-4, len(model.nominal()))
    truth[model.parameter_names().index("tool.z")] = 0.05
    q = configurations(arm, n, seed + 1)
    q_true = q.copy()
    q_true[:, 1] *= 1 + scale  # joint j2 turns more than it reads
    p, *_ = model.tool(truth, q_true)
    table = {"joint_positions": q, "position": p + rng.normal(0, noise, p.shape), "target": np.zeros(n, int),
             "record": np.arange(n), "timestamp_ns": np.arange(n) * 1_000_000_000,
             "time_since_start_s": np.arange(n, dtype=float)}
    return model, table


@pytest.mark.parametrize("seed", [0, 1])
def test_joint_scale_is_found_and_clean_is_clean(seed):
    model, table = campaign(3e-3, seed)
    doc = diagnose(model, table, settings=Settings(n_boot=10, sign_flips=0), adapter=adapter(model, table, held=()))
    labels = [f"{f['effect']}@{f['location']}" for f in doc["findings"]]
    assert "joint_scale@j2" in labels, doc["findings"]
    model, table = campaign(0.0, seed + 10)
    doc = diagnose(model, table, settings=Settings(n_boot=10, sign_flips=0), adapter=adapter(model, table, held=()))
    assert doc["findings"] == [], doc["findings"]
