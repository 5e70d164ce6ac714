"""The default model choice judges a ball-in-socket tool's ball centre free vs known by whole sockets left out.

Contacts made without robocal's code (`independent_ball`: the r6 arm, its joints solved so the true ball centre sits in
each of three sockets, checked by yourdfpy), imported with `robocal import csv --measure coincidence`: a ball centre
4 / −3 / 2 mm off its drawing is freed and recovered within its σ, and `robocal calibrate` → `robocal evaluate` of
other sockets applies it; a ball centre as drawn stays known or is recovered there; the campaign's explicit
``fit_tool`` (false or true) is honoured without a choice.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import independent_ball as ib
from pipeline.accuracy.prior import prior_sigma
from pipeline.identify.least_squares import FitOptions
from pipeline.identify.shrinkage import shrinkage_document
from pipeline.identify.shrinkage_fit import shrunk_fit
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import META_CAMPAIGN
from pipeline.systems.registry import detect
from conftest import run_cli

OFF = (0.004, -0.003, 0.102)  # m: the true ball centre in l6 (drawn at 0, 0, 0.1)
TOOL = ("tool.x", "tool.y", "tool.z")


def _recording(folder, ball, seed):
    data = ib.contacts(ib.ball_urdf(ball), seed=seed)
    for target, q in data:
        ib.check_with_yourdfpy(ib.ball_urdf(ball), target, q[:2], tol=1e-4)  # the generator as yourdfpy sees it
    (folder / "nominal.urdf").write_text(ib.ball_urdf())
    out = folder / "contacts.mcap"
    proc = run_cli("import", "csv", *ib.write_sockets(folder / "sockets", data), "--urdf", folder / "nominal.urdf",
                   "--root", "b", "--tip", "ball_link", "--measure", "coincidence", "--columns", ",".join(ib.JOINTS),
                   "--out", out)
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.fixture(scope="module")
def offset(tmp_path_factory):
    return _recording(tmp_path_factory.mktemp("offset"), OFF, seed=0)


def _choose(path, **campaign):
    rec = read_recording(path)
    rec.meta(META_CAMPAIGN).update(campaign)  # a campaign that says fit_tool (the import leaves it unsaid)
    model, data = detect(rec).load(rec)
    f, s, _ = shrunk_fit(model, data, FitOptions(prior_sigma=prior_sigma(model)[0]), k=2)
    i = [model.parameter_names().index(n) for n in TOOL]
    return f, s, i


def test_ball_centre_off_its_drawing_is_freed_and_recovered(offset):
    f, s, i = _choose(offset)
    truth = np.subtract(OFF, ib.NOMINAL_BALL)
    assert s.tool == "free" and shrinkage_document(s)["tool"] == "free"
    assert np.all(f.free[i]) and np.all(f.std[i] < 2e-5), f.std[i]
    assert np.all(np.abs(f.x[i] - truth) <= 3 * f.std[i]), (f.x[i], truth, f.std[i])


def test_ball_centre_as_drawn_stays_known_or_is_found_there(tmp_path):
    f, s, i = _choose(_recording(tmp_path, ib.NOMINAL_BALL, seed=1))
    assert s.tool in ("known", "free")
    if s.tool == "known":
        assert np.all(f.x[i] == 0) and not np.any(f.free[i])
    else:
        assert np.all(np.abs(f.x[i]) <= 3 * f.std[i]), (f.x[i], f.std[i])


def test_campaign_fit_tool_is_honoured_either_way(offset):
    f, s, i = _choose(offset, fit_tool=False)
    assert s.tool == "" and np.all(f.x[i] == 0) and not np.any(f.free[i])  # no choice: the ball stays as drawn
    assert "tool" not in shrinkage_document(s)
    f, s, i = _choose(offset, fit_tool=True)
    assert s.tool == "" and np.all(f.free[i])
    assert np.all(np.abs(f.x[i] - np.subtract(OFF, ib.NOMINAL_BALL)) <= 3 * f.std[i]), (f.x[i], f.std[i])


def test_calibrate_then_evaluate_applies_the_fitted_ball_centre(offset, tmp_path):
    other = _recording(tmp_path, OFF, seed=3)  # three other sockets, the same true ball
    proc = run_cli("calibrate", offset, "--out", tmp_path / "cal")
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / "cal" / "results.json").read_text())["model_selection"]["tool"] == "free"
    proc = run_cli("evaluate", tmp_path / "cal", other, "--out", tmp_path / "ev")
    assert proc.returncode == 0, proc.stderr
    got = json.loads((tmp_path / "ev" / "evaluation.json").read_text())["recordings"][0]
    assert got["rms_3d_m"] < 5e-5, got["rms_3d_m"]  # the joint noise (1e-5 rad): the ball centre as fitted
