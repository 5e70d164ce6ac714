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
import pytest

# extended (`make test-extended`, outside CI's 20-minute budget): the scanner's plans at full size; CI keeps test_plan_select and test_plan_staged
pytestmark = pytest.mark.extended


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


# ----- two stages: operator poses first, then I-optimal on the calibrated estimate -----------------------

def test_first_stage_is_spread_reachable_and_schema_valid(tmp_path):
    """The first stage's operator poses are spread (maximin: their smallest pairwise distance in the
    unit design cube beats every one of 50 random draws of the same size) and their approach joints
    keep inside the joint limits."""
    from pipeline.plan.scorbot_scanner import LIMIT_MARGIN_RAD, STANDOFF_M, first_stage

    doc = first_stage(5, n=400, seed=7)
    arm = sc.nominal_arm()
    from pipeline.simulate.scanner_operator import aim_box

    lo, hi = aim_box(sim.Pattern())
    tilt = sim.Campaign().max_tilt_rad
    U = []
    for m in doc["measurements"]:
        q, o = np.array(m["joints_rad"]), m["operator"]
        assert np.all(q >= arm.lower + LIMIT_MARGIN_RAD - 1e-12) and np.all(q <= arm.upper - LIMIT_MARGIN_RAD + 1e-12)
        U.append([*(np.array(o["aim_m"][:2]) - lo) / (hi - lo), (o["standoff_m"] - STANDOFF_M[0]) / np.ptp(STANDOFF_M),
                  (o["tilt_rad"] + tilt) / (2 * tilt), (o["roll_rad"] + np.pi / 2) / np.pi])
    U = np.array(U)
    assert np.all((U >= 0) & (U <= 1))

    def min_gap(X):
        d = np.linalg.norm(X[:, None] - X[None], axis=2)
        return d[np.triu_indices(len(X), 1)].min()

    rng = np.random.default_rng(0)
    assert min_gap(U) > max(min_gap(rng.uniform(0, 1, (5, 5))) for _ in range(50))
    plan = tmp_path / "s1.json"
    r = run_cli("plan", "scorbot-scanner", "--stages", "2", "--first-stage", "4", "--out", plan)
    assert r.returncode == 0, r.stderr
    d = json.loads(plan.read_text())
    assert not list(validator("campaign").iter_errors(d)) and (d["stage"], d["stages"]) == (1, 2)
    assert len(d["measurements"]) == 4 and all("operator" in m for m in d["measurements"])


def test_operator_backs_off_until_the_line_shows_enough_crossings():
    """From a stand-off too close to see 5 crossings, the operator backs off (25 mm steps) until it
    does; the pose found has its true stripe on a grid line through those corners."""
    from pipeline.simulate import scanner_operator as so
    from pipeline.simulate.scanner_geometry import camera_pose, floor_line

    arm, s = sc.nominal_arm(), sc.reference_scanner()
    pat, camp, aim = sim.Pattern(), sim.Campaign(), np.array([0.50, 0.0, 0.0])
    assert so.pose_on_line(arm, arm.vector(), s, pat, camp, (640, 480), aim, 0.12, 0.1, 0.3) is None
    q, idx = so.backed_off_pose(arm, arm.vector(), s, pat, camp, (640, 480), aim, 0.12, 0.1, 0.3)
    assert len(idx) == camp.corners
    R, C = camera_pose(arm.vector(), s, q[None])
    p0, d = floor_line(R, C, s, 0.0)
    X = pat.corners()[idx]
    off = (X - p0) - ((X - p0) @ d[0])[:, None] * d  # distance of each corner from the laser's floor line
    assert np.abs(off).max() < 1e-9
    assert so.backed_off_pose(arm, arm.vector(), s, pat, camp, (640, 480), np.array([3.0, 0.0, 0.0]), 0.3, 0.0, 0.0) is None


