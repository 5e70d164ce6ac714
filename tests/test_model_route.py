"""`--model-choice auto` (the default of `robocal run` / `calibrate`): which route a recording takes.

A URDF robot imported from a CSV table (here: points of a perturbed six-joint arm measured by yourdfpy's
forward kinematics, tests/test_evaluate.py's generator) takes shrinkage toward nominal, says so in
results.json and the printed table, and recovers the arm to the noise floor; the route depends on the data
and the model only — a simulated campaign of the same robot takes shrinkage too — while the seed papers'
reference systems keep the group selection, as do trees and cameras; an unknown choice is a one-line error
(exit 2).  On real data: tests/test_physics_choice.py runs FIGAROH's TIAGo protocol through
`robocal calibrate`'s default (shrinkage taken, every held-out session at or below FIGAROH's full model).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_evaluate import NOISE, _frame, _recording, _truth_urdf

from conftest import run_cli
from test_bad_input import assert_one_line_error
from pipeline.errors import RobocalError
from pipeline.identify.route import resolve

REPO = Path(__file__).resolve().parents[1]


class _Model:
    residual_unit = "m"


class _Camera:
    residual_unit = "px"


@pytest.mark.parametrize("system", ["arc-welder", "scorbot-scanner", "delta-tracker"])
def test_seed_systems_keep_the_group_selection(system):
    r = resolve("auto", system, _Model())
    assert r["route"] == "groups" and r["asked"] == "auto" and system in r["reason"]


def test_single_chain_urdf_takes_shrinkage_trees_and_cameras_keep_groups():
    assert resolve("auto", "urdf", _Model())["route"] == "shrinkage"
    assert resolve("auto", "urdf", _Camera())["route"] == "groups"
    assert resolve("auto", "urdf", _Model(), tree=True)["route"] == "groups"  # several tips / coupled joints
    for asked in ("groups", "shrinkage"):  # asked for: taken as asked, whatever the system
        assert resolve(asked, "arc-welder", _Model())["route"] == asked
        assert resolve(asked, "urdf", _Model())["route"] == asked
    with pytest.raises(RobocalError, match="expected auto, groups, shrinkage"):
        resolve("ridge", "urdf", _Model())


def test_unknown_model_choice_is_one_line(tmp_path):
    for cmd in ("calibrate", "run"):
        proc = run_cli(cmd, REPO / "recordings" / "arc-welder-touch.mcap", "--model-choice", "ridge",
                       "--out", tmp_path / cmd)
        assert_one_line_error(proc, "--model-choice", "'ridge' is not one of 'auto', 'groups', 'shrinkage'")


def test_imported_csv_takes_shrinkage_by_default_and_says_so(tmp_path):
    rec = _recording(tmp_path, "imp", 60, 31, _frame(0.2, [0.8, -0.3, 0.1]), truth=_truth_urdf())  # origins off by mm
    proc = run_cli("calibrate", rec, "--out", tmp_path / "cal")
    assert proc.returncode == 0, proc.stderr
    assert "shrinkage (--model-choice auto)" in proc.stdout
    doc = json.loads((tmp_path / "cal" / "results.json").read_text())
    assert doc["model_choice"]["route"] == "shrinkage" and doc["model_choice"]["asked"] == "auto"
    assert doc["model_selection"]["method"].startswith("shrinkage")
    assert doc["rms_3d_after_m"] < 1.5 * NOISE * np.sqrt(3), doc["rms_3d_after_m"]
    assert doc["holdout_rms_3d_m"] < 2.0 * NOISE * np.sqrt(3), doc["holdout_rms_3d_m"]
