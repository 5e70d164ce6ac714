"""Drive state in the encoder stream and compliance from measured joint torques.

Campaigns from the independent generator `independent_drive` (own FK of the URDF text, torques as
∂V/∂q of the potential energy by central differences, a payload the URDF does not describe):
the new `robocal.JointStateBatch` fields round-trip bit for bit (robocal's reader and mcap's standard
protobuf decoder); an unmodelled payload's compliance, which the URDF inertial model gets wrong, is
found and named from the measured torques with the held-out RMS back to the floor; a rigid robot with
efforts gives no finding; a ROS 2 bag (rosbags' writer) with JointState.effort is imported and
diagnosed; optional arrays of the wrong length or with NaN are one line naming file, channel, record.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

import independent_drive as gen
from stream_support import bits
from pipeline.diagnose import Settings, diagnose
from pipeline.diagnose.adapters.urdf_robot import adapter, from_recording
from pipeline.importers.recording import T0_NS, write_urdf_recording
from pipeline.ingest.streams import JOINT_STATE, joint_stream
from pipeline.models import urdf
from pipeline.recording import joint_state_batch as JSB
from pipeline.recording.reader import read_recording
from pipeline.recording.writer import RecordingWriter
from test_bad_input import assert_one_line_error
from test_urdf_compliance import URDF
from test_urdf_diagnose import point_campaign

ROOT = Path(__file__).resolve().parents[1]
S = Settings(n_boot=10, sign_flips=0)
DESC = urdf.parse(URDF, "b", "l6")
PAYLOAD_KG = 10.0  # at 5 cm along the tip's z: not in the URDF
C_J2 = 2e-6  # rad/(N·m): ~10× the minimum detectable size of this campaign


def cli(*args) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "pipeline", *map(str, args)], capture_output=True, text=True,
                          env=env, timeout=600)


K_NM_PER_A = np.array([40.0, 60.0, 50.0, 20.0, 20.0, 10.0])  # torque constants at the joints (N·m/A)


def recording(path: Path, seed: int, c_j2: float, payload_kg: float = PAYLOAD_KG, efforts: bool = True, n: int = 120,
              currents: bool = False, campaign: dict | None = None, desc=DESC):
    """Write an independent campaign (joint j2 of compliance c_j2 under the links and the payload) as a
    URDF recording with the drive state in its stream (efforts, or with `currents` motor currents =
    effort / K_NM_PER_A instead); return (model, diagnosis table) read back."""
    c = np.r_[0.0, c_j2, 0, 0, 0, 0]
    model, table = point_campaign(lambda q: gen.deflected(q, c, payload_kg), seed, n, 2e-5, text=URDF)
    q = table["joint_positions"]
    t = T0_NS + table["timestamp_ns"]
    stream = gen.standstill_stream(t, q, gen.holding_efforts(gen.deflected(q, c, payload_kg), payload_kg),
                                   np.random.default_rng(seed + 99), 0.05) if efforts or currents else None
    if currents:
        stream["current"] = stream.pop("effort") / K_NM_PER_A
    tab = {"joint_positions": q, "position": table["position"], "target": table["target"], "timestamp_ns": t}
    write_urdf_recording(path, desc, "point", {"n_targets": 1, **(campaign or {})}, tab, stream=stream)
    model, tab, _ = from_recording(read_recording(path))
    return model, tab


def run(model, tab) -> dict:
    return diagnose(model, tab, settings=S, adapter=adapter(model, tab, held=()))


# ----- (a) the schema: round trip, independent decoder, old recordings ------------------------------
def test_drive_state_round_trips_bit_for_bit_and_the_standard_decoder_reads_it(tmp_path):
    rng = np.random.default_rng(3)
    T, nj = 777, 6
    t = T0_NS + np.cumsum(rng.integers(1, 10**7, T))
    q, qc = rng.normal(0, 2, (T, nj)), rng.normal(0, 2, (T, nj))
    e, i = rng.normal(0, 50, (T, nj)), rng.normal(0, 3, (T, nj))
    e[0, 0], e[1, 1], qc[2, 2] = -0.0, 5e-324, np.finfo(float).max  # signed zero, subnormal, largest double
    names = [f"j{i + 1}" for i in range(nj)]
    path = tmp_path / "s.mcap"
    with RecordingWriter(path) as w:
        for s in range(0, T, 250):
            w.write_batch(t[s:s + 250], q[s:s + 250], names, q_cmd=qc[s:s + 250], effort=e[s:s + 250],
                          current=i[s:s + 250])
    s = joint_stream(read_recording(path))
    assert np.array_equal(s.t_ns, t) and np.array_equal(bits(s.q), bits(q))
    assert np.array_equal(bits(s.q_cmd), bits(qc)) and np.array_equal(bits(s.effort), bits(e))
    assert np.array_equal(bits(s.current), bits(i))

    from mcap_protobuf.decoder import DecoderFactory

    rows = []
    with open(path, "rb") as f:
        for _, _, _, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=[JOINT_STATE]):
            k = len(m.sample_offsets_ns)
            rows.append([np.array(v).reshape(k, nj) for v in (m.commanded_positions, m.efforts, m.motor_currents)])
    for col, want in enumerate((qc, e, i)):
        assert np.array_equal(bits(np.concatenate([r[col] for r in rows])), bits(want))


def test_a_stream_without_drive_state_and_an_older_registered_schema_still_read():
    """The bundled protobuf recording registers the schema of fields 1–6: accepted, no drive state."""
    rec = read_recording(ROOT / "recordings" / "arc-welder-touch-pb.mcap")
    assert not any(rec.registration.values())
    s = joint_stream(rec)
    assert s.q_cmd is None and s.effort is None
    older = JSB.file_descriptor()
    del older.message_type[0].field[6:]
    data = JSB.D.FileDescriptorSet(file=[older]).SerializeToString()
    assert JSB.descriptor_problem(JSB.SCHEMA_NAME, JSB.ENCODING, data) == ""
    wrong = JSB.file_descriptor()
    wrong.message_type[0].field[7].type = JSB._F.TYPE_FLOAT
    assert "field 8" in JSB.descriptor_problem(JSB.SCHEMA_NAME, JSB.ENCODING,
                                               JSB.D.FileDescriptorSet(file=[wrong]).SerializeToString())


# ----- (b) an unmodelled payload: found from the measured torques ---------------------------------
@pytest.mark.parametrize("seed", [0, 1])
def test_unmodelled_payload_compliance_is_found_from_measured_torques(tmp_path, seed):
    """j2 at 2e-6 rad/(N·m) under the links and a 10 kg payload the URDF lacks.  From the measured
    torques: the only finding, source "measured torque", within 10 % of the truth, held-out back to
    ≤ 1.2× the floor (the rigid robot's held-out geometric fit).  The URDF inertial model on the same
    measurements (efforts dropped) misjudges it: its j2 compliance is > 50 % off or it needs other terms."""
    model, tab = recording(tmp_path / "p.mcap", seed, C_J2)
    assert tab["joint_efforts"].shape == tab["joint_positions"].shape
    floor = run(*recording(tmp_path / "c.mcap", seed, 0.0))["holdout_rms_before_m"]
    doc = run(model, tab)
    (f,) = doc["findings"]
    assert (f["effect"], f["location"], f["source"]) == ("joint_compliance", "j2", "measured torque")
    assert abs(f["parameters"][0]["value"] / C_J2 - 1) < 0.1, f["parameters"]
    assert doc["holdout_rms_after_m"] <= 1.2 * floor
    inertial = run(model, {k: v for k, v in tab.items() if k not in ("joint_efforts", "commanded_positions")})
    j2 = [g for g in inertial["findings"] if (g["effect"], g["location"]) == ("joint_compliance", "j2")]
    assert all(g["source"] == "URDF inertials" for g in j2)
    assert not j2 or abs(j2[0]["parameters"][0]["value"] / C_J2 - 1) > 0.5 or len(inertial["findings"]) > 1


def test_a_urdf_without_inertials_gets_compliance_only_from_measured_torques(tmp_path):
    """The same robot described by a URDF with no `<inertial>` at all: the inertial model has no compliance
    candidate (nothing to find it with), the measured torques find j2 within 10 %."""
    from test_urdf_plan import URDF as BARE

    bare = urdf.parse(BARE, "b", "l6")
    model, tab = recording(tmp_path / "b.mcap", 3, C_J2, desc=bare)
    (f,) = run(model, tab)["findings"]
    assert (f["effect"], f["location"], f["source"]) == ("joint_compliance", "j2", "measured torque")
    assert abs(f["parameters"][0]["value"] / C_J2 - 1) < 0.1
    blind = run(model, {k: v for k, v in tab.items() if k not in ("joint_efforts", "commanded_positions")})
    assert not any(c["effect"] == "joint_compliance" for c in blind["candidates"])
    assert not any(g["effect"] == "joint_compliance" for g in blind["findings"])


# ----- (c) a rigid robot with efforts: no finding ----------------------------------------------------
@pytest.mark.parametrize("seed", [2, 3])
def test_rigid_robot_with_efforts_gives_no_finding(tmp_path, seed):
    model, tab = recording(tmp_path / "c.mcap", seed, 0.0)
    doc = run(model, tab)
    assert doc["findings"] == [], doc["findings"]
    assert any(c["effect"] == "joint_compliance" for c in doc["candidates"])


# ----- (d) a ROS 2 bag with JointState.effort --------------------------------------------------------
def test_ros2_bag_with_efforts_is_imported_and_diagnosed(tmp_path):
    """Stops of the compliant robot with the payload, written by rosbags' writer with each JointState's
    effort (joint names in another order plus a gripper joint); imported with `robocal import ros2`:
    the efforts are in the recording's stream, name-matched, and the diagnosis names j2's compliance
    from the measured torque."""
    from pipeline.measurements.point import PointModel
    from pipeline.models.urdf_arm import UrdfArm
    from pipeline.plan.urdf_robot import configurations
    from pipeline.simulate.ros2_bag import BagLayout, timeline, write_bag

    arm = UrdfArm(DESC)
    model = PointModel(arm)
    rng = np.random.default_rng(5)
    truth = model.nominal() + rng.normal(0, 5e-4, len(model.nominal()))
    truth[model.parameter_names().index("tool.z")] = 0.05
    c = np.r_[0.0, C_J2, 0, 0, 0, 0]
    stops = configurations(arm, 120, 6)
    q_true = gen.deflected(stops, c, PAYLOAD_KG)
    p, *_ = model.tool(truth, q_true)
    layout = BagLayout(rate_hz=50.0, move_s=0.5, dwell_s=0.6, name_order=(5, 4, 3, 2, 1, 0),
                       extra_joints={"finger": 0.01})
    t, q, t_meas, _ = timeline(stops, layout)
    _, effort, _, _ = timeline(gen.holding_efforts(q_true, PAYLOAD_KG), layout)
    effort = effort + rng.normal(0, 0.05, effort.shape)
    bag = tmp_path / "bag"
    write_bag(bag, DESC.joint_names, t, q, t_meas, p + rng.normal(0, 2e-5, p.shape), None, layout, effort=effort)
    robot = tmp_path / "r.urdf"
    robot.write_text(URDF)
    out = tmp_path / "r.mcap"
    proc = cli("import", "ros2", bag, "--urdf", robot, "--root", "b", "--tip", "l6", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "kept the efforts" in proc.stderr
    s = joint_stream(read_recording(out))
    assert s.names == tuple(DESC.joint_names) and s.effort.shape == s.q.shape
    model, tab, _ = from_recording(read_recording(out))
    assert np.allclose(-tab["joint_efforts"][:, 1], -gen.holding_efforts(q_true, PAYLOAD_KG)[:, 1], atol=0.05)
    doc = run(model, tab)
    (f,) = doc["findings"]
    assert (f["effect"], f["location"], f["source"]) == ("joint_compliance", "j2", "measured torque")
    assert abs(f["parameters"][0]["value"] / C_J2 - 1) < 0.1


def test_ros2_bag_with_nan_effort_imports_without_efforts_and_says_so(tmp_path):
    """Drivers publish NaN efforts for joints without torque sensing: the positions still import (the
    recording has no drive efforts) and a warning names the record; nothing fails."""
    from pipeline.simulate.ros2_bag import BagLayout, timeline, write_bag

    stops = np.zeros((3, 6)) + np.r_[0, 0.3, 0.2, 0, 0.1, 0]
    layout = BagLayout(rate_hz=20.0, move_s=0.5, dwell_s=0.6)
    t, q, t_meas, _ = timeline(stops, layout)
    effort = np.ones_like(q)
    effort[7, 3] = np.nan
    bag = tmp_path / "bag"
    write_bag(bag, DESC.joint_names, t, q, t_meas, np.zeros((3, 3)), None, layout, effort=effort)
    robot = tmp_path / "r.urdf"
    robot.write_text(URDF)
    p = cli("import", "ros2", bag, "--urdf", robot, "--root", "b", "--tip", "l6", "--out", tmp_path / "r.mcap")
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert "/joint_states: record 7" in p.stderr and "'j4' effort is NaN" in p.stderr and "not imported" in p.stderr
    _, tab, _ = from_recording(read_recording(tmp_path / "r.mcap"))
    assert "joint_efforts" not in tab and len(tab["joint_positions"]) == 3  # every stop imported, no efforts


# ----- (e) bad optional arrays: one line naming the record --------------------------------------------
@pytest.mark.parametrize("field,edit,why", [
    ("efforts", lambda m: m.efforts.extend([1.0] * 5), "efforts has 5 values, expected 250 samples × 6 joints"),
    ("commanded_positions", lambda m: m.commanded_positions.extend([0.0] * 1499 + [float("nan")]),
     "commanded_positions hold NaN or inf"),
])
def test_bad_drive_arrays_are_one_line_naming_file_channel_record(tmp_path, field, edit, why):
    """Message 1 of a recording's stream carries a drive array of the wrong length or a NaN: validate
    names it (schema check), and diagnose stops with one line naming file, channel and record."""
    src = tmp_path / "ok.mcap"
    recording(src, 4, 0.0, n=12)
    rec = read_recording(src)
    raw = list(rec.messages.raw[JOINT_STATE])
    assert len(raw) == 3
    m = JSB.JointStateBatch.FromString(raw[1])
    m.ClearField(field)
    edit(m)
    raw[1] = m.SerializeToString()
    assert JSB.bad_records(raw) == [(1, why)]
    bad = tmp_path / "bad.mcap"
    from pipeline.recording.schemas import META_CAMPAIGN, META_URDF, STREAM

    with RecordingWriter(bad) as w:
        for name in (META_URDF, META_CAMPAIGN):
            w.metadata(name, rec.metadata[name])
        for body in rec.messages["/measure/point"]:
            w.write("/measure/point", body)
        for i, body in enumerate(raw):
            t = JSB.JointStateBatch.FromString(body).timestamp_ns
            w._add(STREAM, w.channel(STREAM), t, t, body)
    assert_one_line_error(cli("diagnose", bad, "--out", tmp_path / "d"), str(bad), f"channel {JOINT_STATE}",
                          "record 1", why.split(" values")[0].split(" hold")[0])


def test_the_ingest_stage_keeps_the_drive_state_for_later_stages(tmp_path):
    """`encoder.parquet` carries the efforts and commanded positions bit for bit; the diagnosis table built
    from it (as the diagnose stage does) equals the one built from the MCAP."""
    from pipeline.stages.ingest import read_encoder
    from pipeline.stages.runner import run_pipeline

    src = tmp_path / "r.mcap"
    recording(src, 6, C_J2, n=20)
    run_pipeline(src, tmp_path / "run", stages=["ingest"])
    s, direct = read_encoder(tmp_path / "run"), joint_stream(read_recording(src))
    assert np.array_equal(bits(s.effort), bits(direct.effort)) and np.array_equal(bits(s.q_cmd), bits(direct.q_cmd))
    _, a, _ = from_recording(read_recording(src), s)
    _, b, _ = from_recording(read_recording(src))
    assert np.array_equal(bits(a["joint_efforts"]), bits(b["joint_efforts"]))


def test_simulate_urdf_drive_writes_the_true_robots_efforts(tmp_path):
    """`robocal simulate urdf --drive --compliance --payload-kg`: a gap-free stream whose efforts at each
    measurement are the independent generator's holding torques at the deflected joints (links and the
    payload), to the effort noise; commanded = read at standstill; bad options are one line."""
    robot = tmp_path / "r.urdf"
    robot.write_text(URDF)
    out, truth = tmp_path / "s.mcap", tmp_path / "t.json"
    args = ("simulate", "urdf", "--urdf", robot, "--root", "b", "--tip", "l6", "--poses", 30, "--seed", 2)
    proc = cli(*args, "--out", out, "--truth", truth, "--drive", "--compliance", "j2=3e-6",
               "--payload-kg", 7, "--payload-com", "0.02,0,0.06")
    assert proc.returncode == 0, proc.stderr
    model, tab, _ = from_recording(read_recording(out))
    c = np.r_[0.0, 3e-6, 0, 0, 0, 0]
    want = gen.holding_efforts(gen.deflected(tab["joint_positions"], c, 7.0, (0.02, 0, 0.06)), 7.0, (0.02, 0, 0.06))
    assert np.abs(tab["joint_efforts"] - want).max() < 0.02  # 0.05 N·m per sample, 125 samples a mean
    assert np.allclose(tab["commanded_positions"], tab["joint_positions"], rtol=0, atol=1e-12)
    s = joint_stream(read_recording(out))
    assert np.diff(s.t_ns).max() <= 5 * np.median(np.diff(s.t_ns))  # no gaps for validate to warn about
    import json
    assert json.loads(truth.read_text())["compliance_rad_per_Nm"]["j2"] == 3e-6
    assert_one_line_error(cli(*args, "--out", tmp_path / "x.mcap", "--compliance", "j9=1e-6"), "--compliance", "j9")
    assert_one_line_error(cli(*args, "--out", tmp_path / "y.mcap", "--payload-kg", 3, "--measure", "plane"),
                          "--measure point or pose")


# ----- motor currents: per ampere, or through the campaign's torque constants -------------------------
def test_compliance_from_motor_currents_per_ampere_and_with_torque_constants(tmp_path):
    """Currents only (effort / k, k per joint): without torque constants j2's compliance is fitted per
    ampere (c·k, rad/A, source "motor current"); with the campaign's `torque_constants_Nm_per_A` the
    currents become torques at ingest and c itself is found (source "motor current × torque constant");
    a constant missing for a chain joint is one line."""
    model, tab = recording(tmp_path / "i.mcap", 0, C_J2, currents=True)
    assert "joint_efforts" not in tab and tab["joint_currents"].shape == tab["joint_positions"].shape
    (f,) = run(model, tab)["findings"]
    assert (f["effect"], f["location"], f["source"]) == ("joint_compliance", "j2", "motor current")
    assert f["parameters"][0]["unit"] == "rad/A" and abs(f["parameters"][0]["value"] / (C_J2 * 60.0) - 1) < 0.1
    k = dict(zip(DESC.joint_names, K_NM_PER_A.tolist()))
    model, tab = recording(tmp_path / "k.mcap", 0, C_J2, currents=True, campaign={"torque_constants_Nm_per_A": k})
    (f,) = run(model, tab)["findings"]
    assert (f["location"], f["source"]) == ("j2", "motor current × torque constant")
    assert f["parameters"][0]["unit"] == "rad/(N*m)" and abs(f["parameters"][0]["value"] / C_J2 - 1) < 0.1
    bad = tmp_path / "b.mcap"
    with pytest.raises(Exception, match="torque_constants_Nm_per_A has no finite value for j2, j3"):
        recording(bad, 1, 0.0, n=12, currents=True, campaign={"torque_constants_Nm_per_A": {"j1": 40.0}})
    assert_one_line_error(cli("diagnose", bad, "--out", tmp_path / "d"), str(bad), "torque_constants_Nm_per_A",
                          "j2, j3, j4, j5, j6")
