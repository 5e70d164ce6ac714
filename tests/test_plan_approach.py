"""A planned touch campaign approaches every joint from both sides, says how balanced that is
(`approach_balance`), and the signs it states are the ones the campaign's encoder stream shows when the
independent generator (`independent_touch`, its own kinematics and controller timeline) executes the plan file
and ingest derives each joint's last motion (`last_motion_sign_beyond_2mrad`)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

import independent_campaign_file as icf
import independent_touch as it
from touch_ingest import diagnosis_table
from conftest import run_cli
from pipeline.plan.approach import ONE_SIDED, PLAY_RAD, document_balance, last_motion_signs
from pipeline.recording.schemas import validator


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """(plan file, what `robocal plan` said)."""
    path = tmp_path_factory.mktemp("plan") / "campaign.json"
    r = run_cli("plan", "arc-welder", "--candidates", "300", "--select", "40", "--out", path)
    assert r.returncode == 0, r.stderr
    return path, " ".join(r.stderr.split())


@pytest.fixture(scope="module")
def plan_file(planned):
    return planned[0]


def test_a_planned_campaign_approaches_every_joint_from_both_sides(planned):
    plan_file, said = planned
    doc = json.loads(plan_file.read_text())
    validator("campaign").validate(doc)
    bal = doc["approach_balance"]["joints"]
    assert list(bal) == doc["joint_names"] and doc["approach_balance"]["play_rad"] == PLAY_RAD
    for name, b in bal.items():
        assert b["positive"] + b["negative"] + b["unknown"] == len(doc["measurements"]), (name, b)
        assert b["positive"] > 0 and b["negative"] > 0, (name, b)
        assert b["rarer_share"] >= ONE_SIDED, (name, b)
        assert b["faces_both_ways"] >= 1, (name, b)
    assert not any("one side" in w for w in doc.get("warnings", [])), doc["warnings"]
    shares = ", ".join(f"{j} {b['rarer_share']:.0%}" for j, b in bal.items())
    assert f"approach from both sides (rarer side's share of the contacts): {shares}" in said, said


def test_the_planner_still_warns_before_a_campaign_it_predicts_will_land_poorly(planned):
    """40 contacts planned on the nominal model in one stage: fewer than 90 % expected to land under the prior
    error sizes; the warning stays first in the file and is printed."""
    plan_file, said = planned
    doc = json.loads(plan_file.read_text())
    p = np.array([m["landing_probability"] for m in doc["measurements"]])
    assert p.sum() < 0.9 * p.size
    assert doc["warnings"][0].startswith("this campaign is predicted to land poorly")
    assert "warning: this campaign is predicted to land poorly" in said


def test_the_stated_signs_are_what_the_executed_campaign_shows(plan_file):
    """Executed by the generator on an arm equal to the planning model (no noise: each search ends where the
    plan predicts), ingest's sign of each joint's last motion beyond the play agrees with the plan's, contact
    by contact and joint by joint (the first contact: the stream starts at its approach pose)."""
    doc = json.loads(plan_file.read_text())
    targets = icf.from_campaign(doc)
    nom, _ = it.default_arms()
    n = targets.face.size
    c = it.run(nom, nom, targets, (), seed=0, n=n, noise=0.0)
    seen = diagnosis_table(c)[f"last_motion_sign_beyond_{PLAY_RAD * 1e3:g}mrad"]
    rows = doc["measurements"]
    stated, by_search = last_motion_signs(targets.q_a, targets.dq, np.array([r["predicted_travel_m"] for r in rows]))
    travel = np.abs(targets.dq * np.array([r["predicted_travel_m"] for r in rows])[:, None])
    clear = (np.abs(travel - PLAY_RAD) > 1e-4)[1:]  # not on the edge of the play
    assert by_search.mean() > 0.8  # the searches turn most joints further than the play
    assert np.array_equal(stated[1:][clear], seen[1:][clear]), np.argwhere(stated[1:] != seen[1:])
    for name, j in zip(doc["joint_names"], range(6)):
        assert doc["approach_balance"]["joints"][name]["positive"] == int(np.sum(stated[:, j] > 0))


def test_a_joint_approached_from_one_side_is_warned(plan_file):
    """The same plan keeping only the contacts whose search turns J2 positively: the plan says J2 is one-sided
    and how to fix it; the balanced joints are not named."""
    doc = json.loads(plan_file.read_text())
    one = copy.deepcopy(doc)
    one["measurements"] = [r for r in doc["measurements"] if r["search_joint_rate_rad_per_m"][1] > 0]
    one.pop("warnings", None)
    document_balance(one)
    assert one["approach_balance"]["joints"]["J2"]["negative"] == 0
    (w,) = [w for w in one["warnings"] if "one side" in w]
    assert "J2 (0%)" in w and "both sides" in w
    assert all(f"{j} (" not in w for j, b in one["approach_balance"]["joints"].items() if b["rarer_share"] >= ONE_SIDED)


def test_a_short_search_leaves_the_sign_to_the_approach_move():
    """A search turning a joint less than the play: its sign is the move to the approach pose (from the
    previous contact's), 0 for the first contact and for a joint that does not move."""
    q = np.array([[0.0, 0.0], [0.1, 0.0], [0.05, 0.0]])
    dq = np.array([[1.0, 0.0], [0.01, 0.0], [0.01, -1.0]])
    s, by = last_motion_signs(q, dq, np.array([0.04, 0.04, 0.04]))
    assert s.tolist() == [[1, 0], [1, 0], [-1, -1]]
    assert by.tolist() == [[True, False], [False, False], [False, True]]


def test_planning_for_backlash_lowers_the_detectable_plays_at_a_small_cost_to_the_geometry(planned, tmp_path):
    """`robocal plan --backlash`: D-optimal over the geometry and every joint's play together (a play shifts the
    joint by −sign·b/2, the sign the search's turn).  On the independent generator (its own kinematics and dead
    band, noise-free, an arm equal to the planning model) the geometric mean of J1–J5's detectable plays drops by
    more than 10 %; the geometry keeps at least 95 % of its D-efficiency; a staged plan refuses the option."""
    path = tmp_path / "backlash.json"
    r = run_cli("plan", "arc-welder", "--candidates", "300", "--select", "40", "--backlash", "--out", path)
    assert r.returncode == 0, r.stderr
    plain, bk = json.loads(planned[0].read_text()), json.loads(path.read_text())
    assert "backlash" in bk["criterion"] and bk["free_parameters"] == plain["free_parameters"]
    assert np.exp((bk["logdet_geometry"] - plain["logdet"]) / plain["free_parameters"]) >= 0.95
    nom, _ = it.default_arms()

    def plays(doc):
        t = icf.from_campaign(doc)
        return np.array([it.mds(nom, nom, t, it.Effect("backlash", 1.0, {"joint": j}), 1e-4 / 3, n=t.face.size)
                         for j in range(5)])

    before, after = plays(plain), plays(bk)
    assert np.exp(np.mean(np.log(after / before))) < 0.9, (before, after)
    r = run_cli("plan", "arc-welder", "--stages", "2", "--backlash", "--out", tmp_path / "staged.json")
    assert r.returncode == 2 and "--backlash plans one-stage campaigns" in r.stderr
    assert not (tmp_path / "staged.json").exists()
