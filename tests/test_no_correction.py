"""A model choice that keeps the nominal robot says so, and why (`pipeline.identify.correction`).

* On a campaign where a correction helps most groups but one left-out group is predicted worse than by the
  nominal robot (its rows disagree with the others'), the left-out-groups choice keeps registration only; every
  candidate it scored better is solved before it is rejected (never a linearised score alone), and each is
  named with the group it predicts worse.
* On a recording of a robot with no error at all (`robocal simulate urdf`, errors 0, three sockets), the
  command line, results.json and the report say "no correction applied", with the candidates tried, and the
  status is warn.
"""

from __future__ import annotations

import json

import numpy as np

from conftest import run_cli
from pipeline.identify.complexity import Selection
from pipeline.identify.correction import from_selection, from_shrunk
from pipeline.identify.shrinkage_groups import shrink_by_groups
from test_shrinkage_groups import LinearModel
from test_urdf_plan import URDF


def _disagreeing(seed: int, n: int = 80):
    """Four groups; a, b, c share the robot's error, d carries −0.3 of it (its rows disagree)."""
    rng = np.random.default_rng(seed)
    labels = np.array(["a", "b", "c", "d"])
    g = np.repeat(labels, n // 4)
    A = rng.normal(size=(n, 3, 6))
    truth = rng.normal(0, 1e-3, 6)
    model = LinearModel()
    data = {"joint_positions": np.zeros((n, 1)), "A": A, "y": np.zeros((n, 3))}
    err = np.einsum("nkp,p->nk", A, truth) * np.where(g == "d", -0.3, 1.0)[:, None]
    data["y"] = -err + rng.normal(0, 2e-5, (n, 3))
    prior = np.r_[np.ones(3), np.full(6, 1e-3)]
    return model, data, g, prior, model.nominal()


def test_better_scored_candidates_are_solved_and_explained():
    model, data, groups, prior, x0 = _disagreeing(3)
    s = shrink_by_groups(model, data, prior, x0, groups)
    assert np.isinf(s.mu_m)  # the nominal robot kept: d is predicted worse by every correction
    assert s.passed_over, "candidates scored below registration only must be listed"
    ref = np.sqrt(s.gcv[np.inf])
    for p in s.passed_over:
        assert p["solved"], p  # solved before rejected: never a linearised score alone
        assert p["holdout_rms_m"] < ref
        assert "d" in p["worse_groups_m"] and "d worse" in p["reason"]
    reason, tried = from_shrunk(s)
    assert reason.startswith("registration only kept") and "d worse" in reason
    assert any(t.get("solved") for t in tried)


def test_group_selection_that_keeps_registration_says_why():
    sel = Selection(kept=["registration"], fixed=(), holdout_registration_m=1e-3, holdout_rms_m=1e-3,
                    rounds=[{"candidate": "registration", "holdout_rms_m": 1e-3, "kept": True},
                            {"candidate": "joint offsets", "holdout_rms_m": 0.99e-3, "against_m": 1e-3,
                             "kept": False, "why": "held-out RMS lowered by 1.0 % (2 % required)"}])
    reason, tried = from_selection(sel)
    assert "joint offsets: 0.99 mm" in reason and "2 % required" in reason
    assert tried[0]["reason"].startswith("held-out RMS lowered")


def test_a_robot_without_error_is_not_corrected_and_the_run_says_so(tmp_path):
    robot = tmp_path / "r6.urdf"
    robot.write_text(URDF)
    rec, out = tmp_path / "nominal.mcap", tmp_path / "run"
    r = run_cli("simulate", "urdf", "--urdf", robot, "--root", "b", "--tip", "l6", "--measure", "coincidence",
                "--groups", "3", "--poses", "45", "--error-m", "0", "--error-rad", "0", "--seed", "3", "--out", rec)
    assert r.returncode == 0, r.stderr
    r = run_cli("run", rec, "--out", out)
    assert r.returncode == 0, r.stderr
    assert "NONE APPLIED" in r.stderr and "warn: no correction applied" in r.stderr
    s = json.loads((out / "results.json").read_text())["summary"]
    assert s["status"] == "warn" and s["status_reason"].startswith("no correction applied")
    corr = s["correction"]
    assert corr["applied"] is False and corr["tried"] and corr["tried"][0]["candidate"] == "registration only"
    assert s["rms_before_m"] == s["rms_after_m"]
    html = (out / "report.html").read_text()
    assert 'id="no-correction"' in html and "No correction applied" in html
