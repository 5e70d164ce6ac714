"""Compensation of the Delta calibrated with the extended model (axis yaw/tilt, unequal rods):
damped Newton on the full model; round trip, agreement with the β' closed form, per-row status,
and `robocal compensate` end to end on a run whose robot metadata asks for the extended model.

The true robot is checked by `true_platform` below, a forward kinematics written here from the
geometry of docs/reference/systems/delta.md (rod constraints solved by scipy), sharing no robocal function."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from conftest import run_cli
from pipeline.compensate import delta as cd
from pipeline.compensate import delta_newton as dn
from pipeline.models import delta as dm
from pipeline.models.delta import Delta
from pipeline.simulate import delta_tracker as sim
from pipeline.simulate.delta_recording import write
from pipeline.systems import delta_tracker as dt

A, B, L1, L2, W = 0.200, 0.050, 0.350, 0.800, 0.050  # the nominal Delta of docs/reference/systems/delta.md, m
PHI = (np.pi / 2, np.pi, -np.pi / 2)


def _rz(a: float) -> np.ndarray:
    return Rotation.from_euler("z", a).as_matrix()


def true_platform(beta36: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Platform point (N, 3) m in {A} of the robot with 36 error parameters, one point at a time:
    leg i's two rods run from the elbow balls A + Q·l1·u(θ+Δθ) ± w·Q·y to the platform balls
    p + R_P·Rz(φ)·(b + Δb ± w·y), lengths l2 + Δl2 ± Δl2_diff/2, Q = Rz(Δγ)·Rx(Δα)."""
    E = np.asarray(beta36, float).reshape(3, 12)
    y = np.array([0.0, 1.0, 0.0])
    out = []
    for th in np.atleast_2d(theta):
        elbows, balls, lengths = [], [], []
        for i in range(3):
            dax, day, daz, dth, dl1, dl2, dbx, dby, dbz, dg, dal, dd = E[i]
            Q = _rz(dg) @ Rotation.from_euler("x", dal).as_matrix()
            psi = th[i] + dth
            arm = Q @ ((L1 + dl1) * np.array([np.cos(psi), 0.0, np.sin(psi)]))
            for s in (1.0, -1.0):
                elbows.append(_rz(PHI[i]) @ (np.array([A + dax, day, daz]) + arm + s * W * (Q @ y)))
                balls.append(_rz(PHI[i]) @ (np.array([B + dbx, dby, dbz]) + s * W * y))
                lengths.append(L2 + dl2 + s * dd / 2)

        def g(z, elbows=elbows, balls=balls, lengths=lengths):
            R = Rotation.from_rotvec(z[3:]).as_matrix()
            return [np.linalg.norm(z[:3] + R @ c - e) - ln for e, c, ln in zip(elbows, balls, lengths)]

        z = least_squares(g, np.array([0, 0, -0.75, 0, 0, 0]), xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        assert np.abs(g(z)).max() < 1e-12
        out.append(z[:3])
    return np.array(out)


def _truth_x(model: dt.TrackerModel, truth: sim.Truth) -> np.ndarray:
    x = model.nominal()
    x[:model.n_beta] = truth.beta
    x[model.n_beta:model.n_beta + 6] = truth.registration
    return x


def _to_tracker(reg: np.ndarray, p_a: np.ndarray) -> np.ndarray:
    """{A} → {T}: ᴬP = R·ᵀP + t with R = Rz·Ry·Rx of (rz, ry, rx) (written out here)."""
    R = Rotation.from_euler("ZYX", reg[3:]).as_matrix()
    return (p_a - reg[:3]) @ R


@pytest.fixture(scope="module")
def extended_truth():
    truth = sim.random_truth(np.random.default_rng(11), "full")
    rng = np.random.default_rng(3)
    theta = rng.uniform(np.radians(-20), np.radians(50), (40, 3))
    return truth, theta


def test_theta_jacobian_matches_central_differences(extended_truth):
    truth, theta = extended_truth
    _, J, ok = dn.point_and_jacobian(Delta(), truth.beta, theta[:10])
    assert ok.all()
    h = 1e-6
    fd = np.stack([(true_platform(truth.beta, theta[:10] + h * e) - true_platform(truth.beta, theta[:10] - h * e))
                   / (2 * h) for e in np.eye(3)], axis=2)
    assert np.abs(J - fd).max() < 1e-7 * np.abs(fd).max()
    p, R, _ = dm.full_forward(Delta(), truth.beta, theta[:10])  # = the Δθ_i columns of the β Jacobian
    Jb, _ = dm.full_jacobian(Delta(), truth.beta, theta[:10], p, R, np.zeros(3))
    assert np.abs(J - Jb[:, :, list(dn.THETA_COLUMNS)]).max() < 1e-12


def test_extended_compensation_round_trips_on_the_full_model(extended_truth):
    truth, theta = extended_truth
    assert np.abs(truth.beta.reshape(3, 12)[:, 9:]).max() > 1e-3  # the extended terms are there
    model = dt.TrackerModel(variant="extended")
    x = _truth_x(model, truth)
    targets = _to_tracker(truth.registration, true_platform(truth.beta, theta))
    c = cd.compensate(model, model.nominal(), x, targets)
    assert (c.status == "ok").all(), c.status
    reached = _to_tracker(truth.registration, true_platform(truth.beta, c.q))
    assert np.abs(reached - targets).max() < 1e-9
    assert np.abs(c.q - theta).max() < 1e-8  # the same (elbows-out) branch the targets came from
    # the β' closed form alone (what the simplified path would command) misses by the extended terms
    simple = dt.TrackerModel()
    xs = simple.nominal()
    xs[:27] = truth.beta.reshape(3, 12)[:, :9].ravel()
    xs[27:33] = truth.registration
    cs = cd.compensate(simple, simple.nominal(), xs, targets)
    miss = np.linalg.norm(_to_tracker(truth.registration, true_platform(truth.beta, cs.q)) - targets, axis=1)
    assert miss.max() > 1e-4


def test_extended_with_zero_extended_terms_agrees_with_the_closed_form():
    truth = sim.random_truth(np.random.default_rng(4), "simplified")  # extended terms exactly zero
    ext, simple = dt.TrackerModel(variant="extended"), dt.TrackerModel()
    xe, xs = _truth_x(ext, truth), simple.nominal()
    xs[:27] = truth.beta.reshape(3, 12)[:, :9].ravel()
    xs[27:33] = truth.registration
    q = np.random.default_rng(8).uniform(np.radians(-20), np.radians(50), (200, 3))
    p_a, _ = dm.forward(Delta(), xs[:27], q)
    targets = _to_tracker(truth.registration, p_a)
    ce = cd.compensate(ext, ext.nominal(), xe, targets)
    cs = cd.compensate(simple, simple.nominal(), xs, targets)
    assert (ce.status == "ok").all() and (cs.status == "ok").all()
    assert np.abs(ce.q - cs.q).max() < 1e-9
    assert np.abs(ce.p_corrected - cs.p_corrected).max() < 1e-9


def test_extended_unreachable_and_out_of_travel_rows_are_reported_not_clipped(extended_truth):
    truth, theta = extended_truth
    model = dt.TrackerModel(variant="extended")
    x = _truth_x(model, truth)
    p_a = true_platform(truth.beta, np.vstack([theta[:2], np.radians([[-75.0, 10.0, 10.0]])]))
    p_a = np.vstack([p_a, [[0.0, 0.0, -1.6]], [[1.2, 0.0, -0.2]]])  # beyond full stretch; outside the reach
    c = cd.compensate(model, model.nominal(), x, _to_tracker(truth.registration, p_a))
    assert list(c.status) == ["ok", "ok", "out_of_limits", "unreachable", "unreachable"]
    assert (c.error_m[3:] > 1e-3).all()  # the nearest joints miss: stated, not passed off as a solution


def _write_targets(path, p_t: np.ndarray) -> None:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["name", "x", "y", "z"])
        for i, p in enumerate(p_t):
            w.writerow([f"t{i}", *(repr(float(v)) for v in p)])


