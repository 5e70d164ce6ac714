"""The robot in every recording robocal writes, for ROS / Foxglove tools: /tf (foxglove.FrameTransforms,
JSON) and /robot_description (std_msgs/msg/String) plus the URDF attachment, read with the `mcap`
library's own reader and `json` (not robocal's reader), checked against yourdfpy's forward kinematics
of the URDF found in the recording itself; the bundled fixtures stay without them (byte-identical)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from scipy.spatial.transform import Rotation

from conftest import run_cli

REPO = Path(__file__).resolve().parents[1]


def _read(path: Path) -> dict:
    """topic -> {"schema": (name, encoding, data), "messages": [(log_time, decoded JSON)]}, and attachments."""
    out: dict = {"attachments": {}}
    with open(path, "rb") as f:
        r = make_reader(f)
        for schema, ch, m in r.iter_messages(log_time_order=True):
            e = out.setdefault(ch.topic, {"schema": (schema.name, schema.encoding, schema.data), "messages": []})
            if ch.message_encoding == "json":
                e["messages"].append((m.log_time, json.loads(m.data)))
    with open(path, "rb") as f:
        for a in make_reader(f).iter_attachments():
            out["attachments"][a.name] = (a.media_type, bytes(a.data))
    return out


def _matrix(t: dict) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([t["rotation"][k] for k in "xyzw"]).as_matrix()
    T[:3, 3] = [t["translation"][k] for k in "xyz"]
    return T


def _compose(transforms: list[dict], frm: str, to: str) -> np.ndarray:
    """Pose of frame `to` in frame `frm` by walking the parent → child transforms of one message up to
    the tree's top (each frame has one parent: a second is an error here)."""
    by_child: dict[str, dict] = {}
    for t in transforms:
        assert t["child_frame_id"] not in by_child, f"{t['child_frame_id']} has two parents"
        by_child[t["child_frame_id"]] = t

    def up(f: str) -> tuple[np.ndarray, str]:
        T = np.eye(4)
        while f in by_child:
            T = _matrix(by_child[f]) @ T
            f = by_child[f]["parent_frame_id"]
        return T, f

    (A, top_a), (B, top_b) = up(frm), up(to)
    assert top_a == top_b, (frm, to, top_a, top_b)
    return np.linalg.inv(A) @ B


def _check_tf(doc: dict, root: str, tip: str, joint_q_by_time: dict[int, np.ndarray], joint_names: list[str]) -> int:
    """Every /tf message at a measurement time: the chain root → tip composed from the transforms
    equals yourdfpy's forward kinematics of the recording's own URDF at that posture."""
    from pipeline.models.urdf import load_urdf_model

    name, enc, data = doc["/tf"]["schema"]
    assert (name, enc) == ("foxglove.FrameTransforms", "jsonschema")
    schema = json.loads(data)
    text = doc["/robot_description"]["messages"][0][1]["data"]
    assert doc["/robot_description"]["schema"][0] == "std_msgs/msg/String"
    assert doc["attachments"]["robot_description.urdf"] == ("application/xml", text.encode())
    u = load_urdf_model(text)
    checked = 0
    for t, msg in doc["/tf"]["messages"]:
        jsonschema.validate(msg, schema)
        tr = msg["transforms"]
        assert {x["timestamp"]["sec"] * 10**9 + x["timestamp"]["nsec"] for x in tr} == {t}
        for x in tr:
            q = [x["rotation"][k] for k in "xyzw"]
            assert abs(np.linalg.norm(q) - 1) < 1e-12
        if t not in joint_q_by_time:
            continue
        u.update_cfg(dict(zip(joint_names, joint_q_by_time[t])))
        np.testing.assert_allclose(_compose(tr, root, tip), u.get_transform(tip, root), atol=1e-9)
        assert _compose(tr, "robocal_instrument", "robocal_tool").shape == (4, 4)  # instrument and tool present
        checked += 1
    return checked


def test_urdf_simulation_carries_tf_and_the_urdf(tmp_path):
    from test_urdf_simulate import PR6

    u = tmp_path / "r.urdf"
    u.write_text(PR6)
    rec = tmp_path / "sim.mcap"
    p = run_cli("simulate", "urdf", "--urdf", u, "--root", "base", "--tip", "flange", "--measure", "point",
                "--poses", "12", "--out", rec)
    assert p.returncode == 0, p.stderr
    doc = _read(rec)
    meas = doc["/measure/point"]["messages"]
    qs = {t: np.array(m["joint_positions"]) for t, m in meas}
    from pipeline.models.urdf import parse

    names = parse(PR6, "base", "flange").joint_names
    assert _check_tf(doc, "base", "flange", qs, names) == len(meas) == 12
    # robocal itself still reads the recording and calibrates it
    p = run_cli("ingest", rec, "--out", tmp_path / "run")
    assert p.returncode == 0, p.stderr