def test_two_stages_calibrate_better_than_the_first_alone():
    """Stage 2 planned on the calibration of stage 1 (I-optimal, stage 1 as prior) measures the
    planned lines on the true robot, and the final calibration's true 3-D error at 20 new poses is
    below stage 1's own and below the plan's pessimistic bound (3× its prediction)."""
    from pipeline.identify.least_squares import fit
    from pipeline.simulate.scanner_operator import OperatorPose

    arm, s_true, model = sc.nominal_arm(), sc.reference_scanner(), sc.ScannerModel()
    ids = {c: i for i, c in enumerate(sim.Pattern().ids())}
    first = [OperatorPose(tuple(m["operator"]["aim_m"]), m["operator"]["standoff_m"], m["operator"]["tilt_rad"],
                          m["operator"]["roll_rad"]) for m in ps.first_stage(4, seed=11)["measurements"]]
    r1, st1 = sim.simulate_in_memory(arm, arm, s_true, sim.Campaign(poses=4, seed=11), planned=first)
    assert not r1.misses
    doc = ps.next_stage(st1, 4, n=120, seed=11)
    second = [(np.array(m["joints_rad"]), np.array([ids[c] for c in m["corner_ids"]]), m["stripe_row_px"])
              for m in doc["measurements"]]
    r2, st2 = sim.simulate_in_memory(arm, arm, s_true, sim.Campaign(poses=4, seed=12), planned=second)
    assert not r2.misses and all(len(o.corner_idx) == 5 for o in r2.observations)
    planned_lines = [frozenset(ids[c] for c in m["corner_ids"]) for m in doc["measurements"]]
    assert [frozenset(o.corner_idx.tolist()) for o in r2.observations] == planned_lines
    both = {k: np.concatenate([st1[k], st2[k] + (4 if k in ("pose", "record") else 0)])
            for k in ("joint_positions", "pixel", "corner", "pose", "record")}
    _, exact = sim.simulate_in_memory(arm, arm, s_true, sim.Campaign(poses=20, seed=1011), sim.Noise(scale=0.0))

    def err3(t):
        return float(np.sqrt(np.mean(np.sum(model.residuals(fit(model, t).x, exact) ** 2, axis=1))))

    e1, e12 = err3(st1), err3(both)
    assert e12 < e1 and e12 < 3 * doc["predicted_rms_3d_error_m"], (e1, e12, doc["predicted_rms_3d_error_m"])


def test_after_needs_three_poses(tmp_path):
    from pipeline.errors import RobocalError

    _, t = sim.simulate_in_memory(sc.nominal_arm(), sc.nominal_arm(), sc.reference_scanner(), sim.Campaign(poses=2, seed=1))
    try:
        ps.next_stage(t, 3, n=60)
    except RobocalError as e:
        assert "only 2 scanner pose(s)" in str(e)
    else:
        raise AssertionError("a next stage on 2 poses must be refused")


def test_two_stage_cli_end_to_end(tmp_path):
    """plan --stages 2 → simulate → run → plan --after RUN → simulate both stages into one recording."""
    s1, s2, r1, r, run = (tmp_path / n for n in ("s1.json", "s2.json", "r1.mcap", "r.mcap", "run1"))
    assert run_cli("plan", "scorbot-scanner", "--stages", "2", "--out", s1).returncode == 0
    assert run_cli("simulate", "scorbot-scanner", "--campaign", s1, "--out", r1, "--seed", "5").returncode == 0
    # the stages `plan --after` reads (its identify stage): the plan is the one a full run gives, all but its
    # timing; a planned scanner campaign runs in full in test_planned_campaign_runs_on_the_true_robot_and_calibrates
    assert run_cli("run", r1, "--out", run, "--stages", "ingest,validate,identify").returncode == 0
    p = run_cli("plan", "scorbot-scanner", "--after", run, "--select", "3", "--candidates", "100", "--out", s2)
    assert p.returncode == 0, p.stderr
    doc = json.loads(s2.read_text())
    assert (doc["stage"], doc["stages"]) == (2, 2) and len(doc["measurements"]) == 3
    assert doc["earlier_measurements"] == 20 and 0 < doc["predicted_rms_3d_error_m"] < 1e-3
    q = run_cli("simulate", "scorbot-scanner", "--campaign", s1, "--campaign", s2, "--out", r, "--seed", "5")
    assert q.returncode == 0, q.stderr
    assert len(sc.stripe_table(read_recording(r))["corner"]) == 35  # 4 + 3 poses × 5 crossings
    bad = run_cli("plan", "scorbot-scanner", "--after", tmp_path / "nowhere", "--select", "3", "--out", tmp_path / "x.json")
    assert bad.returncode != 0 and "Traceback" not in bad.stderr and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
