"""Backlash (free play) of a whole robot's joints: the independent humanoid generator (no robocal code)
with a play on two joints, each posture approached from a random side written as CSV columns
``dir_<joint>`` (−1/+1).  Calibrated with the held-out model selection (`--physics auto`): the play is
kept, recovered within 2σ and the held-out error is at the noise floor; with directions but no play the
family is not kept; the Jacobian columns match finite differences; a direction column with a value
other than −1/0/+1 (or NaN) is one line, exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from conftest import run_cli
from humanoid_import import calibrated_tree, evaluate_at_noise_floor, import_humanoid_run

import independent_humanoid as hu

pytest.importorskip("pinocchio")

PLAY = {"left_j2": 4e-3, "right_j4": 3e-3}  # rad: δq = b·d/2


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("backlash")
    out = {}
    for name, kw in (("play", {"backlash": PLAY}), ("dirs", {"directions": True})):
        d = hu.write(tmp / name, seed=11, n=120, noise_m=2e-4, geometry=False, **kw)
        r = import_humanoid_run(d, tmp / f"{name}.mcap")
        assert r.returncode == 0, r.stderr
        out[name] = (tmp / f"{name}.mcap", json.loads((d / "truth.json").read_text()), d)
    return tmp, out


def _calibrate(rec, out, physics):
    from pipeline.calibrate import calibrate
    from pipeline.identify.least_squares import FitOptions

    return calibrate(rec, out, FitOptions(), k_folds=3, physics=physics, select_groups=True)


def test_backlash_jacobian_matches_finite_differences(recordings):
    from pipeline.recording.reader import read_recording
    from pipeline.systems.registry import detect, load_with_physics

    _, recs = recordings
    r = read_recording(recs["play"][0])
    model, table = load_with_physics(detect(r), r, "backlash,joint-scale", None)
    assert {"left_j2.backlash", "right_j4.backlash"} <= set(model.encoder) and not model.absent
    assert set(np.unique(table["approach"])) == {-1, 1}
    rows = np.r_[np.flatnonzero(table["target"] == 0)[:15], np.flatnonzero(table["target"] == 1)[:15]]
    data = {k: v[rows] for k, v in table.items()}
    x = model.initial_guess(data)
    names = model.parameter_names()
    terms = [names.index(n) for n in model.encoder]
    x[terms] = np.random.default_rng(2).uniform(-3e-3, 3e-3, len(terms))
    J = model.jacobian(x, data)
    for i in terms:
        e = np.zeros_like(x)
        e[i] = 1e-6
        fd = (model.residuals(x + e, data) - model.residuals(x - e, data)) / 2e-6
        assert np.abs(fd - J[:, :, i]).max() <= 1e-6 * max(1.0, np.abs(J[:, :, i]).max()), names[i]
    for n in PLAY:  # the play moves the tip where a direction is known
        assert np.abs(J[:, :, names.index(f"{n}.backlash")]).max() > 1e-2, n
    unknown = dict(data, approach=np.zeros_like(data["approach"]))  # 0: unknown, the play adds nothing
    assert np.abs(model.jacobian(x, unknown)[:, :, [names.index("left_j2.backlash")]]).max() == 0


def test_backlash_kept_recovered_and_at_the_noise_floor(recordings):
    import jsonschema

    tmp, recs = recordings
    rec, truth, d = recs["play"]
    doc = _calibrate(rec, tmp / "out_play", "auto")
    assert "backlash" in doc["model_selection"]["kept_groups"], doc["model_selection"]
    assert doc["holdout_rms_m"] < 1.3 * truth["noise_m"], doc["holdout_rms_m"]
    p = {r["name"]: r for r in doc["parameters"]}
    for joint, b in PLAY.items():
        r = p[f"{joint}.backlash"]
        assert r["identifiable"] and abs(r["estimate"] - b) <= 2 * r["std"], (joint, r, b)
        assert r["std"] < 0.25 * b and r["unit"] == "rad"
    side = yaml.safe_load((tmp / "out_play" / "model.physics.yaml").read_text())
    from pathlib import Path

    schema = json.loads((Path(__file__).resolve().parents[1] / "schemas" / "model_physics.schema.json").read_text())
    jsonschema.validate(side, schema)
    assert side["not_fitted"] == []
    by = {t["parameter"]: t for t in side["terms"] if "parameter" in t}
    assert by["left_j2.backlash"]["std"] == pytest.approx(p["left_j2.backlash"]["std"])
    # evaluate applies the play to a second session of the same robot (its own directions): noise floor
    d2 = hu.write(tmp / "play_s2", seed=11, n=60, noise_m=2e-4, geometry=False, session=2, backlash=PLAY)
    assert import_humanoid_run(d2, tmp / "play_s2.mcap").returncode == 0
    evaluate_at_noise_floor(tmp / "out_play", tmp / "play_s2.mcap", tmp / "ev_play", truth["noise_m"])
    # compensate's kinematics (`TreeKinematics`, --approach): every joint approaching from above (+1), the
    # left tip lands on the generator's noise-free marker; taken as unknown (0, mid-play) it does not
    from pipeline.compensate.tree import TreeKinematics

    model, x = calibrated_tree(rec, "auto", doc)
    t = hu.default_truth(np.random.default_rng(11), geometry=False)
    t.backlash = dict(PLAY)
    qd = hu.postures(np.random.default_rng(3), 20)
    want = hu.measure(t, qd, 0.0, np.random.default_rng(0), approach={k: np.ones(20) for k in PLAY})["left"]
    q = np.column_stack([qd[j] for j in hu.READ])
    err = {a: np.sqrt(np.mean(np.sum((TreeKinematics(model, 0, True, a).pose(x, q)[1] - want) ** 2, axis=1)))
           for a in (1, 0)}
    assert err[1] < 0.5e-3 and err[1] < 0.5 * err[0], err


@pytest.mark.extended  # `make test-extended`: a second full backlash run; CI keeps test_backlash_kept_recovered_and_at_the_noise_floor
def test_no_play_not_kept(recordings):
    tmp, recs = recordings
    rec, truth, _ = recs["dirs"]
    doc = _calibrate(rec, tmp / "out_dirs", "auto")
    assert "backlash" in {r["candidate"] for r in doc["model_selection"]["rounds"]}  # offered
    assert "backlash" not in doc["model_selection"]["kept_groups"]
    assert doc["holdout_rms_m"] < 1.3 * truth["noise_m"]


@pytest.mark.parametrize("bad", ["2", "nan", "0.5"])
def test_bad_direction_column_one_line_exit_2(recordings, tmp_path, bad):
    _, recs = recordings
    d = recs["dirs"][2]
    lines = (d / "postures.csv").read_text().splitlines()
    head = lines[0].split(",")
    k = head.index("dir_left_j3")
    row = lines[5].split(",")
    row[k] = bad
    lines[5] = ",".join(row)
    (d / "bad.csv").write_text("\n".join(lines) + "\n")
    r = import_humanoid_run(d, tmp_path / "bad.mcap", "bad.csv")
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "Traceback" not in r.stderr, r.stderr
    assert "bad.csv: row 6: column 'dir_left_j3'" in r.stderr, r.stderr
    assert not (tmp_path / "bad.mcap").exists()


def test_compensate_approach_must_be_a_direction(tmp_path):
    (tmp_path / "t.csv").write_text("x,y,z\n0.1,0.2,0.3\n")
    r = run_cli("compensate", tmp_path / "no_run", "--targets", tmp_path / "t.csv", "--out", tmp_path / "p.csv",
                "--approach", "2")
    assert r.returncode == 2 and r.stderr.strip() == "robocal: error: --approach 2: expected -1, 0 or 1", r.stderr
    assert not (tmp_path / "p.csv").exists()