def test_arc_welder_simulation_follows_the_encoder_stream(tmp_path):
    rec = tmp_path / "aw.mcap"
    p = run_cli("simulate", "arc-welder", "--out", rec, "--contacts", "10", "--seed", "3")
    assert p.returncode == 0, p.stderr
    doc = _read(rec)
    tf = doc["/tf"]["messages"]
    times = np.array([t for t, _ in tf])
    assert np.all(np.diff(times) > 0) and np.median(np.diff(times)) == pytest.approx(2e8, rel=0.05)  # ≈ 5 Hz
    from google.protobuf import descriptor_pb2, descriptor_pool
    from google.protobuf.message_factory import GetMessageClass

    t_all, q_all = [], []
    with open(rec, "rb") as f:  # the encoder samples, decoded with the schema the recording registers
        for schema, ch, m in make_reader(f).iter_messages(topics=["/robot/joint_state"]):
            if not t_all:
                fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
                pool = descriptor_pool.DescriptorPool()
                for fd in fds.file:
                    pool.Add(fd)
                cls = GetMessageClass(pool.FindMessageTypeByName(schema.name))
            b = cls.FromString(m.data)
            t_all.append(b.timestamp_ns + np.asarray(b.sample_offsets_ns, np.int64))
            q_all.append(np.asarray(b.positions).reshape(-1, len(b.joint_names)))
    t_all, q_all = np.concatenate(t_all), np.concatenate(q_all)
    at = {int(t): q_all[i] for i, t in enumerate(t_all) if int(t) in set(times[::50].tolist())}
    assert _check_tf(doc, "jig", "tool", at, [f"J{i}" for i in range(1, 7)]) == len(at) > 5


def test_bundled_recordings_are_unchanged():
    """The fixtures are never rewritten: no scene channels, bytes as git committed them."""
    import subprocess

    for path in sorted((REPO / "recordings").glob("*.mcap")):
        data = path.read_bytes()
        blob = hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()
        r = subprocess.run(["git", "ls-files", "-s", str(path)], cwd=REPO, capture_output=True, text=True)
        if r.returncode == 0 and r.stdout.split():
            assert r.stdout.split()[1] == blob, f"{path} differs from the committed fixture"
        with open(path, "rb") as f:
            topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
        assert "/tf" not in topics and "/robot_description" not in topics


def test_a_recording_written_as_it_comes_gets_the_scene_at_close(tmp_path):
    """The acquisition's writer (scene=True): /tf along the encoder stream written, added at close,
    and robocal's own reader still reads the encoder stream and metadata unchanged."""
    from pipeline.recording.reader import read_recording
    from pipeline.recording.schemas import META_ROBOT
    from pipeline.recording.writer import RecordingWriter
    from pipeline.systems import arc_welder as aw

    arm = aw.nominal_arm()
    t = 1_800_000_000_000_000_000 + np.arange(2500, dtype=np.int64) * 4_000_000  # 10 s at 250 Hz
    q = np.column_stack([0.3 * np.sin(t * 1e-9 + k) for k in range(6)])
    out = tmp_path / "live.mcap"
    with RecordingWriter(out, scene=True) as w:
        w.metadata(META_ROBOT, arm.to_dict())
        for s in range(0, t.size, 250):
            w.write_batch(t[s:s + 250], q[s:s + 250], [j.name for j in arm.joints])
    doc = _read(out)
    times = np.array([m[0] for m in doc["/tf"]["messages"]])
    assert len(times) == 50 and np.all(np.diff(times) == 200_000_000)
    at = {int(tt): q[i] for i, tt in enumerate(t) if int(tt) in set(times.tolist())}
    assert _check_tf(doc, "jig", "tool", at, [j.name for j in arm.joints]) == 50
    rec = read_recording(out)
    assert rec.metadata[META_ROBOT] == json.loads(json.dumps(arm.to_dict())) and not rec.warnings


