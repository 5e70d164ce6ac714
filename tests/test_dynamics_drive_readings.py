"""Drive logs as a controller writes them, not as a URDF describes the joints: motor-side encoder angles through
reductions (one reversed), a coupled wrist whose last motor turns two joints, another zero, no time column
(`--rate`), headers in another case, bare joint names in the effort table — imported by `robocal import csv
--measure effort` and read back as joint angles; a coupled motor's own friction and rotor inertia recovered from
torques of the independent generator (tests/independent_dynamics.py: Pinocchio's RNEA of a perturbed URDF, the
motor's friction written there); bad rates and scales refused with one line, exit 2.  The real TX40 log through
the guide's commands: tests/test_dynamics_tx40.py (extended)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import independent_dynamics as G
from conftest import run_cli
from pipeline.dynamics import design, identify as I, rigid_body as RB
from pipeline.dynamics.effort import number
from pipeline.errors import RobocalError
from pipeline.importers import joint_readings as JR
from pipeline.importers.csv_effort import read_logs
from pipeline.models import urdf as U

RATIO = np.array([32.0, -48.0, 45.0, 32.0])  # a2's drive reversed; motor 4 turns a3 and a4: θ4 = 32 (q3 + q4)
ZERO_A2 = np.pi / 6  # a2's encoder zero is π/6 from the URDF's
WORDS = ["--rate", "1000", "--position-scale", "a1=1/32,a2=-1/48,a3=1/45,a4=1/32",
         "--position-mix", "a4=a4-32/45*a3", "--position-offset", "a2=pi/6"]


@pytest.mark.parametrize("text, value", [("0.5", 0.5), ("1/32", 1 / 32), ("-1/48", -1 / 48), ("pi/2", np.pi / 2),
                                         ("-2*pi", -2 * np.pi), ("32/45", 32 / 45), ("1e-3", 1e-3), ("x", None),
                                         ("1/0", None), ("pi/", None)])
def test_numbers_as_an_engineer_writes_them(text, value):
    got = number(text)
    assert (got is None and value is None) or abs(got - value) < 1e-15


@settings(max_examples=60, deadline=None)
@given(st.integers(-10**6, 10**6), st.integers(1, 10**6), st.sampled_from(["", "-", "+"]))
def test_a_ratio_reads_as_its_quotient(a, b, sign):
    got = number(f"{sign}{a}/{b}") if a >= 0 else number(f"{a}/{b}")
    want = (-1 if sign == "-" and a >= 0 else 1) * a / b
    assert got is not None and abs(got - want) <= 1e-12 * max(1.0, abs(want))


def _motor_side(q: np.ndarray) -> np.ndarray:
    p = q * RATIO
    p[:, 1] = RATIO[1] * (q[:, 1] - ZERO_A2)
    p[:, 3] = RATIO[3] * (q[:, 2] + q[:, 3])
    return p


@pytest.fixture(scope="module")
def drive_log(tmp_path_factory):
    """2 s at 1 kHz of the generator's arm, written as its drives log it: motor angles, currents, no time."""
    d = tmp_path_factory.mktemp("drive")
    (d / "arm.urdf").write_text(G.ARM)
    t, q, v, a = G.trajectory(3, duration=2.0, rate=1000.0)
    head = ",".join(j.upper() for j in G.JOINTS)  # A1 … A4: another case than the URDF's
    np.savetxt(d / "pos.csv", _motor_side(q), delimiter=",", header=head, comments="", fmt="%.12g")
    np.savetxt(d / "cur.csv", np.sin(t[:, None] + np.arange(4)), delimiter=",", header=head, comments="", fmt="%.12g")
    np.savetxt(d / "timed.csv", np.column_stack([t, _motor_side(q)]), delimiter=",", header="t," + head, comments="",
               fmt="%.12g")
    np.savetxt(d / "short.csv", np.zeros((t.size - 1, 4)), delimiter=",", header=head, comments="", fmt="%g")
    return d, t, q


