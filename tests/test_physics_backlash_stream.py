"""Backlash with the direction of approach taken from the joint stream, not from a column.

The independent humanoid generator (no robocal code) with a free play on two joints; its postures written
as a ROS 2 bag by rosbags' own writer (`independent_joint_bag`): a JointState stream in which each joint
reaches each posture from the generator's side (±1), markers on one PointStamped topic per hand, no
direction anywhere in the bag.  The import derives each joint's direction (the sign of its last motion),
equal to the generator's; `--physics auto` keeps the play, recovers it within 2σ, the held-out error is
at the noise floor and the geometry-only fit is clearly worse.  A robocal recording with an encoder stream
and no direction field (`robocal simulate urdf --drive`, and the same campaign acquired by `robocal acquire`
over a pty) gets its directions from the stream at load;
an explicit ``approach`` field wins over the stream; a stream that does not decode leaves the directions
unknown and every measurement loaded."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_cli

import independent_humanoid as hu
import independent_joint_bag as jb

# extended (`make test-extended`, outside CI's 20-minute budget): backlash from a streamed encoder at full size; CI keeps test_physics_backlash
pytestmark = pytest.mark.extended

pytest.importorskip("pinocchio")
pytest.importorskip("rosbags")

PLAY = {"left_j2": 4e-3, "right_j4": 3e-3}  # rad: δq = b·d/2
TOPICS = {"left_hand": "/mocap/left_hand", "right_hand": "/mocap/right_hand"}


def _postures(d):
    """(readings (n, J) in hu.READ order, directions (n, J), markers {link: (n, 3)}) from the generator's CSV."""
    lines = (d / "postures.csv").read_text().splitlines()
    head = lines[0].split(",")
    rows = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    col = {h: i for i, h in enumerate(head)}
    q = rows[:, [col[j] for j in hu.READ]]
    dirs = rows[:, [col[f"dir_{j}"] for j in hu.READ]]
    y = {"left_hand": rows[:, [col[c] for c in "lx ly lz".split()]],
         "right_hand": rows[:, [col[c] for c in "rx ry rz".split()]]}
    return q, dirs, y


def _bag_recording(tmp, name, storage="mcap", **kw):
    d = hu.write(tmp / name, seed=11, n=kw.pop("n", 120), noise_m=2e-4, geometry=False, **kw)
    q, dirs, y = _postures(d)
    bag = jb.write_bag(tmp / f"{name}.bag", hu.READ, q, dirs, {TOPICS[k]: v for k, v in y.items()}, storage)
    rec = tmp / f"{name}.mcap"
    r = run_cli("import", "ros2", bag, "--urdf", d / "humanoid.urdf", "--root", "base",
                "--coupled", "torso_j3=-torso_j1-torso_j2", "--measure-topic", f"left_hand={TOPICS['left_hand']}",
                "--measure-topic", f"right_hand={TOPICS['right_hand']}", "--out", rec)
    assert r.returncode == 0, r.stderr
    return rec, d, dirs


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("backlash_stream")
    rec, d, dirs = _bag_recording(tmp, "play", backlash=PLAY)
    return tmp, rec, json.loads((d / "truth.json").read_text()), dirs


def _load(rec, physics="auto"):
    from pipeline.recording.reader import read_recording
    from pipeline.systems.registry import detect, load_with_physics

    r = read_recording(rec)
    return load_with_physics(detect(r), r, physics, None)


def test_bag_directions_are_the_generators(played):
    _, rec, _, dirs = played
    model, table = _load(rec)
    order = np.lexsort((table["target"], table["timestamp_ns"]))
    got = np.asarray(table["approach"])[order][::2]  # both hands of a posture share its directions
    assert np.array_equal(got, dirs.astype(np.int8))
    assert {f"{j}.backlash" for j in hu.READ} <= set(model.encoder) and not model.absent
    from pipeline.recording.reader import read_recording

    camp = read_recording(rec).meta("robocal.campaign")
    assert "last motion" in camp["ros2"]["approach"]


def test_play_from_the_stream_recovered_at_the_noise_floor(played):
    tmp, rec, truth, _ = played
    r = run_cli("calibrate", rec, "--out", tmp / "auto")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp / "auto" / "results.json").read_text())
    assert "backlash" in doc["model_selection"]["kept_groups"], doc["model_selection"]
    p = {q["name"]: q for q in doc["parameters"]}
    for joint, b in PLAY.items():
        q = p[f"{joint}.backlash"]
        assert q["identifiable"] and abs(q["estimate"] - b) <= 2 * q["std"], (joint, q, b)
        assert q["std"] < 0.25 * b
    floor = truth["noise_m"]
    assert doc["holdout_rms_m"] < 1.3 * floor, doc["holdout_rms_m"]
    r = run_cli("calibrate", rec, "--out", tmp / "none", "--physics", "none")
    assert r.returncode == 0, r.stderr
    rigid = json.loads((tmp / "none" / "results.json").read_text())
    assert rigid["holdout_rms_m"] > 2 * floor and rigid["holdout_rms_m"] > 1.8 * doc["holdout_rms_m"], \
        (rigid["holdout_rms_m"], doc["holdout_rms_m"])


