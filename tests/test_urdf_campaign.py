"""`robocal simulate urdf --campaign CAMPAIGN.json`: a planned pose campaign of a URDF robot
executed on the (simulated) true robot, measured at exactly the planned joints, calibrated to the
noise floor; a campaign for other joints fails in one line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from pipeline.models import urdf, urdf_arm
from pipeline.plan.select import plan
from pipeline.plan.urdf_robot import candidates_for
from pipeline.recording.reader import read_recording
from pipeline.systems.urdf_robot import model_for
from test_urdf_simulate import PR6

ROOT = Path(__file__).resolve().parents[1]


def cli(*args) -> subprocess.CompletedProcess:
    """This checkout's CLI (python -m pipeline from the repository root)."""
    return subprocess.run([sys.executable, "-m", "pipeline", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, timeout=600)


def campaign_doc(names: list[str], q: np.ndarray) -> dict:
    return {"kind": "robocal.campaign", "version": 1, "system": "urdf", "measurement": "pose", "joint_names": names,
            "stage": 1, "stages": 1,
            "measurements": [{"index": i, "joints_rad": row.tolist()} for i, row in enumerate(q)]}


def test_planned_urdf_campaign_is_executed_at_its_joints_and_calibrates(tmp_path):
    desc = urdf.parse(PR6, "base", "flange")
    arm = urdf_arm.UrdfArm(desc)
    model = model_for(arm, "point", {}, [])
    cand = candidates_for(model, 400, seed=3)
    idx = plan(model, cand, 45).selection.index
    q = cand["joint_positions"][idx]
    names = list(arm.joint_names)
    order = np.array([3, 0, 1, 2, 4, 5, 6])  # the file may list the joints in any order
    doc = campaign_doc([names[i] for i in order], q[:, order])
    (tmp_path / "c.json").write_text(json.dumps(doc))
    (tmp_path / "r.urdf").write_text(PR6)
    rec = tmp_path / "sim.mcap"
    p = cli("simulate", "urdf", "--urdf", tmp_path / "r.urdf", "--root", "base", "--tip", "flange", "--measure", "point",
            "--noise-mm", "0.02", "--campaign", tmp_path / "c.json", "--out", rec, "--seed", "4")
    assert p.returncode == 0, p.stderr
    got = np.array([m["joint_positions"] for m in read_recording(rec).messages["/measure/point"]])
    np.testing.assert_array_equal(got, q)  # measured where planned, in the robot's joint order
    p = cli("calibrate", rec, "--out", tmp_path / "cal")
    assert p.returncode == 0, p.stderr
    res = json.loads((tmp_path / "cal" / "results.json").read_text())
    assert res["rms_before_m"] > 5 * 2e-5
    assert 0.6 * 2e-5 < res["rms_after_m"] < 1.5 * 2e-5


def test_campaign_for_other_joints_fails_in_one_line(tmp_path):
    (tmp_path / "r.urdf").write_text(PR6)
    (tmp_path / "c.json").write_text(json.dumps(campaign_doc(["j1", "j2"], np.zeros((3, 2)))))
    p = cli("simulate", "urdf", "--urdf", tmp_path / "r.urdf", "--root", "base", "--tip", "flange",
            "--campaign", tmp_path / "c.json", "--out", tmp_path / "x.mcap")
    assert p.returncode != 0
    assert "do not match the robot's joints" in p.stderr and "Traceback" not in p.stderr


def test_plan_urdf_campaign_runs_through_simulate_urdf(tmp_path):
    """`robocal plan urdf --out P.json` → `robocal simulate urdf --campaign P.json`: the planned
    configurations are the ones measured."""
    (tmp_path / "r.urdf").write_text(PR6)
    p = cli("plan", "urdf", "--urdf", tmp_path / "r.urdf", "--root", "base", "--tip", "flange", "--measure", "point",
            "--candidates", "200", "--select", "30", "--out", tmp_path / "p.json")
    assert p.returncode == 0, p.stderr
    q = np.array([m["joints_rad"] for m in json.loads((tmp_path / "p.json").read_text())["measurements"]])
    rec = tmp_path / "sim.mcap"
    p = cli("simulate", "urdf", "--urdf", tmp_path / "r.urdf", "--root", "base", "--tip", "flange", "--measure", "point",
            "--campaign", tmp_path / "p.json", "--out", rec)
    assert p.returncode == 0, p.stderr
    got = np.array([m["joint_positions"] for m in read_recording(rec).messages["/measure/point"]])
    np.testing.assert_array_equal(got, q)