def test_motor_side_angles_of_a_coupled_wrist_without_times_read_back_as_joint_angles(drive_log):
    d, t, q = drive_log
    out = d / "rec.mcap"
    r = run_cli("import", "csv", d / "pos.csv", "--effort-csv", d / "cur.csv", "--urdf", d / "arm.urdf",
                "--root", "base", "--tip", "s4", "--measure", "effort", *WORDS, "--effort-scale",
                "a1=32,a2=-48,a3=1,a4=32", "--effort-mix", "a3=45*a3+32*a4", "--out", out)
    assert r.returncode == 0, r.stderr
    from pipeline.recording.reader import read_recording
    from pipeline.systems.urdf_dynamics import load

    model, table = load(read_recording(out))
    np.testing.assert_allclose(table["joint_positions"], q, atol=1e-9)  # the round trip: 12 digits in the CSV
    np.testing.assert_allclose(np.diff(table["timestamp_ns"]), 1_000_000)  # --rate 1000: 1 ms a row
    e = np.sin(t[:, None] + np.arange(4))
    np.testing.assert_allclose(table["joint_torques"][:, 2], 45 * e[:, 2] + 32 * e[:, 3], rtol=1e-5, atol=1e-5)
    assert model.motors == (("a4", (0.0, 0.0, 1.0, 1.0)),)  # motor 4's speed is q̇3 + q̇4, felt by a3 and a4


def test_the_readings_conversion_inverts_the_transmission():
    """q = M p + c from the words; the coupled motor's G is its row of M⁻¹ over the joint's own ratio."""
    doc = JR.declaration(JR.PositionSpec(("a1=1/32,a2=-1/48,a3=1/45,a4=1/32",), ("a2=pi/6",), ("a4=a4-32/45*a3",)),
                         G.JOINTS)
    q = np.random.default_rng(0).uniform(-1, 1, (50, 4))
    np.testing.assert_allclose(JR.convert(doc, G.JOINTS, _motor_side(q))[0], q, atol=1e-12)
    assert JR.coupled_motors(doc, G.JOINTS) == (("a4", (0.0, 0.0, 1.0, 1.0)),)
    assert JR.declaration(JR.PositionSpec(), G.JOINTS) is None and JR.coupled_motors(None, G.JOINTS) == ()


@pytest.mark.parametrize("case", ["joint_angles_assumed", "rate_with_times", "no_times_no_rate", "bad_rate",
                                  "rows_differ", "rate_ten_times_too_high"])
def test_a_wrong_rate_or_scale_is_one_line(drive_log, case):
    d, _, _ = drive_log
    desc = U.read(d / "arm.urdf", "base", "s4")
    pos = JR.declaration(JR.PositionSpec((WORDS[3],), (WORDS[7],), (WORDS[5],)), G.JOINTS)
    kw = {"joint_angles_assumed": dict(rate=1000.0), "rate_with_times": dict(rate=1000.0, positions=pos),
          "no_times_no_rate": dict(positions=pos), "bad_rate": dict(rate=-5.0, positions=pos),
          "rows_differ": dict(rate=1000.0, positions=pos), "rate_ten_times_too_high": dict(rate=10000.0,
                                                                                           positions=pos)}[case]
    first = d / ("timed.csv" if case == "rate_with_times" else "pos.csv")
    effort = d / ("short.csv" if case == "rows_differ" else "cur.csv")
    with pytest.raises(RobocalError) as e:
        read_logs(first, desc, None, effort, **kw)
    msg = str(e.value)
    expect = {"joint_angles_assumed": "motor-side angles? --position-scale", "rate_with_times": "--rate is for a "
              "table without one", "no_times_no_rate": "--rate HZ", "bad_rate": "expected the sample rate",
              "rows_differ": "1999 data rows", "rate_ten_times_too_high": "its URDF velocity limit"}[case]
    assert expect in msg and "\n" not in msg, msg


def test_one_encoder_glitch_is_not_a_wrong_rate(drive_log):
    """A single spike (a reading error at one row) moves a joint far faster than its limit for one step; the speed
    check judges the clock and the scale, which are systematic, so the log still reads."""
    d, t, q = drive_log
    p = _motor_side(q)
    p[700, 0] += 32 * 0.5  # half a radian at the joint for one row, 1 ms
    np.savetxt(d / "glitch.csv", p, delimiter=",", header=",".join(j.upper() for j in G.JOINTS), comments="",
               fmt="%.12g")
    desc = U.read(d / "arm.urdf", "base", "s4")
    pos = JR.declaration(JR.PositionSpec((WORDS[3],), (WORDS[7],), (WORDS[5],)), G.JOINTS)
    out = read_logs(d / "glitch.csv", desc, None, d / "cur.csv", rate=1000.0, positions=pos)
    assert out["q"].shape == q.shape


