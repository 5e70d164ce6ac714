"""Executable campaigns: plan → campaign file (schema) → executed on the true robot (misses
recorded as misses) → calibrated; two stages; bad campaign files."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli
from stream_support import record_over_pty
from pipeline.errors import RobocalError
from pipeline.models import serial_arm
from pipeline.models.jig import stepped_block
from pipeline.plan import campaign as cdoc
from pipeline.plan import touch
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import validator
from pipeline.simulate.arc_welder import Campaign, Noise
from pipeline.simulate.campaign_run import execute
from pipeline.systems import arc_welder as aw

# extended (`make test-extended`, outside CI's 20-minute budget): full campaigns planned, simulated and diagnosed; CI keeps test_plan_select, test_plan_staged, test_plan_approach
pytestmark = pytest.mark.extended


@pytest.fixture(scope="module")
def planned(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("plan")
    r = run_cli("plan", "arc-welder", "--candidates", "150", "--select", "30", "--out", d / "c.json")
    assert r.returncode == 0, r.stderr
    return d / "c.json"


def test_campaign_file_is_schema_valid_and_targets_keep_the_margin(planned):
    doc = json.loads(planned.read_text())
    validator("campaign").validate(doc)
    assert doc["kind"] == "robocal.campaign" and len(doc["measurements"]) == 30
    jig = stepped_block()
    nominal = aw.nominal_arm()
    for m in doc["measurements"]:
        f = jig.face(m["face"])
        ma, mb = doc["face_margins_m"][f.id]
        a, b = f.other_axes()
        p = m["predicted_contact_m"]
        assert f.extent[0][0] + ma - 1e-9 <= p[a] <= f.extent[0][1] - ma + 1e-9
        assert f.extent[1][0] + mb - 1e-9 <= p[b] <= f.extent[1][1] - mb + 1e-9
        q = np.array(m["approach_joints_rad"])
        assert np.all(q >= nominal.lower) and np.all(q <= nominal.upper)
    assert min(doc["face_margins_m"]["top1"]) == pytest.approx(0.010)  # a wide face keeps the stated margin


def test_executed_on_a_robot_equal_to_its_planning_model_every_contact_lands_where_predicted(planned):
    nominal, jig = aw.nominal_arm(), stepped_block()
    plan = cdoc.read(planned, aw.SYSTEM, 6, jig)
    ex = execute(nominal, nominal, jig, plan, Noise(scale=0.0))
    assert ex.landed.all()
    pred = np.array([m["predicted_contact_m"] for m in plan.doc["measurements"]])
    p = serial_arm.tip_position(nominal.vector(), ex.sim.contact_q)
    assert np.abs(p - pred).max() < 1e-9


def test_misses_on_the_true_robot_are_recorded_as_misses_and_contacts_are_true(tmp_path):
    nominal, truth, jig = aw.nominal_arm(), aw.reference_truth(), stepped_block()
    pool = touch.pool(nominal, jig, 60, seed=3, margin_m=0.0)  # no margin: the ~20 mm error makes misses
    path = tmp_path / "c.json"
    path.write_text(json.dumps(cdoc.touch_document(aw.SYSTEM, nominal, jig, pool, Campaign(), 0.0)))
    plan = cdoc.read(path, aw.SYSTEM, 6, jig)
    ex = execute(nominal, truth, jig, plan, Noise(), seed=1)
    assert 0 < (~ex.landed).sum() < plan.n  # some miss, some land, none replaced
    assert ex.sim.contact_t_ns.size + ex.miss_index.size == plan.n
    assert ex.sim.injected_noise_rms_m < 1e-4  # every recorded contact is a true contact (noise only)
    # a miss is genuine: the true tip never meets its face inside the edges within the travel
    from pipeline.simulate.campaign_run import landing
    for i in ex.miss_index[:5]:
        f = np.array([[x.id for x in jig.faces].index(plan.face_id[i])])
        hit, _, _ = landing(truth.vector(), jig, f, plan.q_approach[[i]], plan.dq[[i]], 0.09)
        assert not hit[0]
    out = tmp_path / "r.mcap"
    r = run_cli("simulate", "arc-welder", "--campaign", path, "--out", out, "--truth", tmp_path / "t.json")
    assert r.returncode == 0, r.stderr
    rec = read_recording(out)
    t = json.loads((tmp_path / "t.json").read_text())["campaign_execution"]
    assert len(rec.messages.get("/touch/contact", [])) == t["landed"]
    misses = rec.messages.get("/touch/miss", [])
    assert len(misses) == t["missed"] > 0
    for m in misses:
        validator("touch_miss").validate(m)
    assert sorted([m["campaign_index"] for m in misses]) == [x["index"] for x in t["misses"]]


def test_a_search_stops_at_a_joint_limit_and_is_a_miss_logged_there():
    """A controller stops a search at the first joint limit: the face beyond it is a miss, and no joint reading of
    the stream or the miss leaves its travel (a planned campaign's search once ran J4 0.29 rad past its limit and
    validate refused the recording the guide's commands made)."""
    nominal, jig = aw.nominal_arm(), stepped_block()
    pool = touch.pool(nominal, jig, 12, seed=3, margin_m=0.01)
    away = pool.q_approach[:, 3] * pool.dq[:, 3] > 0  # searches turning J4 away from the home pose's J4 = 0
    pool = pool.take([int(np.argmax(np.where(away, np.abs(pool.dq[:, 3]), -1)))])  # the fastest of them
    plan = cdoc.from_pool(aw.SYSTEM, nominal, jig, pool)
    assert execute(nominal, nominal, jig, plan, Noise(scale=0.0)).landed.all()
    i = 0  # J4's limit half-way to its contact
    stop = pool.q_approach[i, 3] + 0.5 * pool.travel[i] * pool.dq[i, 3]
    j4 = nominal.joints[3]
    j4 = replace(j4, upper=stop) if pool.dq[i, 3] > 0 else replace(j4, lower=stop)
    limited = replace(nominal, joints=(*nominal.joints[:3], j4, *nominal.joints[4:]))
    ex = execute(limited, nominal, jig, plan, Noise(scale=0.0))
    assert list(ex.miss_index) == [i] and ex.miss_reason == ["no_contact"]
    assert np.all((ex.sim.stream_q >= limited.lower) & (ex.sim.stream_q <= limited.upper))
    assert ex.miss_q[0, 3] == pytest.approx(stop, abs=2e-4)  # stopped at the limit (less 1e-4 rad)


# The two-stage campaign (plan, simulate, run, plan --after, both stages in one recording): docs/guide/plan.md's
# commands, run as printed and checked by the documentation's runner (tests/doc_runner.py, doc_expect.py).


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["measurements"][0].update(approach_joints_rad=[0.0] * 5), "measurement 0: approach_joints_rad"),
    (lambda d: d["measurements"][1].update(face="nowhere"), "measurement 1: face 'nowhere'"),
    (lambda d: d["measurements"][2].update(search_direction=[0, 0, 2]), "measurement 2: search_direction"),
    (lambda d: d.pop("measurements"), "'measurements' is a required property"),
])
def test_bad_campaign_files_fail_with_one_line_naming_file_and_measurement(planned, tmp_path, edit, message):
    doc = json.loads(planned.read_text())
    edit(doc)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(RobocalError, match=message):
        cdoc.read(bad, aw.SYSTEM, 6, stepped_block())
    r = run_cli("simulate", "arc-welder", "--campaign", bad, "--out", tmp_path / "x.mcap")
    assert r.returncode == 2 and "Traceback" not in r.stderr and str(bad) in r.stderr
    assert not (tmp_path / "x.mcap").exists()


