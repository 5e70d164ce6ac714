"""Errors of the joint readings as terms of a whole robot's model: the independent humanoid generator
(no robocal code) with an eccentric encoder disc on two joints, or a gear-ratio error on two, calibrated
with the held-out model selection (`--physics auto`).  A family the data carry is kept, its values
recovered within 2σ and the held-out error is at the noise floor; on data without the effect the
family is not kept.  The sidecar carries every term's σ and validates against its schema."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from humanoid_import import calibrated_tree, evaluate_at_noise_floor, import_humanoid

import independent_humanoid as hu

# extended (`make test-extended`, outside CI's 20-minute budget): the reading terms through `--physics auto` at full size; CI keeps test_diagnose_independent and test_diagnose_power_random (eccentricity named on independent campaigns)
pytestmark = pytest.mark.extended

pytest.importorskip("pinocchio")

ECC = {"left_j3": (3e-3, -2e-3), "right_j3": (-2e-3, 2.5e-3)}  # rad: δq = a·sin q + b·cos q
SCALE = {"left_j4": 4e-3, "right_j2": -3e-3}  # δq = s·q
ENCODER_GROUPS = ("encoder eccentricity", "joint scale", "joint coupling")


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("encoder")
    out = {}
    for name, kw in (("ecc", {"eccentricity": ECC}), ("scale", {"scale": SCALE}), ("none", {})):
        d = hu.write(tmp / name, seed=7, n=120, noise_m=2e-4, geometry=False, **kw)
        out[name] = (import_humanoid(d, tmp / f"{name}.mcap"), json.loads((d / "truth.json").read_text()))
    return tmp, out


def _calibrate(rec, out, physics, select=True):
    from pipeline.calibrate import calibrate
    from pipeline.identify.least_squares import FitOptions

    return calibrate(rec, out, FitOptions(), k_folds=3, physics=physics, select_groups=select)


def _schema():
    from pathlib import Path

    return json.loads((Path(__file__).resolve().parents[1] / "schemas" / "model_physics.schema.json").read_text())


def test_reading_terms_jacobian_matches_finite_differences(recordings):
    from pipeline.recording.reader import read_recording
    from pipeline.systems.registry import detect, load_with_physics

    _, recs = recordings
    r = read_recording(recs["ecc"][0])
    model, table = load_with_physics(detect(r), r, "encoder-eccentricity,joint-scale,joint-coupling", None)
    assert model.encoder and model.forced and not model.compliant
    assert {"left_j1.coupling", "left_j3.ecc_cos", "torso_j2.scale"} <= set(model.encoder)
    assert "torso_j1.coupling" not in model.encoder  # the first read joint has no driver
    data = {k: v[:30] for k, v in table.items()}
    x = model.initial_guess(data)
    names = model.parameter_names()
    rng = np.random.default_rng(1)
    terms = [names.index(n) for n in model.encoder]
    x[terms] = rng.uniform(-3e-3, 3e-3, len(terms))
    J = model.jacobian(x, data)
    for i in terms + [names.index("left_j3.offset")]:
        e = np.zeros_like(x)
        e[i] = 1e-6
        fd = (model.residuals(x + e, data) - model.residuals(x - e, data)) / 2e-6
        assert np.abs(fd - J[:, :, i]).max() <= 1e-6 * max(1.0, np.abs(J[:, :, i]).max()), names[i]


def test_eccentricity_kept_recovered_and_at_the_noise_floor(recordings):
    import jsonschema

    tmp, recs = recordings
    rec, truth = recs["ecc"]
    doc = _calibrate(rec, tmp / "out_ecc", "auto")
    assert "encoder eccentricity" in doc["model_selection"]["kept_groups"]
    assert doc["holdout_rms_m"] < 1.3 * truth["noise_m"], doc["holdout_rms_m"]
    p = {r["name"]: r for r in doc["parameters"]}
    for joint, (a, b) in ECC.items():
        for kind, v in (("ecc_sin", a), ("ecc_cos", b)):
            r = p[f"{joint}.{kind}"]
            assert r["identifiable"] and abs(r["estimate"] - v) <= 2 * r["std"], (joint, kind, r, v)
    assert doc["physics"]["holdout_geometry_only_m"] > 2 * doc["physics"]["holdout_with_physics_m"]
    side = yaml.safe_load((tmp / "out_ecc" / "model.physics.yaml").read_text())
    jsonschema.validate(side, _schema())
    assert side["version"] == 2
    by = {t["parameter"]: t for t in side["terms"] if "parameter" in t}
    assert by["left_j3.ecc_sin"]["std"] == pytest.approx(p["left_j3.ecc_sin"]["std"])
    assert by["left_j3.ecc_sin"]["unit"] == "rad"
    for t in side["terms"]:  # every compliance with its σ and its stiffness' σ (σ_c / c²)
        if "compliance_rad_per_Nm" in t and t["compliance_rad_per_Nm"] > 0:
            c, s = t["compliance_rad_per_Nm"], t["compliance_std_rad_per_Nm"]
            assert t["stiffness_std_Nm_per_rad"] == pytest.approx(s / c**2)
    assert [n["family"] for n in side["not_fitted"]] == ["backlash"]  # no direction of motion: said, not fitted
    model = json.loads((tmp / "out_ecc" / "model.json").read_text())
    assert model["physics"]["terms"] == side["terms"]


def test_no_reading_error_no_reading_terms(recordings):
    tmp, recs = recordings
    rec, truth = recs["none"]
    doc = _calibrate(rec, tmp / "out_none", "auto")
    kept = doc["model_selection"]["kept_groups"]
    assert not set(ENCODER_GROUPS) & set(kept), kept
    assert {r["candidate"] for r in doc["model_selection"]["rounds"]} >= set(ENCODER_GROUPS)  # offered
    assert doc["holdout_rms_m"] < 1.3 * truth["noise_m"]
    side = yaml.safe_load((tmp / "out_none" / "model.physics.yaml").read_text())
    assert not [t for t in side["terms"] if "parameter" in t]
    assert "direction of motion" in side["not_fitted"][0]["reason"]


def test_joint_scale_recovered_when_fitted(recordings):
    """The scale family fitted with the compliance (a list: always fitted), then applied by evaluate: the
    same robot's second session is predicted at the noise floor without refitting."""
    tmp, recs = recordings
    rec, truth = recs["scale"]
    doc = _calibrate(rec, tmp / "out_scale", "joint-compliance,lateral-compliance,joint-scale", select=False)
    assert doc["holdout_rms_m"] < 1.3 * truth["noise_m"], doc["holdout_rms_m"]
    p = {r["name"]: r for r in doc["parameters"]}
    for joint, s in SCALE.items():
        r = p[f"{joint}.scale"]
        assert r["identifiable"] and abs(r["estimate"] - s) <= 2 * r["std"], (joint, r, s)
        assert r["unit"] == "rad/rad"
    # evaluate applies the scale terms to a second session of the same robot (no refit): at the noise floor
    d2 = hu.write(tmp / "scale_s2", seed=7, n=60, noise_m=2e-4, geometry=False, session=2, scale=SCALE)
    rec2 = import_humanoid(d2, tmp / "scale_s2.mcap")
    evaluate_at_noise_floor(tmp / "out_scale", rec2, tmp / "ev_scale", truth["noise_m"])
    # compensate's kinematics of the calibrated tree (`TreeKinematics`, what its inverse kinematics solves)
    # carry the reading terms: at the second session's readings the left tip lands on the generator's
    # noise-free marker; with the scale terms zeroed it does not
    from pipeline.compensate.tree import TreeKinematics

    model, x = calibrated_tree(rec, "joint-compliance,lateral-compliance,joint-scale", doc)
    t = hu.default_truth(np.random.default_rng(7), geometry=False)
    t.scale = dict(SCALE)
    qd = hu.postures(np.random.default_rng(3), 20)
    want = hu.measure(t, qd, 0.0, np.random.default_rng(0))["left"]
    q = np.column_stack([qd[j] for j in hu.READ])
    rigid_scale = x.copy()
    rigid_scale[[i for i, n in enumerate(model.parameter_names()) if n.endswith(".scale")]] = 0.0
    kin = TreeKinematics(model, 0, True)
    err = {ph: np.sqrt(np.mean(np.sum((kin.pose(v, q)[1] - want) ** 2, axis=1)))
           for ph, v in ((True, x), (False, rigid_scale))}
    assert err[True] < 0.5e-3 and err[True] < 0.25 * err[False], err