def test_positions_far_outside_the_limits_exit_2_naming_the_fix(drive_log):
    d, _, _ = drive_log
    r = run_cli("import", "csv", d / "pos.csv", "--effort-csv", d / "cur.csv", "--urdf", d / "arm.urdf", "--root",
                "base", "--tip", "s4", "--measure", "effort", "--rate", "1000", "--out", d / "bad.mcap")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    line = r.stderr.strip().splitlines()[-1]
    assert "far outside the URDF's limits" in line and "--position-scale JOINT=1/RATIO" in line, line
    assert not (d / "bad.mcap").exists()


def test_a_coupled_motors_friction_and_rotor_inertia_are_recovered_and_lower_the_held_out_error():
    """The generator's arm with motor 4 turning a3 and a4 (u = q̇3 + q̇4): its viscous, Coulomb and rotor inertia
    reach both joints' torques.  Modelled per joint only, the fit leaves them in the residual; with the motor's
    terms (from the position mix) they are recovered near their truth and the held-out error falls to the noise."""
    t, q, v, a = G.trajectory(5, duration=30.0, rate=100.0)
    tau, _ = G.efforts(5, t, q, v, a, noise=0.05)
    u, du = v[:, 2] + v[:, 3], a[:, 2] + a[:, 3]
    fvm, fcm, iam = 0.4, 0.8, 0.01
    motor = fvm * u + fcm * np.tanh(u / G.PRESLIDING) + iam * du
    tau[:, 2:] += motor[:, None]
    rb = RB.build(G.ARM, G.JOINTS)
    data = I.Data(t, q, tau, np.ones(4, bool))
    base = I.Choice(cutoff_hz=8.0, terms=design.Terms(coulomb_width=0.003))
    plain = I.identify(rb, data, (base,), solvers=("ols",))
    coupled = I.identify(rb, data, I.candidates_for(data, (("a4", (0.0, 0.0, 1.0, 1.0)),), (base,)), solvers=("ols",))
    got = dict(zip(coupled.names, coupled.theta))
    assert abs(got["a4.motor.fv"] - fvm) < 0.05 and abs(got["a4.motor.fc"] - fcm) < 0.05, got
    assert abs(got["a4.motor.Ia"] - iam) < 0.003, got
    assert I.rms(coupled.rms_cv) < 0.6 * I.rms(plain.rms_cv), (coupled.rms_cv, plain.rms_cv)
    assert replace(base.terms, motors=()) == base.terms  # the default model has no motor terms


def test_a_singular_position_conversion_is_one_line_on_import_and_in_a_recording(drive_log, tmp_path):
    """A mix that gives two joints the same combination of readings (a typo: a3=a4 beside a4=a4) has no inverse:
    refused at import with one line, exit 2, nothing written; a recording whose metadata declares one (hostile or
    damaged) is refused by `robocal run` with one line naming it, not a LinAlgError."""
    d, _, _ = drive_log
    out = tmp_path / "sing.mcap"
    r = run_cli("import", "csv", d / "pos.csv", "--effort-csv", d / "cur.csv", "--urdf", d / "arm.urdf", "--root",
                "base", "--tip", "s4", "--measure", "effort", "--rate", "1000", "--position-scale", WORDS[3],
                "--position-mix", "a3=a4", "--out", out)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert "singular" in r.stderr.strip().splitlines()[-1] and not out.exists(), r.stderr
    from pipeline.systems.urdf_dynamics import positions_doc

    bad = {"scale": {}, "offset": {}, "mix": {"a3": {"a4": 1.0}}}
    with pytest.raises(RobocalError, match="singular"):
        positions_doc(bad, list(G.JOINTS), "rec.mcap")
    with pytest.raises(RobocalError, match="positions must map"):
        positions_doc({"mix": {"a3": 2.0}}, list(G.JOINTS), "rec.mcap")
