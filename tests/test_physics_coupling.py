"""A reading of a joint offset by a transmission through the joint before it (cables, belts): the independent
humanoid generator (no robocal code) with δq_j = κ·q_read(i), i the read joint before j on its arm, on two
joints; calibrated with the held-out model selection (`--physics auto`).  The coupling is kept, each κ
recovered within 2σ, the held-out error is at the noise floor and the geometry-only fit is clearly worse;
a second session of the same robot, evaluated without refitting, is at the noise floor too."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_cli
from humanoid_import import import_humanoid

import independent_humanoid as hu

# extended (`make test-extended`, outside CI's 20-minute budget): coupling calibrated end to end; CI keeps test_diagnose_library_more and test_diagnose_independent (couplings named)
pytestmark = pytest.mark.extended

pytest.importorskip("pinocchio")

COUPLING = {"left_j3": ("left_j2", 8e-3), "right_j5": ("right_j4", -6e-3)}  # δq = κ·q(driver), rad/rad


def test_coupling_kept_recovered_and_at_the_noise_floor(tmp_path):
    from pipeline.calibrate import calibrate
    from pipeline.identify.least_squares import FitOptions

    d = hu.write(tmp_path / "c", seed=5, n=150, noise_m=2e-4, geometry=False, coupling=COUPLING)
    truth = json.loads((d / "truth.json").read_text())
    assert truth["coupling"]["left_j3"] == ["left_j2", 8e-3]
    rec = import_humanoid(d, tmp_path / "c.mcap")
    doc = calibrate(rec, tmp_path / "out", FitOptions(), k_folds=3, physics="auto", select_groups=True)
    assert "joint coupling" in doc["model_selection"]["kept_groups"], doc["model_selection"]
    p = {r["name"]: r for r in doc["parameters"]}
    for joint, (driver, kappa) in COUPLING.items():
        r = p[f"{joint}.coupling"]
        assert r["identifiable"] and abs(r["estimate"] - kappa) <= 2 * r["std"], (joint, r, kappa)
        assert r["std"] < 0.25 * abs(kappa) and r["unit"] == "rad/rad"
    terms = {t["parameter"]: t for t in doc["physics"]["terms"] if "parameter" in t}
    assert terms["left_j3.coupling"]["driver"] == "left_j2" and terms["right_j5.coupling"]["driver"] == "right_j4"
    floor = truth["noise_m"]
    assert doc["holdout_rms_m"] < 1.3 * floor, doc["holdout_rms_m"]
    assert doc["physics"]["holdout_geometry_only_m"] > 1.5 * doc["physics"]["holdout_with_physics_m"], doc["physics"]
    d2 = hu.write(tmp_path / "c2", seed=5, n=60, noise_m=2e-4, geometry=False, session=2, coupling=COUPLING)
    r = run_cli("evaluate", tmp_path / "out", import_humanoid(d2, tmp_path / "c2.mcap"), "--out", tmp_path / "ev")
    assert r.returncode == 0, r.stderr
    (ev,) = json.loads((tmp_path / "ev" / "evaluation.json").read_text())["recordings"]
    assert ev["rms_3d_m"] < 1.3 * np.sqrt(3) * floor, ev["rms_3d_m"]
