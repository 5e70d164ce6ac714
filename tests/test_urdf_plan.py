"""D-optimal planning for a URDF robot measured by 3-D points (the generic `plan` over the generic
measurement model): the planned set beats the median of random sets of the same size at new
configurations, on a truth with errors the plan did not know."""

from __future__ import annotations

import numpy as np

from pipeline.identify.model import take
from pipeline.measurements.point import PointModel
from pipeline.models import urdf, urdf_arm
from pipeline.plan.select import holdout_rms, plan
from pipeline.plan.urdf_robot import configurations, table_at

URDF = """<robot name="r6">
  <link name="b"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="l5"/><link name="l6"/>
  <joint name="j1" type="revolute"><parent link="b"/><child link="l1"/><origin xyz="0 0 0.2"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0.1 0" rpy="1.5708 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.4 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2.5" upper="2.5" effort="1" velocity="1"/></joint>
  <joint name="j4" type="revolute"><parent link="l3"/><child link="l4"/><origin xyz="0.35 0 0" rpy="0 1.5708 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j5" type="revolute"><parent link="l4"/><child link="l5"/><origin xyz="0 0 0.1" rpy="-1.5708 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j6" type="continuous"><parent link="l5"/><child link="l6"/><origin xyz="0 0 0.08"/><axis xyz="0 0 1"/></joint>
</robot>
"""


def test_planned_points_beat_random_sets():
    arm = urdf_arm.UrdfArm(urdf.parse(URDF, "b", "l6"))
    model = PointModel(arm)
    rng = np.random.default_rng(3)
    truth = model.nominal() + rng.normal(0, 1e-3, len(model.nominal()))
    truth[model.parameter_names().index("tool.z")] = 0.05
    cand = table_at(model, truth, configurations(arm, 400, 1))
    cand["position"] = cand["position"] + rng.normal(0, 5e-5, cand["position"].shape)
    test = table_at(model, truth, configurations(arm, 300, 2))
    p = plan(model, cand, 30)
    planned = holdout_rms(model, take(cand, p.selection.index), test)
    random = [holdout_rms(model, take(cand, np.sort(rng.choice(400, 30, replace=False))), test) for _ in range(7)]
    assert planned < np.median(random), (planned, random)
    assert planned < 1e-4  # at new configurations: near the 50 µm measurement noise
