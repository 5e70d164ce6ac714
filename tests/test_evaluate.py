"""`robocal evaluate`: a calibrated model applied, without refitting, to recordings it never saw.

Truth from yourdfpy's own forward kinematics of a perturbed 6R arm (robocal's model never generates
the data): a calibration on one campaign predicts another campaign's points to the noise floor; a moved
instrument is seen as error unless `--refit registration`; errors.parquet holds one row per
measurement whose norms give the headline; bad input is one line, exit 2.  On real data (skipped where
../shared/real-data is absent): MUKCa's published calibrated Panda is evaluated on panda_2's placements
by robocal's code and by yourdfpy directly, to 1e-9 m; robocal's TIAGo calibration carries over to the
frozen protocol's other sessions better than FIGAROH's registration-only model.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yourdfpy
from r6_robot import BARE_URDF

from conftest import run_cli
from test_bad_input import assert_one_line_error
from real_data import real_data

REPO = Path(__file__).resolve().parents[1]
REAL = real_data()  # ../shared/real-data (tests/real_data.py)
needs_real = pytest.mark.skipif(not REAL.is_dir(), reason="../shared/real-data is absent (real datasets not shipped)")
JOINTS = [f"j{i}" for i in range(1, 7)]
NOISE = 20e-6  # m per axis
TOOL = np.array([0.03, -0.02, 0.05])  # tool point in l6, m


def _truth_urdf() -> str:
    """The r6 arm with its joint origins moved by a few mm (what the nominal URDF does not know)."""
    t = BARE_URDF.replace('<origin xyz="0.4 0 0"/>', '<origin xyz="0.403 0.002 -0.001"/>')
    t = t.replace('<origin xyz="0.35 0 0" rpy="0 1.5708 0"/>', '<origin xyz="0.348 0.001 0.002" rpy="0.003 1.5738 0"/>')
    return t.replace('<origin xyz="0 0 0.1" rpy="-1.5708 0 0"/>', '<origin xyz="0.002 0 0.1" rpy="-1.5728 0 0.002"/>')


def _measure(q: np.ndarray, frame: np.ndarray, rng, truth: str | None = None) -> np.ndarray:
    """Tool points of the true robot in an instrument frame (4×4 instrument → base), by yourdfpy."""
    import io

    u = yourdfpy.URDF.load(io.BytesIO((truth or _truth_urdf()).encode()), load_meshes=False, build_scene_graph=True,
                           build_collision_scene_graph=False, load_collision_meshes=False)
    base_in_instr = np.linalg.inv(frame)
    out = []
    for qi in q:
        u.update_cfg(dict(zip(JOINTS, qi)))
        T = u.get_transform("l6", "b")
        out.append((base_in_instr @ T @ np.r_[TOOL, 1.0])[:3])
    return np.asarray(out) + rng.normal(0, NOISE, (len(q), 3))


def _frame(yaw: float, t) -> np.ndarray:
    T = np.eye(4)
    T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    T[:3, 3] = t
    return T


def _recording(tmp: Path, name: str, n: int, seed: int, frame: np.ndarray, *extra: str, truth: str | None = None
               ) -> Path:
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.2, 1.2, (n, 6))
    p = _measure(q, frame, rng, truth)
    csv = tmp / f"{name}.csv"
    csv.write_text("x,y,z," + ",".join(JOINTS) + "\n" + "\n".join(",".join(f"{v:.9f}" for v in np.r_[pi, qi])
                                                                  for pi, qi in zip(p, q)) + "\n")
    urdf = tmp / "r6.urdf"
    urdf.write_text(BARE_URDF)
    out = tmp / f"{name}.mcap"
    proc = run_cli("import", "csv", csv, "--urdf", urdf, "--root", "b", "--tip", "l6", "--measure", "point",
                   "--out", out, *extra)
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("evaluate")
    f0 = _frame(0.3, [1.0, -0.5, 0.2])
    train = _recording(tmp, "train", 60, 1, f0, "--instrument", "tracker-A")
    proc = run_cli("calibrate", train, "--out", tmp / "cal")
    assert proc.returncode == 0, proc.stderr
    return tmp, f0, train


def test_calibration_predicts_new_configurations_to_the_noise_floor(calibrated):
    tmp, f0, train = calibrated
    test = _recording(tmp, "test", 40, 2, f0, "--instrument", "tracker-A")
    proc = run_cli("evaluate", tmp / "cal", test, train, "--out", tmp / "ev")
    assert proc.returncode == 0, proc.stderr
    assert "RMS of the 3-D error" in proc.stdout
    doc = json.loads((tmp / "ev" / "evaluation.json").read_text())
    new, same = doc["recordings"]
    floor = NOISE * np.sqrt(3)
    assert new["n"] == 40 and new["registration"] == "as calibrated"
    assert new["rms_3d_m"] < 1.5 * floor, new  # nothing refitted: geometry and registration carried over
    # the nominal robot (registration fitted, the user's "before") is far off at the same configurations
    res = json.loads((tmp / "cal" / "results.json").read_text())
    assert res["rms_3d_before_m"] > 20 * new["rms_3d_m"]
    # evaluating the calibration's own recording gives the fit's own 3-D RMS
    assert abs(same["rms_3d_m"] - res["rms_3d_after_m"]) < 1e-9
    # one row per measurement; the headline is the RMS of the rows' norms; per-axis RMS its own key
    t = pq.read_table(tmp / "ev" / "errors.parquet").to_pydict()
    rows = np.array(t["recording"]) == str(test)
    e = np.stack([np.array(t[f"e_{j}"])[rows] for j in range(3)], 1)
    assert rows.sum() == 40 and np.array_equal(np.array(t["record"])[rows], np.arange(40))
    np.testing.assert_allclose(np.array(t["norm_m"])[rows], np.linalg.norm(e, axis=1), rtol=1e-12)
    assert abs(np.sqrt(np.mean(np.sum(e**2, 1))) - new["rms_3d_m"]) < 1e-12
    assert abs(np.sqrt(np.mean(e**2)) - new["rms_axis_m"]) < 1e-12
    # posture groups relative to the training postures: the training recording is all "repeated"; the new
    # campaign (other random configurations) has none repeated; errors.parquet carries each row's group
    assert same["postures"] == {"repeated": {k: v for k, v in same.items() if k in same["postures"]["repeated"]}}
    assert "repeated" not in new["postures"] and sum(d["n"] for d in new["postures"].values()) == 40
    post = np.array(t["posture"], object)
    assert set(post[rows]) <= {"new", "out_of_range"} and set(post[~rows]) == {"repeated"}
    for g, d in new["postures"].items():
        assert abs(np.sqrt(np.mean(np.array(t["norm_m"])[rows][post[rows] == g] ** 2)) - d["rms_3d_m"]) < 1e-12
    # report.html: the evaluation as one page, rendered by a real browser
    from reprocess_support import chromium

    dom = chromium(["--dump-dom", (tmp / "ev" / "report.html").resolve().as_uri()], tmp)
    assert dom.returncode == 0, dom.stderr[-2000:]
    sec = dom.stdout[dom.stdout.index('<section id="evaluation">'):]
    sec = sec[:sec.index("</section>")]
    assert "test.mcap" in sec and "repeated postures" in sec and "RMS of the 3-D error (mm)" in sec
    assert f"{new['rms_3d_m'] * 1e3:.3f}" in sec and sec.count("<svg") == 1


def test_moved_instrument_is_error_unless_the_registration_is_refitted(calibrated):
    tmp, f0, _ = calibrated
    moved = _recording(tmp, "moved", 30, 3, _frame(0.31, [1.002, -0.5, 0.2]), "--instrument", "tracker-A")
    proc = run_cli("evaluate", tmp / "cal", moved, "--out", tmp / "ev_moved")
    assert proc.returncode == 0, proc.stderr
    as_cal = json.loads((tmp / "ev_moved" / "evaluation.json").read_text())["recordings"][0]
    assert as_cal["rms_3d_m"] > 1e-3  # 10 mrad and 2 mm of instrument motion
    proc = run_cli("evaluate", tmp / "cal", moved, "--refit", "registration", "--out", tmp / "ev_refit")
    assert proc.returncode == 0, proc.stderr
    refit = json.loads((tmp / "ev_refit" / "evaluation.json").read_text())["recordings"][0]
    assert refit["rms_3d_m"] < 1.5 * NOISE * np.sqrt(3), refit
    assert refit["registration"] == "refitted (shared)"
    # the re-estimated frame is the true one (instrument → base; base.yaw = -0.31 rad)
    assert abs(refit["registration_values"]["base.yaw"] + 0.31) < 1e-4


def test_shrinkage_carries_over_and_names_an_implausible_parameter(tmp_path):
    """--model-choice shrinkage: every parameter pulled toward nominal by its prior; a link 15 mm longer
    than its URDF says (7.5 prior σ) is still fitted, named in a warning, and the status is not pass."""
    truth = _truth_urdf().replace('<origin xyz="0.403 0.002 -0.001"/>', '<origin xyz="0.415 0.002 -0.001"/>')
    f0 = _frame(0.3, [1.0, -0.5, 0.2])
    train = _recording(tmp_path, "train", 60, 11, f0, truth=truth)
    test = _recording(tmp_path, "test", 30, 12, f0, truth=truth)
    proc = run_cli("calibrate", train, "--model-choice", "shrinkage", "--out", tmp_path / "cal")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "cal" / "results.json").read_text())
    sel = doc["model_selection"]
    assert [p["name"] for p in sel["implausible"]] == ["j3.x"], sel["implausible"]
    assert any(w.startswith("j3.x:") and "implausible" in w for w in doc["warnings"]), doc["warnings"]
    assert doc["status"] != "pass" and "j3.x" in doc["status_reason"]
    proc = run_cli("evaluate", tmp_path / "cal", test, "--out", tmp_path / "ev")
    assert proc.returncode == 0, proc.stderr
    got = json.loads((tmp_path / "ev" / "evaluation.json").read_text())["recordings"][0]["rms_3d_m"]
    assert got < 3 * NOISE * np.sqrt(3), got


def test_bad_input_is_one_line(calibrated, tmp_path):
    tmp, f0, train = calibrated
    # a folder without a calibrated model
    (tmp_path / "empty").mkdir()
    assert_one_line_error(run_cli("evaluate", tmp_path / "empty", train, "--out", tmp_path / "o1"),
                          "no calibrated model")
    # another instrument under the calibration's registration
    other = _recording(tmp_path, "other", 10, 4, f0, "--instrument", "tracker-B")
    assert_one_line_error(run_cli("evaluate", tmp / "cal", other, "--out", tmp_path / "o2"),
                          str(other), "'tracker-B'", "'tracker-A'")
    # … and two instruments under one shared re-estimated registration; per recording is fine
    assert_one_line_error(run_cli("evaluate", tmp / "cal", train, other, "--refit", "registration",
                                  "--out", tmp_path / "o3"), "'tracker-B'")
    proc = run_cli("evaluate", tmp / "cal", train, other, "--refit", "registration", "--registration",
                   "per-recording", "--out", tmp_path / "o4")
    assert proc.returncode == 0, proc.stderr
    # a recording of another robot (a chain of other joints)
    urdf = tmp_path / "two.urdf"
    urdf.write_text(BARE_URDF.replace('name="r6"', 'name="r6b"'))
    csv = tmp_path / "two.csv"
    csv.write_text("x,y,z," + ",".join(JOINTS) + "\n0.1,0.2,0.3,0,0,0,0,0,0\n")
    rec = tmp_path / "two.mcap"
    assert run_cli("import", "csv", csv, "--urdf", urdf, "--root", "b", "--tip", "l6", "--measure", "point",
                   "--out", rec).returncode == 0
    assert_one_line_error(run_cli("evaluate", tmp / "cal", rec, "--out", tmp_path / "o5"), str(rec), "'r6b'")
    # an output folder robocal did not write is not touched
    user = tmp_path / "mine"
    user.mkdir()
    (user / "notes.txt").write_text("keep")
    assert_one_line_error(run_cli("evaluate", tmp / "cal", train, "--out", user), str(user))
    assert (user / "notes.txt").read_text() == "keep" and len(list(user.iterdir())) == 1


# ----- real data ----------------------------------------------------------------------------------
def _panda_placement(tmp: Path, robot: str, place: str) -> Path:
    d = REAL / "mukca_panda"
    out = tmp / f"{robot}_{place}.mcap"
    proc = run_cli("import", "csv", *[d / "data" / robot / place / f"hole_{k}.csv" for k in (0, 1)],
                   "--urdf", d / "urdf" / "panda.urdf", "--root", "panda_link0", "--tip", "ball_link",
                   "--measure", "coincidence", "--group-from", "parent/file",
                   "--columns", ",".join(f"panda_joint{i}" for i in range(1, 8)),
                   "--distance", f"{place}/hole_0:{place}/hole_1:0.05", "--out", out)
    assert proc.returncode == 0, proc.stderr
    return out


@needs_real
def test_mukca_calibrated_panda_evaluated_as_yourdfpy_sees_it(tmp_path):
    """MUKCa's figure per socket: mean distance of the ball centres from their mean; robocal's code
    gives what yourdfpy's forward kinematics of MUKCa's URDF give."""
    from pipeline.evaluate.apply import evaluate
    from pipeline.evaluate.calibrated import from_urdf
    from pipeline.recording.reader import read_recording

    path = REAL / "mukca_panda" / "calibrated_urdf" / "panda_2" / "panda_calibrated.urdf"
    recs = [read_recording(_panda_placement(tmp_path, "panda_2", p)) for p in ("front_center", "high")]
    out = evaluate(from_urdf(path, "panda_link0", "ball_link", "coincidence"), recs)
    u = yourdfpy.URDF.load(str(path), load_meshes=False, build_scene_graph=True, build_collision_scene_graph=False,
                           load_collision_meshes=False)
    for r, place in zip(out, ("front_center", "high")):
        means = []
        for k in (0, 1):
            q = np.loadtxt(REAL / "mukca_panda" / "data" / "panda_2" / place / f"hole_{k}.csv", delimiter=",")
            p = []
            for qi in q:
                u.update_cfg(dict(zip([f"panda_joint{i}" for i in range(1, 8)], qi)))
                p.append(u.get_transform("ball_link", "panda_link0")[:3, 3])
            p = np.asarray(p)
            means.append(p.mean(0))
            g = r["groups"][f"{place}/hole_{k}"]
            assert abs(g["mean_3d_m"] - np.mean(np.linalg.norm(p - p.mean(0), axis=1))) < 1e-9
        d = np.linalg.norm(means[0] - means[1]) - 0.05
        assert abs(r["distances"][f"distance {place}/hole_0–{place}/hole_1"] - d) < 1e-9
    assert out[0]["mean_3d_m"] < 0.3e-3  # its training placement


@needs_real
def test_tiago_calibration_carries_over_to_other_sessions(tiago_frozen_protocol):
    """FIGAROH's frozen protocol: train on 2021-11-30, evaluate on the other sessions without refitting;
    robocal's automatic model beats FIGAROH's registration-only figures (4.87 / 4.58 / 4.22 mm)."""
    _, _, _, _, ev_dir = tiago_frozen_protocol  # imported, calibrated, evaluated once (conftest)
    got = [r["rms_3d_m"] for r in json.loads((ev_dir / "evaluation.json").read_text())["recordings"]]
    assert all(g < f for g, f in zip(got, (4.87e-3, 4.58e-3, 4.22e-3))), got
