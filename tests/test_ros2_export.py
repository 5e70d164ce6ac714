"""`robocal export ros2 REC.mcap --out BAG`: a real ROS 2 bag (rosbags' writer, MCAP storage), read back with
rosbags' own `AnyReader` (every message equal to what the recording holds), its transforms checked against
yourdfpy's forward kinematics of the URDF the bag carries (one tree: every frame one parent), and opened by
rerun's own MCAP importer (`rr.log_file_from_path`): the transforms and the robot's links by name.

Recordings: the real UR10e poses (../shared/real-data/figaroh_ur10_pose, imported by `robocal import csv`;
skips where absent) and a simulated torso + arm with its encoder stream (`robocal simulate urdf --drive`)."""

from __future__ import annotations

import io
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import run_cli

REPO = Path(__file__).resolve().parents[1]
UR10 = REPO.parent / "shared" / "real-data" / "figaroh_ur10_pose"


def _messages(bag: Path) -> dict[str, list]:
    """topic → [(log time ns, decoded message)] with rosbags' AnyReader; also the connections."""
    from rosbags.highlevel import AnyReader

    out: dict[str, list] = {}
    with AnyReader([bag]) as r:
        out["__connections__"] = {c.topic: c for c in r.connections}
        for c, t, raw in r.messages():
            out.setdefault(c.topic, []).append((t, r.deserialize(raw, c.msgtype)))
    return out


def _stamp(h) -> int:
    return h.stamp.sec * 1_000_000_000 + h.stamp.nanosec


def _matrix(tr) -> np.ndarray:
    T = np.eye(4)
    r, p = tr.transform.rotation, tr.transform.translation
    T[:3, :3] = Rotation.from_quat([r.x, r.y, r.z, r.w]).as_matrix()
    T[:3, 3] = (p.x, p.y, p.z)
    return T


def _tree(urdf: str, *tf_messages) -> dict[str, tuple[str, np.ndarray | None]]:
    """child → (parent, transform or None for a URDF joint), failing on a frame with two parents."""
    parent: dict[str, tuple[str, np.ndarray | None]] = {}
    for j in ET.fromstring(urdf).findall("joint"):
        parent[j.find("child").get("link")] = (j.find("parent").get("link"), None)
    for msg in tf_messages:
        for tr in msg.transforms:
            c, a = tr.child_frame_id, tr.header.frame_id
            assert parent.get(c, (a,))[0] == a, f"{c} has two parents: {parent[c][0]} and {a}"
            parent[c] = (a, _matrix(tr))
    return parent


def _pose(tree: dict, frm: str, to: str) -> np.ndarray:
    def up(f):
        T = np.eye(4)
        while f in tree and tree[f][1] is not None:
            T = tree[f][1] @ T
            f = tree[f][0]
        return T, f
    (A, a), (B, b) = up(frm), up(to)
    assert a == b, (frm, to, a, b)
    return np.linalg.inv(A) @ B


@pytest.fixture(scope="module")
def ur10(tmp_path_factory):
    if not UR10.is_dir():
        pytest.skip(f"real data not here: {UR10}")
    import sys

    sys.path.insert(0, str(REPO / "benchmarks"))
    from bench_real_data import import_args

    d = tmp_path_factory.mktemp("ur10bag")
    rec = d / "ur10.mcap"
    p = run_cli("import", "csv", *import_args("ur10", rec))
    assert p.returncode == 0, p.stderr
    p = run_cli("export", "ros2", rec, "--out", d / "bag")
    assert p.returncode == 0, p.stderr
    assert "/measure/pose: 23 geometry_msgs/msg/PoseStamped" in p.stderr
    return d, rec, _messages(d / "bag")


def test_every_message_reads_back_equal(ur10):
    from pipeline.recording.reader import read_recording

    d, rec, m = ur10
    r = read_recording(rec)
    meas = r.messages["/measure/pose"]
    conns = m["__connections__"]
    assert {t: c.msgtype for t, c in conns.items()} == {
        "/robot_description": "std_msgs/msg/String", "/tf_static": "tf2_msgs/msg/TFMessage",
        "/joint_states": "sensor_msgs/msg/JointState", "/tf": "tf2_msgs/msg/TFMessage",
        "/measure/pose": "geometry_msgs/msg/PoseStamped"}
    qos = conns["/robot_description"].ext.offered_qos_profiles[0]  # as robot_state_publisher offers it
    assert (qos.durability.name, qos.reliability.name, qos.history.name, qos.depth) == (
        "TRANSIENT_LOCAL", "RELIABLE", "KEEP_LAST", 1)
    assert conns["/tf_static"].ext.offered_qos_profiles[0].durability.name == "TRANSIENT_LOCAL"
    assert m["/robot_description"][0][1].data == r.metadata["robocal.urdf"]["urdf"]
    names = r.metadata["robocal.campaign"]["joint_names"]
    js = m["/joint_states"]
    assert len(js) == len(meas) == 23
    for (t, msg), want in zip(js, meas):
        assert t == _stamp(msg.header) == want["timestamp_ns"]
        assert list(msg.name) == names and msg.position.tolist() == want["joint_positions"]
    for (t, msg), want in zip(m["/measure/pose"], meas):
        assert t == _stamp(msg.header) == want["timestamp_ns"] and msg.header.frame_id == "robocal_instrument"
        p, o = msg.pose.position, msg.pose.orientation
        assert [p.x, p.y, p.z] == want["position"] and [o.x, o.y, o.z, o.w] == want["orientation"]


