"""A ROS 2 bag of a robot measured on several links: the independent humanoid generator's postures
written by rosbags' own rosbag2 writer (JointState of the read joints, one PointStamped topic per hand)
and imported with `--measure-topic LINK=TOPIC` per tip and `--coupled`.  The recording holds the same
measurements as the CSV import of the same data; bad tip input is one line, exit 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli
from test_bad_input import assert_one_line_error

import independent_humanoid as hu

T0_NS = 1_700_000_000_000_000_000
STEP_S = 2.0  # one posture every 2 s; the robot holds still around each measurement
TOPICS = {"left": "/mocap/left_hand", "right": "/mocap/right_hand"}


def write_bag(out: Path, q: np.ndarray, y: dict) -> Path:
    """rosbag2 (MCAP) of the postures: joint states at −0.3, 0, +0.3 s of each posture, both markers at 0."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.LATEST)
    T = store.types

    def header(t_ns: int, frame: str):
        return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9,
                                                                             nanosec=t_ns % 10**9), frame_id=frame)
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        cj = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        cm = {s: w.add_connection(t, "geometry_msgs/msg/PointStamped", typestore=store) for s, t in TOPICS.items()}
        for i in range(len(q)):
            t = T0_NS + int(i * STEP_S * 1e9)
            for dt in (-300_000_000, 0, 300_000_000):
                msg = T["sensor_msgs/msg/JointState"](header=header(t + dt, ""), name=list(hu.READ),
                                                      position=q[i], velocity=np.zeros(0), effort=np.zeros(0))
                w.write(cj, t + dt, bytes(store.serialize_cdr(msg, "sensor_msgs/msg/JointState")))
                if dt == 0:
                    for s, c in cm.items():
                        p = T["geometry_msgs/msg/Point"](x=float(y[s][i, 0]), y=float(y[s][i, 1]), z=float(y[s][i, 2]))
                        m = T["geometry_msgs/msg/PointStamped"](header=header(t, "mocap"), point=p)
                        w.write(c, t + 1000 * (1 + (s == "right")), bytes(store.serialize_cdr(m, c.msgtype)))
    return out


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    pytest.importorskip("rosbags")
    tmp = tmp_path_factory.mktemp("tree_bag")
    d = hu.write(tmp / "data", seed=2, n=20, noise_m=2e-4)
    rows = np.loadtxt(d / "postures.csv", delimiter=",", skiprows=1)
    q, y = rows[:, :len(hu.READ)], {"left": rows[:, -6:-3], "right": rows[:, -3:]}
    return d, write_bag(tmp / "bag", q, y)


@pytest.fixture(scope="module")
def bag_import(data, tmp_path_factory):
    """`robocal import ros2` of the bag, a measurement topic per tip (one run shared by the tests that read it)."""
    d, bag = data
    out = tmp_path_factory.mktemp("tree_bag_import") / "bag.mcap"
    r = run_cli("import", "ros2", bag, "--urdf", d / "humanoid.urdf", "--root", "base",
                "--coupled", "torso_j3=-torso_j1-torso_j2", "--measure-topic", f"left_hand={TOPICS['left']}",
                "--measure-topic", f"right_hand={TOPICS['right']}", "--out", out)
    assert r.returncode == 0, r.stderr
    return out


def _table(rec: Path):
    from pipeline.recording.reader import read_recording
    from pipeline.systems import urdf_robot

    model, table = urdf_robot.load(read_recording(rec), "none")
    order = np.lexsort((table["target"], table["timestamp_ns"]))
    return model, {k: np.asarray(table[k])[order] for k in ("joint_positions", "position", "target")}


