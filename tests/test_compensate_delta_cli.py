"""Compensation of the Delta (closed form on the calibrated β' model) and `robocal compensate`
end to end (targets CSV → program CSV, per-row status, report section, bad input)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from conftest import run_cli
from pipeline.compensate import delta as cd
from pipeline.identify.least_squares import fit
from pipeline.models import delta as dm
from pipeline.models import serial_arm
from pipeline.models.delta import Delta
from pipeline.simulate import delta_tracker as sim
from pipeline.systems import delta_tracker as dt
from pipeline.systems.delta_tracker import registration_matrix

# extended (`make test-extended`, outside CI's 20-minute budget): the Delta's compensation through the CLI; CI keeps the compensate guide's commands (tests/test_doc_blocks.py)
pytestmark = pytest.mark.extended


def true_platform_in_tracker(truth: sim.Truth, theta: np.ndarray) -> np.ndarray:
    p, _, ok = dm.full_forward(Delta(), truth.beta, theta, extended=True)
    R, t = registration_matrix(truth.registration)
    return (p - t) @ R


def test_delta_compensated_program_round_trips_and_is_within_1_2x_predicted_on_the_true_robot():
    truth = sim.random_truth(np.random.default_rng(5))
    s = sim.simulate(Delta(), truth, sim.Campaign(), sim.Noise())
    model = dt.TrackerModel()
    f = fit(model, {"joint_positions": s.q, "point": s.point_t})
    val = sim.simulate(Delta(), truth, sim.Campaign(points=1000, seed=77), sim.Noise(scale=0.0))
    targets = true_platform_in_tracker(truth, val.q)  # 1 000 new targets over the workspace, in {T}
    c = cd.compensate(model, f.nominal, f.x, targets)
    ok = c.status == "ok"
    assert ok.mean() > 0.95
    P, J = model.points(f.x, {"joint_positions": c.q[ok]})
    assert np.abs(P - targets[ok]).max() < 1e-9  # calibrated model's forward kinematics hits the targets
    before = np.linalg.norm(true_platform_in_tracker(truth, c.q_nominal[ok]) - targets[ok], axis=1)
    after = np.linalg.norm(true_platform_in_tracker(truth, c.q[ok]) - targets[ok], axis=1)
    Jf = J[:, :, f.free]
    sigma = np.sqrt(np.einsum("nip,pq,niq->n", Jf, f.cov, Jf))
    rms = lambda v: float(np.sqrt(np.mean(v**2)))  # noqa: E731
    assert rms(before) > 20 * rms(after)
    assert rms(after) <= 1.2 * rms(sigma), (rms(after), rms(sigma))
    # a nominal controller given the corrected target (its own frame {A}) computes the calibrated joints
    qn, okn = dm.inverse(model.delta, np.zeros(27), c.p_corrected[ok])
    assert np.abs(qn - c.q[ok]).max() < 1e-9


def test_delta_unreachable_target_is_reported():
    model = dt.TrackerModel()
    x = model.nominal()
    c = cd.compensate(model, x, x, np.array([[0.0, 0.0, -0.9], [50.0, 0.0, 0.0]]))
    assert c.status[1] == "unreachable"


@pytest.fixture(scope="module")
def arc_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("comp")
    assert run_cli("simulate", "arc-welder", "--out", d / "r.mcap", "--contacts", "60", "--seed", "2").returncode == 0
    r = run_cli("run", d / "r.mcap", "--out", d / "run")
    assert r.returncode == 0, r.stderr
    return d


def test_robocal_compensate_writes_a_program_that_round_trips(arc_run):
    from pipeline.systems import arc_welder as aw

    nominal = aw.nominal_arm()
    q = np.array([[0.1, 0.5, -0.3, 0.4, 0.8, 0.2], [-0.2, 0.4, -0.2, -0.5, 1.0, 1.0], [0.0, 0.6, -0.4, 0.2, 0.9, -0.5]])
    R, p = serial_arm.forward(nominal.vector(), q)
    from scipy.spatial.transform import Rotation
    quat = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]
    targets = arc_run / "targets.csv"
    with targets.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["name", "x", "y", "z", "qw", "qx", "qy", "qz"])
        for i in range(3):
            w.writerow([f"p{i}", *(repr(float(v)) for v in p[i]), *(repr(float(v)) for v in quat[i])])
        w.writerow(["far", 3.0, 3.0, 3.0, 1.0, 0.0, 0.0, 0.0])
    out = arc_run / "program.csv"
    r = run_cli("compensate", arc_run / "run", "--targets", targets, "--out", out)
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(out.open()))
    assert [row["status"] for row in rows] == ["ok", "ok", "ok", "unreachable"]
    x_cal = np.array(json.loads((arc_run / "run" / "identify" / "fit.json").read_text())["x"])
    qc = np.array([[float(row[f"q_J{k}"]) for k in range(1, 7)] for row in rows[:3]])
    Rc, pc = serial_arm.forward(x_cal, qc)
    assert np.abs(pc - p).max() < 1e-9 and np.abs(Rc - R).max() < 1e-9
    sig = [float(row["predicted_sigma_m"]) for row in rows[:3]]
    assert all(0 < v < 1e-3 for v in sig)
    doc = json.loads((arc_run / "run" / "compensation" / "compensation.json").read_text())
    assert doc["status_counts"] == {"ok": 3, "unreachable": 1}
    b95, s1 = doc["predicted_rms_bound95_m"], doc["predicted_sigma_rms_m"]
    assert s1 < b95 < 3 * s1  # the stated accuracy: the 95 % bound on this calibration's RMS, above the 1σ mean
    said = " ".join(r.stderr.split())
    assert f"predicted accuracy (95 %): tool-point RMS ≤ {b95 * 1e3:.4f} mm" in said, said
    r = run_cli("report", arc_run / "run", "--force", "--no-rrd")
    assert r.returncode == 0, r.stderr
    html = (arc_run / "run" / "report.html").read_text()
    assert 'id="compensation"' in html and "unreachable" in html
    assert f"Predicted accuracy (95 %)</b>: this calibration's RMS 3-D tool-point error over the program ≤ {b95 * 1e3:.4f} mm" in html


@pytest.mark.parametrize("text, message", [
    ("x,y\n0,0\n", "missing column(s) z"),
    ("x,y,z\n0.1,0.2,0.3\n0.1,abc,0.3\n", "row 2 (line 3), column y"),
    ("x,y,z,qw,qx,qy,qz\n0.1,0.2,0.3,2,0,0,0\n", "row 1 (line 2): quaternion norm"),
    ("x,y,z,qw\n0.1,0.2,0.3,1\n", "needs all of qw,qx,qy,qz"),
])
def test_bad_targets_fail_with_one_line_naming_file_and_row(arc_run, text, message):
    bad = arc_run / "bad.csv"
    bad.write_text(text)
    r = run_cli("compensate", arc_run / "run", "--targets", bad, "--out", arc_run / "never.csv")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert message in " ".join(r.stderr.split()) and "bad.csv" in r.stderr
    assert not (arc_run / "never.csv").exists()


def test_urdf_robot_compensated_program_end_to_end(tmp_path):
    """A URDF 6R arm ~1 mm / 1 mrad off its URDF, 120 tracker points (20 µm noise) imported and
    calibrated by `robocal run`; 50 position targets compensated: the true robot reaches them
    within 1.2× the predicted accuracy."""
    from test_compensate import URDF

    from pipeline.compensate.serial import ChainKinematics
    from pipeline.models.urdf import parse
    from pipeline.models.urdf_arm import UrdfArm

    (tmp_path / "robot.urdf").write_text(URDF)
    arm = UrdfArm(parse(URDF, "base", "tool"))
    kin = ChainKinematics.of(arm)
    rng = np.random.default_rng(1)
    x_true = arm.vector() + rng.normal(0, 1e-3, arm.vector().size)
    q = rng.uniform(-1, 1, (120, 6))
    q[:, 4] = rng.uniform(0.4, 1.2, 120)
    p = kin.pose(x_true, q)[1] + rng.normal(0, 2e-5, (120, 3))
    cols = ["x", "y", "z", *(f"j{i}" for i in range(1, 7))]
    (tmp_path / "data.csv").write_text(",".join(cols) + "\n" + "".join(
        ",".join(repr(float(v)) for v in [*pi, *qi]) + "\n" for pi, qi in zip(p, q)))
    qt = rng.uniform(-0.8, 0.8, (50, 6))
    qt[:, 4] = rng.uniform(0.5, 1.0, 50)
    pt = kin.pose(arm.vector(), qt)[1]
    (tmp_path / "targets.csv").write_text("x,y,z," + ",".join(f"q_j{i}" for i in range(1, 7)) + "\n" + "".join(
        ",".join(repr(float(v)) for v in [*pi, *qi]) + "\n" for pi, qi in zip(pt, qt)))
    assert run_cli("import", "csv", tmp_path / "data.csv", "--urdf", tmp_path / "robot.urdf", "--root", "base",
                   "--tip", "tool", "--measure", "point", "--out", tmp_path / "rec.mcap").returncode == 0
    # the stages compensate reads (ingest's model, identify's fit and covariance); a full run of an imported
    # URDF robot (diagnose, report) is test_report_urdf.py's
    r = run_cli("run", tmp_path / "rec.mcap", "--out", tmp_path / "run", "--stages", "ingest,validate,identify")
    assert r.returncode == 0, r.stderr
    r = run_cli("compensate", tmp_path / "run", "--targets", tmp_path / "targets.csv", "--out", tmp_path / "prog.csv")
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader((tmp_path / "prog.csv").open()))
    assert all(row["status"] == "ok" for row in rows)
    qc = np.array([[float(row[f"q_j{i}"]) for i in range(1, 7)] for row in rows])
    sig = np.array([float(row["predicted_sigma_m"]) for row in rows])
    rms = lambda v: float(np.sqrt(np.mean(v**2)))  # noqa: E731
    before = np.linalg.norm(kin.pose(x_true, qt)[1] - pt, axis=1)
    after = np.linalg.norm(kin.pose(x_true, qc)[1] - pt, axis=1)
    assert rms(before) > 1e-3 and rms(after) <= 1.2 * rms(sig), (rms(before), rms(after), rms(sig))
