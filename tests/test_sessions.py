"""Several recordings in one calibration, and a model choice that leaves out whole groups.

Sessions measured by yourdfpy's forward kinematics of a perturbed arm (tests/test_evaluate.py's
generator) in two instrument frames: one shared frame cannot serve both instruments (one-line error);
per-recording frames recover each frame and the robot to the noise floor; the merged recording keeps
every row and its time order is checked within sessions.  On real data (skipped where absent): the
shrinkage choice on one Panda placement leaves out whole sockets, never predicts a left-out socket worse
than registration only, and carries over to another placement far better than registration only.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_evaluate import NOISE, REAL, _frame, _panda_placement, _recording, needs_real

from conftest import run_cli
from test_bad_input import assert_one_line_error


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sessions")
    a = _recording(tmp, "a", 40, 21, _frame(0.3, [1.0, -0.5, 0.2]), "--instrument", "tracker-A")
    b = _recording(tmp, "b", 40, 22, _frame(-0.4, [0.2, 1.1, -0.1]), "--instrument", "tracker-B")
    return tmp, a, b


def test_one_shared_frame_refuses_two_instruments(sessions, tmp_path):
    _, a, b = sessions
    assert_one_line_error(run_cli("calibrate", a, b, "--out", tmp_path / "cal"), "different instruments",
                          "--registration per-recording")


def test_per_recording_frames_recover_each_instrument(sessions):
    tmp, a, b = sessions
    proc = run_cli("calibrate", a, b, "--registration", "per-recording", "--out", tmp / "cal")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp / "cal" / "results.json").read_text())
    est = {p["name"]: p["estimate"] for p in doc["parameters"]}
    assert abs(est["base.yaw"] + 0.3) < 1e-3 and abs(est["base.yaw@1"] - 0.4) < 1e-3, (est["base.yaw"], est["base.yaw@1"])
    assert doc["n_measurements"] == 80
    assert doc["rms_3d_after_m"] < 1.5 * NOISE * np.sqrt(3)
    # the merged recording holds every row of both, in order, and validates without a time-order warning
    from pipeline.recording.reader import read_recording
    from pipeline.systems.registry import detect

    merged = read_recording(tmp / "cal" / "merged.mcap")
    _, table = detect(merged).load(merged)
    ra, rb = (detect(r).load(r)[1] for r in (read_recording(a), read_recording(b)))
    np.testing.assert_array_equal(table["position"], np.vstack([ra["position"], rb["position"]]))
    np.testing.assert_array_equal(table["session"], np.r_[np.zeros(40), np.ones(40)])
    proc = run_cli("run", a, b, "--registration", "per-recording", "--stages", "ingest,validate", "--out", tmp / "run")
    assert proc.returncode == 0, proc.stderr
    checks = json.loads((tmp / "run" / "validate" / "validate.json").read_text())["checks"]
    assert all(c["status"] == "pass" for c in checks if c["name"].startswith("time")), checks
    # the robot fitted in both sessions predicts a third recording of instrument A in A's frame
    c = _recording(tmp, "c", 30, 23, _frame(0.3, [1.0, -0.5, 0.2]), "--instrument", "tracker-A")
    proc = run_cli("evaluate", tmp / "cal", c, "--out", tmp / "ev")
    assert proc.returncode == 0, proc.stderr
    rms = json.loads((tmp / "ev" / "evaluation.json").read_text())["recordings"][0]["rms_3d_m"]
    assert rms < 1.5 * NOISE * np.sqrt(3), rms


@needs_real
def test_shrinkage_leaves_out_whole_sockets_and_carries_over(tmp_path):
    train = _panda_placement(tmp_path, "panda_2", "front_center")
    other = _panda_placement(tmp_path, "panda_2", "mid_left")
    proc = run_cli("calibrate", train, "--model-choice", "shrinkage", "--out", tmp_path / "cal")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "cal" / "results.json").read_text())
    sel = doc["model_selection"]
    assert "whole groups" in sel["method"] and doc["holdout_kind"].startswith("whole groups")
    per = sel["holdout_per_group_m"]
    reg = per["registration only"]
    chosen = per[f"{sel['mu_m']:.6g}"]
    assert set(reg) == {"front_center/hole_0", "front_center/hole_1"}
    assert all(chosen[g] <= reg[g] for g in reg)  # never worse than registration only on a left-out socket
    proc = run_cli("evaluate", tmp_path / "cal", other, "--out", tmp_path / "ev_shrinkage")
    assert proc.returncode == 0, proc.stderr
    got = json.loads((tmp_path / "ev_shrinkage" / "evaluation.json").read_text())["recordings"][0]
    from pipeline.evaluate.apply import evaluate
    from pipeline.evaluate.calibrated import from_urdf
    from pipeline.recording.reader import read_recording

    nominal = evaluate(from_urdf(REAL / "mukca_panda" / "urdf" / "panda.urdf", "panda_link0", "ball_link",
                                 "coincidence"), [read_recording(other)])[0]
    assert got["rms_3d_m"] < 0.2 * nominal["rms_3d_m"], (got["rms_3d_m"], nominal["rms_3d_m"])


def test_headerless_coincidence_import_validates_without_a_time_warning(tmp_path):
    """The known-distance rows have no time of their own: no time-order warning over them."""
    from r6_robot import BARE_URDF

    urdf = tmp_path / "r6.urdf"
    urdf.write_text(BARE_URDF)
    rng = np.random.default_rng(5)
    files = []
    for k in (0, 1):
        f = tmp_path / f"hole_{k}.csv"
        f.write_text("\n".join(",".join(f"{v:.6f}" for v in rng.uniform(-1, 1, 6)) for _ in range(8)) + "\n")
        files.append(f)
    rec = tmp_path / "c.mcap"
    proc = run_cli("import", "csv", *files, "--urdf", urdf, "--root", "b", "--tip", "l6", "--measure", "coincidence",
                   "--columns", "j1,j2,j3,j4,j5,j6", "--distance", "hole_0:hole_1:0.05", "--out", rec)
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("run", rec, "--stages", "ingest,validate", "--out", tmp_path / "run")
    assert proc.returncode == 0, proc.stderr
    checks = {c["name"]: c for c in json.loads((tmp_path / "run" / "validate" / "validate.json").read_text())["checks"]}
    assert checks["time_order"]["status"] == "pass", checks["time_order"]
    assert "earlier than the previous" not in proc.stderr