def test_robocal_compensate_extended_run_end_to_end(tmp_path):
    """Simulated true robot with extended errors, robot metadata asking for the extended model,
    `robocal run` (ingest, validate, identify), `robocal compensate`: the true robot at the
    program's joints is within the stated 95 % bound and far better than uncompensated."""
    rec, truth_path = tmp_path / "rec.mcap", tmp_path / "truth.json"
    r = run_cli("simulate", "delta-tracker", "--out", rec, "--truth", truth_path, "--truth-model", "full",
                "--model-variant", "extended", "--points", "150", "--seed", "3")
    assert r.returncode == 0, r.stderr
    r = run_cli("run", rec, "--out", tmp_path / "run", "--stages", "ingest,validate,identify")
    assert r.returncode == 0, r.stderr
    fit = json.loads((tmp_path / "run" / "identify" / "fit.json").read_text())
    assert "leg1.dgamma" in fit["names"]  # the run calibrated the extended model
    par = json.loads(truth_path.read_text())["parameters"]
    beta = np.array([par[n] for n in dm.beta_names(3, extended=True)])
    reg = np.array([par[f"tracker.{a}"] for a in ("x", "y", "z", "rz", "ry", "rx")])
    box = np.random.default_rng(21).uniform([-0.15, -0.15, -0.79], [0.15, 0.15, -0.71], (30, 3))  # the campaign's
    theta, _ = dm.inverse(Delta(), np.zeros(27), box)
    targets = _to_tracker(reg, true_platform(beta, theta))  # 30 points of the true robot in the calibrated box
    _write_targets(tmp_path / "targets.csv", targets)
    r = run_cli("compensate", tmp_path / "run", "--targets", tmp_path / "targets.csv", "--out", tmp_path / "prog.csv")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    rows = list(csv.DictReader((tmp_path / "prog.csv").open()))
    assert all(row["status"] == "ok" for row in rows)
    qc = np.array([[float(row[f"q_theta{k}"]) for k in (1, 2, 3)] for row in rows])
    after = np.linalg.norm(_to_tracker(reg, true_platform(beta, qc)) - targets, axis=1)
    # uncompensated: the nominal controller's inverse of the target, even with the true registration
    R = Rotation.from_euler("ZYX", reg[3:]).as_matrix()
    q_nom, _ = dm.inverse(Delta(), np.zeros(27), targets @ R.T + reg[:3])
    before = np.linalg.norm(_to_tracker(reg, true_platform(beta, q_nom)) - targets, axis=1)
    rms = lambda v: float(np.sqrt(np.mean(v**2)))
    doc = json.loads((tmp_path / "run" / "compensation" / "compensation.json").read_text())
    assert doc["status_counts"] == {"ok": 30}
    assert rms(after) <= doc["predicted_rms_bound95_m"], (rms(after), doc["predicted_rms_bound95_m"])
    assert rms(before) > 10 * rms(after), (rms(before), rms(after))
    print(f"extended Delta on the true robot: uncompensated {rms(before) * 1e3:.2f} mm -> compensated "
          f"{rms(after) * 1e3:.3f} mm RMS (stated 95 % bound {doc['predicted_rms_bound95_m'] * 1e3:.3f} mm, 1σ "
          f"{doc['predicted_sigma_rms_m'] * 1e3:.3f} mm)")


def test_error_model_comes_from_the_robot_metadata_and_a_bad_one_is_one_line(tmp_path):
    from pipeline.errors import RobocalError
    from pipeline.recording.reader import read_recording

    truth = sim.random_truth(np.random.default_rng(2), "full")
    camp = sim.Campaign(points=12)
    for variant, n_beta in (("extended", 36), (None, 27)):
        write(tmp_path / f"{variant}.mcap", Delta(), truth, camp, error_model=variant)
        model, _ = dt.load(read_recording(tmp_path / f"{variant}.mcap"))
        assert model.n_beta == n_beta
    write(tmp_path / "bad.mcap", Delta(), truth, camp, error_model="bogus")
    with pytest.raises(RobocalError, match="error_model 'bogus' is not one of simplified, extended"):
        dt.load(read_recording(tmp_path / "bad.mcap"))
    r = run_cli("simulate", "delta-tracker", "--out", tmp_path / "x.mcap", "--model-variant", "bogus")
    assert r.returncode == 2 and "Traceback" not in r.stderr and "--model-variant must be" in r.stderr
    assert not (tmp_path / "x.mcap").exists()