def test_bag_with_a_topic_per_tip_matches_the_csv_import(data, bag_import, tmp_path):
    d, _ = data
    common = ["--urdf", d / "humanoid.urdf", "--root", "base", "--coupled", "torso_j3=-torso_j1-torso_j2"]
    c = run_cli("import", "csv", d / "postures.csv", *common, "--tip", "left_hand=lx,ly,lz",
                "--tip", "right_hand=rx,ry,rz", "--measure", "point", "--out", tmp_path / "csv.mcap")
    assert c.returncode == 0, c.stderr
    mb, tb = _table(bag_import)
    mc, tc = _table(tmp_path / "csv.mcap")
    assert mb.kin.tips == mc.kin.tips == ["left_hand", "right_hand"]
    assert mb.kin.coupling == mc.kin.coupling and "torso_j3" not in mb.kin.joint_names
    assert len(tb["target"]) == 40 and np.bincount(tb["target"]).tolist() == [20, 20]
    # the CSV import sorts rows by posture then tip; the bag's by time: same pairs of (joints, point, tip)
    kb = np.lexsort((tb["target"], *tb["joint_positions"].T[::-1]))
    kc = np.lexsort((tc["target"], *tc["joint_positions"].T[::-1]))
    for k in tb:
        np.testing.assert_allclose(tb[k][kb], tc[k][kc], rtol=0, atol=1e-9)


@pytest.mark.parametrize("args, needle", [
    (["--measure-topic", "left_hand=/nope", "--measure-topic", "right_hand=/mocap/right_hand"], "/nope"),
    (["--measure-topic", "left_hand=/mocap/left_hand", "--measure-topic", "/mocap/right_hand"], "LINK=TOPIC"),
    (["--measure-topic", "nose=/mocap/left_hand"], "nose"),
    (["--measure-topic", "left_hand=/mocap/left_hand", "--coupled", "torso_j3=-torso_j1-ghost"], "ghost"),
    (["--measure-topic", "left_hand=/mocap/left_hand", "--coupled", "torso_j3=-torso_j3"], "cycle"),
    (["--measure-topic", "left_hand=/joint_states"], "PointStamped"),
])
def test_bad_tip_input_is_one_line(data, tmp_path, args, needle):
    d, bag = data
    r = run_cli("import", "ros2", bag, "--urdf", d / "humanoid.urdf", "--root", "base", *args,
                "--out", tmp_path / "x.mcap")
    assert_one_line_error(r, needle)
    assert not (tmp_path / "x.mcap").exists()


def test_run_takes_the_whole_tree_bag_in_one_command(data, bag_import, tmp_path):
    """`robocal run BAG` with a measurement topic per tip: imported into the run folder (the same rows
    as `import ros2`), then identified on both hands' points."""
    import json

    d, bag = data
    out = tmp_path / "run"
    r = run_cli("run", bag, "--urdf", d / "humanoid.urdf", "--root", "base", "--coupled", "torso_j3=-torso_j1-torso_j2",
                "--measure-topic", f"left_hand={TOPICS['left']}", "--measure-topic", f"right_hand={TOPICS['right']}",
                "--physics", "none", "--stages", "ingest,validate,identify", "--folds", "3", "--out", out)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
    m_run, t_run = _table(out / "import" / "recording.mcap")
    _, t_imp = _table(bag_import)
    assert m_run.kin.tips == ["left_hand", "right_hand"] and "torso_j3" in m_run.kin.coupling
    for k in t_run:
        np.testing.assert_array_equal(t_run[k], t_imp[k])
    fit = json.loads((out / "identify" / "fit.json").read_text())
    assert fit["n_measurements"] == 40
    assert fit["holdout_rms_m"] < 5e-3  # both hands fitted by one tree model (geometry errors: mm)


@pytest.mark.parametrize("args, needle", [
    (["--measure-topic", "left_hand=/mocap/left_hand", "--measure-topic", "/mocap/right_hand"], "LINK=TOPIC"),
    (["--tip", "left_hand", "--measure-topic", "left_hand=/mocap/left_hand"], "--tip and --measure-topic"),
    (["--measure-topic", "left_hand=/mocap/left_hand", "--measure-topic", "left_hand=/mocap/right_hand"], "twice"),
    (["--measure-topic", "nose=/mocap/left_hand"], "nose"),
])
def test_run_bad_tip_input_is_one_line(data, tmp_path, args, needle):
    d, bag = data
    r = run_cli("run", bag, "--urdf", d / "humanoid.urdf", "--root", "base", *args, "--out", tmp_path / "run")
    assert_one_line_error(r, needle)