def test_transforms_are_the_urdfs_kinematics_in_one_tree(ur10):
    import yourdfpy

    _, _, m = ur10
    urdf = m["/robot_description"][0][1].data
    u = yourdfpy.URDF.load(io.StringIO(urdf), load_meshes=False)
    static = m["/tf_static"][0][1]
    for (t, js), (t2, tf) in zip(m["/joint_states"], m["/tf"]):
        assert t == t2
        tree = _tree(urdf, static, tf)
        assert tree["robocal_instrument"][0] == "base_link" and tree["base_link"][0] == "support_link"
        u.update_cfg(dict(zip(js.name, js.position)))
        for frm, to in (("world", "tool0"), ("base_link", "wrist_3_link"), ("support_link", "robocal_tool")):
            want = u.get_transform(to if to != "robocal_tool" else "tool0", frm)
            np.testing.assert_allclose(_pose(tree, frm, to), want, atol=1e-9)
    movable = {tr.child_frame_id for tr in m["/tf"][0][1].transforms}
    assert movable == {"shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link"}


def test_rerun_imports_the_bag_with_the_robot_and_its_transforms(ur10, tmp_path):
    """rerun's own MCAP importer: /tf and /tf_static as Transform3D with our frame names, the URDF of
    /robot_description loaded with its links by name."""
    import rerun as rr

    from test_rerun_rrd import _read

    d, _, m = ur10
    mcap = next((d / "bag").glob("*.mcap"))
    rec = rr.RecordingStream("robocal-test-export")
    rec.save(str(tmp_path / "bag.rrd"))
    rec.log_file_from_path(mcap)
    rec.flush()
    rec.disconnect()
    rrd = _read(tmp_path / "bag.rrd")
    flat = lambda rows: [v for row in rows for v in (row if isinstance(row, list) else [row])]  # noqa: E731
    children = flat(rrd["tf"]["rows"]["Transform3D:child_frame"])
    assert {"shoulder_link", "wrist_3_link"} <= set(children) and len(children) == 6 * len(m["/tf"])
    assert "robocal_instrument" in flat(rrd["tf_static"]["rows"]["Transform3D:child_frame"])
    links = {e.split("/")[2] for e in rrd if "/visual_geometries/" in e}
    assert {"shoulder_link", "upper_arm_link", "forearm_link", "wrist_3_link"} <= links


@pytest.fixture(scope="module")
def streamed(tmp_path_factory):
    """A simulated torso + arm with its encoder stream and measured efforts (`simulate urdf --drive`)."""
    from test_urdf_simulate import PR6

    d = tmp_path_factory.mktemp("streambag")
    (d / "r.urdf").write_text(PR6)
    rec = d / "sim.mcap"
    p = run_cli("simulate", "urdf", "--urdf", d / "r.urdf", "--root", "base", "--tip", "flange", "--measure", "point",
                "--poses", "6", "--drive", "--out", rec)
    assert p.returncode == 0, p.stderr
    p = run_cli("export", "ros2", rec, "--out", d / "bag")
    assert p.returncode == 0, p.stderr
    return d, rec, _messages(d / "bag")


def test_the_encoder_stream_becomes_joint_states_with_efforts(streamed):
    from pipeline.recording import joint_state_batch as JSB
    from pipeline.recording.reader import read_recording

    _, rec, m = streamed
    r = read_recording(rec)
    b = JSB.decode(r.messages.raw["/robot/joint_state"])
    js = m["/joint_states"]
    assert len(js) == len(b.t_ns) == len(m["/tf"]) > 100
    for i in range(0, len(js), max(1, len(js) // 20)):
        t, msg = js[i]
        assert t == _stamp(msg.header) == b.t_ns[i] and tuple(msg.name) == b.names
        assert msg.position.tolist() == b.q[i].tolist() and msg.effort.tolist() == b.effort[i].tolist()
    pts = m["/measure/point"]
    want = r.messages["/measure/point"]
    assert [p.point.x for _, p in pts] == [w["position"][0] for w in want]
    assert m["__connections__"]["/tf"].ext.offered_qos_profiles[0].depth == 100


def test_an_existing_folder_is_never_replaced_silently(streamed, tmp_path):
    """A folder robocal did not write: refused even with --force (one line, exit 2, untouched); a bag it
    exported: replaced only with --force, the old one kept as NAME.bak, never over an existing .bak."""
    from pipeline.errors import RobocalError
    from pipeline.ros2.export import export_bag

    d, rec, _ = streamed
    mine = tmp_path / "other"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    p = run_cli("export", "ros2", rec, "--out", mine, "--force")
    assert p.returncode == 2 and "was not written by robocal" in p.stderr and "Traceback" not in p.stderr
    assert (mine / "notes.txt").read_text() == "mine"
    bag = tmp_path / "bag"
    export_bag(rec, bag)
    with pytest.raises(RobocalError, match="--force"):
        export_bag(rec, bag)
    export_bag(rec, bag, force=True)
    assert (tmp_path / "bag.bak" / "metadata.yaml").is_file() and (bag / "metadata.yaml").is_file()
    with pytest.raises(RobocalError, match="bag.bak, which exists already"):
        export_bag(rec, bag, force=True)
    with pytest.raises(RobocalError, match="is a ROS 2 bag"):  # a bag is not a recording
        export_bag(d / "bag", tmp_path / "again")
