"""Scanner planning: `robocal plan scorbot-scanner` writes an executable pose campaign (joints and
the grid line per pose, D-optimal over poses), and `robocal simulate scorbot-scanner --campaign`
executes it on the true robot — each pose servoed from its planned joints onto its grid line with
the true camera — so that the recording measures the planned crossings and calibrates."""

from __future__ import annotations

import json

import numpy as np

from conftest import run_cli
from pipeline.plan import scorbot_scanner as ps
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import validator
from pipeline.simulate import scorbot_scanner as sim
from pipeline.systems import scorbot_scanner as sc


def test_plan_selects_distinct_poses_on_grid_lines():
    model, table = ps.candidates(60, seed=4)
    assert np.bincount(table["pose"]).tolist() == [5] * 60
    sel, free = ps.plan_poses(model, table, 6)
    assert len(set(sel.index.tolist())) == 6 and free.sum() == 12  # 14 parameters, 2 gauge directions
    assert sel.logdet >= sel.greedy_logdet - 1e-9
    P = sim.Pattern().corners()
    for m in ps.pose_campaign(table, sel.index)["measurements"]:
        ids = {c: i for i, c in enumerate(sim.Pattern().ids())}
        X = P[[ids[c] for c in m["corner_ids"]]]
        d = X[-1] - X[0]
        assert len(m["corner_ids"]) == 5 and np.allclose(np.cross(X - X[0], d), 0, atol=1e-12)  # one grid line


def test_planned_campaign_runs_on_the_true_robot_and_calibrates(tmp_path):
    plan, rec, run = tmp_path / "c.json", tmp_path / "r.mcap", tmp_path / "run"
    r = run_cli("plan", "scorbot-scanner", "--candidates", "120", "--select", "5", "--out", plan)
    assert r.returncode == 0, r.stderr
    doc = json.loads(plan.read_text())
    assert not list(validator("campaign").iter_errors(doc)) and doc["system"] == "scorbot-scanner"
    r = run_cli("simulate", "scorbot-scanner", "--campaign", plan, "--out", rec, "--seed", "3")
    assert r.returncode == 0, r.stderr
    measured = sc.stripe_table(read_recording(rec))["corner"]
    planned = sim.Pattern().corners()[[sim.Pattern().ids().index(c) for m in doc["measurements"] for c in m["corner_ids"]]]
    hit = np.linalg.norm(measured[:, None, :] - planned[None], axis=2).min(axis=1) < 1e-9  # whole corners, not coordinates
    assert len(measured) >= 15 and hit.mean() >= 0.8, hit
    r = run_cli("run", rec, "--out", run)
    assert r.returncode == 0, r.stderr
    res = json.loads((run / "results.json").read_text())["summary"]
    assert res["n_measurements"] >= 15 and res["holdout_rms_m"] < 1e-3, res["holdout_rms_m"]


def test_bad_scanner_campaign_is_one_line(tmp_path):
    plan = tmp_path / "c.json"
    assert run_cli("plan", "scorbot-scanner", "--candidates", "60", "--select", "4", "--out", plan).returncode == 0
    doc = json.loads(plan.read_text())
    doc["measurements"][2]["corner_ids"] = ["r0c0", "nowhere"]
    plan.write_text(json.dumps(doc))
    r = run_cli("simulate", "scorbot-scanner", "--campaign", plan, "--out", tmp_path / "x.mcap")
    assert r.returncode != 0 and "measurement 2: corner_ids" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "x.mcap").exists()
