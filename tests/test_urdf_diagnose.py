"""Diagnosis of a URDF robot (generic adapter): a joint's scale error injected into the true robot
(joint reads q, turns (1 + s)·q) is found and named; a clean campaign gives no finding.  The
campaign is made here from the kinematics (not from the diagnosis's signature functions)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.diagnose import Settings, diagnose
from pipeline.diagnose.adapters.urdf_robot import adapter
from pipeline.measurements.point import PointModel
from pipeline.models import urdf, urdf_arm
from pipeline.plan.urdf_robot import configurations
from test_urdf_plan import URDF


def point_campaign(true_joints, seed: int, n: int = 120, noise: float = 2e-5, text: str = URDF):
    """(PointModel, table) of a 3-D point campaign on the chain of `text` (b → l6): joints read q,
    the true robot stands at `true_joints(q)`; a random truth (0.5 mm / 0.5 mrad) and tracker noise."""
    arm = urdf_arm.UrdfArm(urdf.parse(text, "b", "l6"))
    model = PointModel(arm)
    rng = np.random.default_rng(seed)
    truth = model.nominal() + rng.normal(0, 5e-4, len(model.nominal()))
    truth[model.parameter_names().index("tool.z")] = 0.05
    q = configurations(arm, n, seed + 1)
    p, *_ = model.tool(truth, true_joints(q))
    table = {"joint_positions": q, "position": p + rng.normal(0, noise, p.shape), "target": np.zeros(n, int),
             "record": np.arange(n), "timestamp_ns": np.arange(n) * 1_000_000_000,
             "time_since_start_s": np.arange(n, dtype=float)}
    return model, table


def campaign(scale: float, seed: int, n: int = 120, noise: float = 2e-5):
    """Joint j2 turns (1 + scale) times what it reads."""
    return point_campaign(lambda q: q * np.r_[1, 1 + scale, 1, 1, 1, 1], seed, n, noise)


@pytest.mark.parametrize("seed", [0, 1])
def test_joint_scale_is_found_and_clean_is_clean(seed):
    model, table = campaign(3e-3, seed)
    doc = diagnose(model, table, settings=Settings(n_boot=10, sign_flips=0), adapter=adapter(model, table, held=()))
    labels = [f"{f['effect']}@{f['location']}" for f in doc["findings"]]
    assert "joint_scale@j2" in labels, doc["findings"]
    model, table = campaign(0.0, seed + 10)
    doc = diagnose(model, table, settings=Settings(n_boot=10, sign_flips=0), adapter=adapter(model, table, held=()))
    assert doc["findings"] == [], doc["findings"]