def test_sqlite3_bag_gives_the_same_directions(tmp_path):
    rec, _, dirs = _bag_recording(tmp_path, "sq", storage="sqlite3", n=12, directions=True)
    _, table = _load(rec, "none")
    order = np.lexsort((table["target"], table["timestamp_ns"]))
    assert np.array_equal(np.asarray(table["approach"])[order][::2], dirs.astype(np.int8))


@pytest.fixture(scope="module")
def drive_recording(tmp_path_factory):
    from test_urdf_compliance import URDF

    tmp = tmp_path_factory.mktemp("drive")
    (tmp / "r.urdf").write_text(URDF)
    out = tmp / "s.mcap"
    r = run_cli("simulate", "urdf", "--urdf", tmp / "r.urdf", "--root", "b", "--tip", "l6", "--poses", 20,
                "--seed", 3, "--drive", "--out", out)
    assert r.returncode == 0, r.stderr
    return tmp, out


def test_robocal_stream_gives_directions_at_load(drive_recording):
    """The simulated controller holds each posture and steps to the next: each joint's direction is the
    sign of its step, 0 for the first posture (nothing before it)."""
    _, out = drive_recording
    _, table = _load(out, "none")
    q = table["joint_positions"]
    want = np.vstack([np.zeros((1, q.shape[1])), np.sign(np.diff(q, axis=0))]).astype(np.int8)
    assert np.array_equal(table["approach"], want)


def test_explicit_direction_wins_over_the_stream(drive_recording):
    from pipeline.importers.recording import write_urdf_recording
    from pipeline.ingest.streams import joint_stream
    from pipeline.models import urdf
    from pipeline.recording.reader import read_recording

    tmp, out = drive_recording
    r = read_recording(out)
    _, table = _load(out, "none")
    meta = r.meta("robocal.urdf")
    desc = urdf.parse(meta["urdf"], meta["root"], meta["tip"])
    s = joint_stream(r)
    explicit = -np.asarray(table["approach"], np.int8)
    tab = {k: table[k] for k in ("joint_positions", "position", "target", "timestamp_ns")} | {"approach": explicit}
    write_urdf_recording(tmp / "explicit.mcap", desc, "point", {"n_targets": 1}, tab,
                         stream={"t_ns": s.t_ns, "q": s.q})
    _, got = _load(tmp / "explicit.mcap", "none")
    assert np.array_equal(got["approach"], explicit)


def test_a_damaged_stream_leaves_the_directions_unknown(drive_recording):
    """A stream that does not decode (a batch naming other joints) is validate's finding: the measurements
    still load, every one of them, without directions."""
    from pipeline.ingest.streams import joint_stream
    from pipeline.recording.reader import read_recording
    from pipeline.recording.schemas import META_CAMPAIGN, META_URDF
    from pipeline.recording.writer import RecordingWriter

    tmp, out = drive_recording
    r = read_recording(out)
    _, table = _load(out, "none")
    s = joint_stream(r)
    with RecordingWriter(tmp / "damaged.mcap") as w:
        w.metadata(META_URDF, r.meta(META_URDF))
        w.metadata(META_CAMPAIGN, r.meta(META_CAMPAIGN))
        for m in r.require("/measure/point"):
            w.write("/measure/point", m)
        half = len(s.t_ns) // 2
        w.write_batch(s.t_ns[:half], s.q[:half], list(s.names))
        w.write_batch(s.t_ns[half:], s.q[half:], [f"other_{n}" for n in s.names])
    damaged = read_recording(tmp / "damaged.mcap")
    with pytest.raises(Exception, match="differ from the first message"):
        joint_stream(damaged)
    _, got = _load(tmp / "damaged.mcap", "none")
    assert "approach" not in got
    assert np.array_equal(got["joint_positions"], table["joint_positions"])


def test_robocal_acquisition_gives_directions_at_load(drive_recording, tmp_path):
    """robocal's own acquisition (device-sim replaying the simulated campaign over a pty, `robocal acquire`):
    the acquired recording's stream gives each measurement the same directions as the source's."""
    from stream_support import record_over_pty

    _, src = drive_recording
    out, s, _ = record_over_pty(tmp_path, "urdf", ("--recording", str(src), "--speed", "20", "--batch", "4"))
    assert s["stop_reason"] == "campaign complete"
    _, want = _load(src, "none")
    _, got = _load(out, "none")
    assert np.array_equal(got["joint_positions"], want["joint_positions"])
    assert np.array_equal(got["approach"], want["approach"]) and np.abs(want["approach"]).sum() > 0