def test_delta_simulation_carries_its_tree_and_closed_chain_transforms(tmp_path):
    """A Delta (closed chain) gets a URDF tree a viewer can load (parsed here by yourdfpy) and /tf whose
    transforms close the chain: yourdfpy's pose of each upper arm at the actuator angle equals /tf's,
    the arm's end (l1 along it) is the forearm's origin, each forearm reaches the platform's ball joint
    at l2, and the reflector hangs reflector_offset_m below the platform point."""
    import io

    import yourdfpy

    from pipeline.models.delta import Delta

    rec = tmp_path / "delta.mcap"
    p = run_cli("simulate", "delta-tracker", "--out", rec, "--points", "6", "--grid", "2", "2", "2", "--seed", "4")
    assert p.returncode == 0, p.stderr
    doc = _read(rec)
    (t0, desc), = doc["/robot_description"]["messages"]
    assert doc["/robot_description"]["schema"][0] == "std_msgs/msg/String"
    assert doc["attachments"]["robot_description.urdf"][1].decode() == desc["data"]
    robot = yourdfpy.URDF.load(io.StringIO(desc["data"]), build_scene_graph=True, load_meshes=False)
    assert {"actuator_1", "actuator_2", "actuator_3"} <= set(robot.actuated_joint_names)
    with open(rec, "rb") as f:
        meta = {m.name: json.loads(m.metadata["json"]) for m in make_reader(f).iter_metadata()}
    d = Delta.from_dict(meta["robocal.robot_model"])
    h = meta["robocal.fixture"]["reflector_offset_m"]
    tf = doc["/tf"]["messages"]
    assert len(tf) > 20
    checked = 0
    for _, m in tf[:: max(1, len(tf) // 25)]:
        tr = m["transforms"]
        plat = _compose(tr, "base", "platform")
        assert np.allclose(plat[:3, :3], np.eye(3), atol=1e-9)  # the nominal platform stays parallel to the base
        cfg = {}
        for i, phi in enumerate(d.phi, start=1):
            arm = _compose(tr, "base", f"upper_arm_{i}")
            # the actuator angle: elbow height over l1, from the arm's x axis
            cfg[f"actuator_{i}"] = float(np.arctan2(arm[2, 0], np.hypot(arm[0, 0], arm[1, 0])))
        robot.update_cfg(cfg)
        for i, phi in enumerate(d.phi, start=1):
            arm = _compose(tr, "base", f"upper_arm_{i}")
            assert np.allclose(robot.get_transform(f"upper_arm_{i}", "base"), arm, atol=1e-9)
            fore = _compose(tr, "base", f"forearm_{i}")
            assert np.allclose(arm[:3, :3] @ [d.l1, 0, 0] + arm[:3, 3], fore[:3, 3], atol=1e-9)
            ball = plat[:3, 3] + d.b * np.array([np.cos(phi), np.sin(phi), 0.0])
            assert np.allclose(fore[:3, :3] @ [d.l2, 0, 0] + fore[:3, 3], ball, atol=1e-6)
        tool = _compose(tr, "platform", "robocal_tool")
        assert tool[2, 3] == pytest.approx(-float(h)) and h > 0
        assert _compose(tr, "robocal_instrument", "robocal_tool").shape == (4, 4)
        checked += 1
    assert checked > 10


UR10 = REPO.parent / "shared" / "real-data" / "figaroh_ur10_pose"


@pytest.mark.skipif(not UR10.is_dir(), reason=f"real data not here: {UR10}")
def test_one_tree_where_the_root_link_has_a_parent(tmp_path):
    """The real UR10e's URDF has world → support_link → base_link: the recording's /tf hangs the
    instrument below base_link (as model.urdf does), so URDF joints and /tf together give every frame
    one parent and reach every /tf frame from the URDF's own top link."""
    import xml.etree.ElementTree as ET

    import sys

    sys.path.insert(0, str(REPO / "benchmarks"))
    from bench_real_data import import_args

    rec = tmp_path / "ur10.mcap"
    p = run_cli("import", "csv", *import_args("ur10", rec))
    assert p.returncode == 0, p.stderr
    doc = _read(rec)
    urdf = ET.fromstring(doc["/robot_description"]["messages"][0][1]["data"])
    parent = {j.find("child").get("link"): j.find("parent").get("link") for j in urdf.findall("joint")}
    assert parent["base_link"] == "support_link"
    for _, msg in doc["/tf"]["messages"][:5]:
        for t in msg["transforms"]:
            c, a = t["child_frame_id"], t["parent_frame_id"]
            assert parent.setdefault(c, a) == a, f"{c} has two parents: {parent[c]} and {a}"
    top = {f for f in set(parent.values()) if f not in parent}
    assert top == {"world"} and parent["robocal_instrument"] == "base_link"