def test_not_json_campaign(tmp_path):
    bad = tmp_path / "c.json"
    bad.write_text("{not json")
    r = run_cli("simulate", "arc-welder", "--campaign", bad, "--out", tmp_path / "x.mcap")
    assert r.returncode == 2 and "not a JSON campaign" in r.stderr


def test_device_sim_plays_a_planned_campaign_over_a_pty_with_its_misses(planned, tmp_path):
    record_over_pty(tmp_path, "arc-welder", ("--campaign", str(planned), "--speed", "100", "--seed", "3"))
    rec = read_recording(tmp_path / "acq.mcap")
    n_contact = len(rec.messages.get("/touch/contact", []))
    n_miss = len(rec.messages.get("/touch/miss", []))
    assert n_contact + n_miss == 30 and n_contact >= 10


def test_delta_pose_campaign_is_planned_executed_and_calibrated(tmp_path):
    r = run_cli("plan", "delta-tracker", "--candidates", "300", "--select", "27", "--out", tmp_path / "c.json")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "c.json").read_text())
    validator("campaign").validate(doc)
    assert doc["measurement"] == "pose" and len(doc["measurements"]) == 27
    r = run_cli("simulate", "delta-tracker", "--campaign", tmp_path / "c.json", "--out", tmp_path / "r.mcap")
    assert r.returncode == 0, r.stderr
    rec = read_recording(tmp_path / "r.mcap")
    q = np.array([m["joint_positions"] for m in rec.messages["/tracker/point"]])
    planned = np.array([m["joints_rad"] for m in doc["measurements"]])
    assert np.abs(q - planned).max() < 1e-4  # the robot stood at the planned configurations (encoder resolution)
    r = run_cli("calibrate", tmp_path / "r.mcap", "--out", tmp_path / "cal")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "cal" / "results.json").read_text())["holdout_rms_m"] < 5e-5
    bad = dict(doc, system="arc-welder")
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    r = run_cli("simulate", "delta-tracker", "--campaign", tmp_path / "bad.json", "--out", tmp_path / "x.mcap")
    assert r.returncode == 2 and "not a delta-tracker pose campaign" in r.stderr


