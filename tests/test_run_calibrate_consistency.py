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
