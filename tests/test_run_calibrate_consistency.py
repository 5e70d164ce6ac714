"""One verdict whichever command reads a recording; the planner says when its own prediction is poor."""

from __future__ import annotations

import math

import numpy as np

from conftest import run_cli
from pipeline.plan.arc_welder import landing_warning
from tests.pipeline_support import base_campaign, write


def test_calibrate_refuses_the_joint_values_run_refuses(tmp_path):
    meta, js, contacts = base_campaign()
    contacts[9]["joint_positions"][4] = math.radians(140)  # J5 limit ±135°
    rec = write(tmp_path / "bad.mcap", meta, js, contacts)
    run = run_cli("run", rec, "--out", tmp_path / "run")
    cal = run_cli("calibrate", rec, "--out", tmp_path / "cal")
    assert run.returncode == cal.returncode == 2
    lines = [ln for ln in cal.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "joint_limits" in lines[0] and "(9)" in lines[0] and "J5" in lines[0]
    assert not (tmp_path / "cal" / "results.json").exists()


def test_the_planner_warns_before_a_campaign_it_predicts_will_land_poorly():
    assert landing_warning(np.full(15, 0.99)) is None
    w = landing_warning(np.r_[np.full(14, 0.99), 0.2])
    assert w and "contacts 14 below 50%" in w and "14.1 of 15" in w
    w = landing_warning(np.full(15, 0.8))  # none hopeless, but 3 of 15 expected to miss
    assert w and "12.0 of 15 contacts expected" in w


def test_compensate_reaches_every_target_made_from_joints_inside_the_limits():
    """Targets the calibrated robot reaches at joints inside every limit: none is called unreachable or
    out of limits (the controller's few seeds miss some; the spread starts find them)."""
    from pipeline.compensate import serial as S
    from pipeline.models import serial_arm
    from pipeline.simulate.arc_welder import IK_SEEDS
    from pipeline.systems import arc_welder as aw

    nominal = aw.nominal_arm()
    kin = S.SerialArmKinematics.of(nominal)
    truth = aw.random_truth(nominal, np.random.default_rng(0)).vector()
    q = np.random.default_rng(10).uniform(0.95 * nominal.lower, 0.95 * nominal.upper, (400, 6))
    R, p = serial_arm.forward(truth, q)
    c = S.compensate(kin, nominal.vector(), truth, p, R, IK_SEEDS)
    assert not np.isin(c.status, ("unreachable", "out_of_limits")).any()
    reached = c.status != "singular"
    Rc, pc = serial_arm.forward(truth, c.q[reached])
    assert np.abs(pc - p[reached]).max() < 1e-9 and np.all((c.q >= kin.lower) & (c.q <= kin.upper))