def test_planned_campaign_with_an_effect_is_executed_and_diagnose_finds_it(tmp_path):
    """`simulate arc-welder --campaign C.json --effect …`: the planned searches run on the true robot
    with the effect (misses still logged as misses), and `robocal diagnose` names and sizes it."""
    c, rec, truth = tmp_path / "c.json", tmp_path / "r.mcap", tmp_path / "t.json"
    assert run_cli("plan", "arc-welder", "--candidates", "400", "--select", "120", "--seed", "1", "--out", c).returncode == 0
    r = run_cli("simulate", "arc-welder", "--campaign", c, "--effect", "joint_scale=1e-3@J3", "--out", rec,
                "--truth", truth)
    assert r.returncode == 0, r.stderr
    t = json.loads(truth.read_text())
    assert t["effects"] == [{"name": "joint_scale", "location": "J3", "values": [1e-3]}]
    ex = t["campaign_execution"]
    got = read_recording(rec).messages
    assert len(got["/touch/contact"]) == ex["landed"] > 60 and len(got["/touch/miss"]) == ex["missed"] > 0
    assert ex["landed"] + ex["missed"] == 120
    r = run_cli("diagnose", rec, "--out", tmp_path / "d")
    assert r.returncode == 0, r.stderr
    found = json.loads((tmp_path / "d" / "diagnosis.json").read_text())["findings"]
    assert [(f["effect"], f["location"]) for f in found] == [("joint_scale", "J3")]
    est = found[0]["parameters"][0]
    assert abs(est["value"] - 1e-3) < max(0.2e-3, 4 * est["std"])
    # the same campaign without the effect: nothing to find
    rec0 = tmp_path / "r0.mcap"
    assert run_cli("simulate", "arc-welder", "--campaign", c, "--search-speeds", "0.01", "--out", rec0).returncode == 0
    assert run_cli("diagnose", rec0, "--out", tmp_path / "d0").returncode == 0
    assert json.loads((tmp_path / "d0" / "diagnosis.json").read_text())["findings"] == []


def test_payload_pairs_do_not_combine_with_a_campaign(planned, tmp_path):
    out = tmp_path / "r.mcap"
    r = run_cli("simulate", "arc-welder", "--campaign", planned, "--payloads", "0,6", "--payload-pairs", "--out", out)
    assert r.returncode != 0 and "--payload-pairs" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not out.exists()
