"""ROS 2 bags in: real bags written by rosbags' own writer (MCAP and SQLite3 storage)
from a simulated URDF robot with a known truth.

The bag calibrates to the noise; joint names in another order and extra joints change nothing; a
measurement taken while moving is reported and left out; PoseStamped works; the standstill pairing
agrees with a plain per-measurement reference; bad input (no JointState topic, a topic of another
type, joint names matching none of the URDF's, a missing chain joint, CDR that does not decode) is
one line naming file, topic and record, exit 2, no traceback; the real URDFs of ../shared/real-data
(Panda, UR10e) go through a synthetic bag.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli
from pipeline.importers import standstill
from pipeline.ros2.kind import ros2_kind
from pipeline.models import urdf
from pipeline.simulate.ros2_bag import JOINT_STATE, BagLayout, simulate_bag
from test_bad_input import assert_one_line_error
from test_urdf_import import REAL, needs_real
from test_urdf_simulate import R6T

NOISE_M = 2e-5  # tracker noise, 1σ per axis
FAST = "ingest,validate,identify"


@pytest.fixture
def robot(tmp_path) -> tuple[Path, object]:
    p = tmp_path / "r6.urdf"
    p.write_text(R6T)
    return p, urdf.parse(R6T, "b", "tcp")


def bag_of(tmp_path: Path, desc, name: str = "bag", **kw) -> dict:
    layout = kw.pop("layout", BagLayout())
    return simulate_bag(tmp_path / name, desc, layout=layout, **kw)


def robot_args(urdf_path: Path, root: str = "b", tip: str = "tcp") -> list:
    return ["--urdf", urdf_path, "--root", root, "--tip", tip]


def campaign_of(rec: Path) -> dict:
    from pipeline.recording.reader import read_recording
    from pipeline.recording.schemas import META_CAMPAIGN

    return read_recording(rec).metadata[META_CAMPAIGN]


# ----- the bag calibrates ------------------------------------------------------------------------
def test_run_on_a_bag_recovers_the_truth_and_excludes_the_moving_measurement(tmp_path, robot):
    """`robocal run BAG` with joint names reversed, two extra joints, encoder noise and one
    measurement taken mid-move: that one is reported and left out; the rest pair with the true
    stops to the encoder noise and calibrate to the tracker noise."""
    upath, desc = robot
    layout = BagLayout(noise_q_rad=1e-5, name_order=(5, 4, 3, 2, 1, 0), extra_joints={"gripper": 0.02, "lift": 0.1},
                       moving=(5,))
    truth = bag_of(tmp_path, desc, n=40, seed=2, noise_m=NOISE_M, layout=layout)
    proc = run_cli("run", tmp_path / "bag", *robot_args(upath), "--measure-topic", "/tracker/point",
                   "--out", tmp_path / "run", "--stages", FAST)
    assert proc.returncode == 0, proc.stderr
    assert "39 paired, 1 taken while moving" in proc.stderr
    assert "/tracker/point record 5 at" in proc.stderr and "moving" in proc.stderr
    assert "ignored joints: gripper, lift" in proc.stderr
    rec = tmp_path / "run" / "import" / "recording.mcap"
    camp = campaign_of(rec)
    p = camp["ros2"]["pairing"]
    assert (p["window_s"], p["max_speed_rad_s_or_m_s"], p["n_paired"], p["n_moving"]) == (0.5, 0.01, 39, 1)
    assert p["moving"][0]["index"] == 5 and p["moving"][0]["speed"] > 0.1
    assert camp["ros2"]["frame_id"] == "tracker" and camp["source_files"] == [str(tmp_path / "bag")]
    # the paired joint positions are the true stops (the mean of ~50 noisy readings)
    from pipeline.recording.reader import read_recording

    msgs = read_recording(rec).messages["/measure/point"]
    q = np.array([m["joint_positions"] for m in msgs])
    np.testing.assert_allclose(q, np.delete(truth["q_stops"], 5, axis=0), atol=1e-5)
    res = json.loads((tmp_path / "run" / "results.json").read_text())["summary"]
    assert res["n_measurements"] == 39
    assert res["rms_after_m"] < 1.3 * NOISE_M
    assert res["holdout_rms_m"] < 2.0 * NOISE_M, res["holdout_rms_m"]
    # a second run re-imports bit-identically: every stage after the import is cached
    again = run_cli("run", tmp_path / "bag", *robot_args(upath), "--measure-topic", "/tracker/point",
                    "--out", tmp_path / "run", "--stages", FAST)
    assert again.returncode == 0 and "every stage cached" in again.stderr, again.stderr


def test_pose_stamped_from_sqlite3_storage(tmp_path, robot):
    """PoseStamped on a .db3 bag: `robocal import ros2` on the storage file, then calibrate."""
    upath, desc = robot
    layout = BagLayout(measure_topic="/probe/pose", frame_id="probe", noise_q_rad=1e-5)
    truth = bag_of(tmp_path, desc, measure="pose", n=30, seed=4, noise_m=NOISE_M, noise_rad=1e-4,
                   layout=layout, storage="sqlite3")
    assert truth["storage"].suffix == ".db3" and ros2_kind(truth["storage"]) == "sqlite3"
    out = tmp_path / "pose.mcap"
    proc = run_cli("import", "ros2", truth["storage"], *robot_args(upath), "--out", out,
                   "--sigma-m", NOISE_M, "--sigma-rad", 1e-4)
    assert proc.returncode == 0, proc.stderr
    assert "30 paired, 0 taken while moving" in proc.stderr
    assert campaign_of(out)["measure"] == "pose"
    run = run_cli("run", out, "--out", tmp_path / "run", "--stages", FAST)
    assert run.returncode == 0, run.stderr
    res = json.loads((tmp_path / "run" / "results.json").read_text())["summary"]
    assert res["n_measurements"] == 30 and res["holdout_rms_m"] < 2.0 * NOISE_M, res


def test_ros2_bags_are_recognised_and_not_misread_as_recordings(tmp_path, robot):
    upath, desc = robot
    truth = bag_of(tmp_path, desc, n=6, seed=1)
    assert ros2_kind(tmp_path / "bag") == "folder" and ros2_kind(truth["storage"]) == "mcap"
    assert ros2_kind(Path(__file__).resolve().parents[1] / "recordings" / "arc-welder-touch.mcap") is None
    for args in (["run", truth["storage"], "--out", tmp_path / "r"], ["calibrate", truth["storage"], "--out", tmp_path / "c"]):
        assert_one_line_error(run_cli(*args), str(truth["storage"]), "is a ROS 2 bag", "--urdf")
    rec = Path(__file__).resolve().parents[1] / "recordings" / "arc-welder-touch.mcap"
    assert_one_line_error(run_cli("run", rec, *robot_args(upath), "--out", tmp_path / "w"), "is not a ROS 2 bag")
    # an MCAP of CDR channels under another profile is recognised too (rosbags then names the profile)
    from mcap.writer import Writer

    other = tmp_path / "other.mcap"
    with open(other, "wb") as f:
        w = Writer(f)
        w.start(profile="x-custom", library="test")
        sid = w.register_schema(name=JOINT_STATE, encoding="ros2msg", data=b"")
        w.register_channel(topic="/joint_states", message_encoding="cdr", schema_id=sid)
        w.finish()
    assert ros2_kind(other) == "mcap"
    assert_one_line_error(_import(tmp_path, upath, other), str(other), "cannot read as a ROS 2 bag", "ros2")
    # the storage file alone (no metadata.yaml) reads the same
    proc = run_cli("import", "ros2", truth["storage"], *robot_args(upath), "--out", tmp_path / "a.mcap")
    assert proc.returncode == 0, proc.stderr
    assert "imported 6 point measurements" in proc.stderr


@pytest.mark.parametrize("zero,args,warned", [((), ("--time", "log"), False), (("/tracker/point",), (), True)])
def test_clocks_offset_and_missing_stamps_still_pair(tmp_path, robot, zero, args, warned):
    """The tracker's clock 80 ms off the controller's changes nothing while the robot stands still;
    a topic without header stamps falls back to receive times (with a warning when the other topic
    has stamps); `--time log` uses receive times for both."""
    upath, desc = robot
    truth = bag_of(tmp_path, desc, n=8, seed=6, layout=BagLayout(clock_offset_s=0.08, zero_stamps=zero, moving=(2,)))
    proc = _import(tmp_path, upath, tmp_path / "bag", *args)
    assert proc.returncode == 0, proc.stderr
    assert "7 paired, 1 taken while moving" in proc.stderr
    assert ("receive time" in proc.stderr) == warned, proc.stderr
    camp = campaign_of(tmp_path / "out.mcap")["ros2"]
    assert camp["time_measurements"] == ("receive time" if zero or args else "header.stamp")
    from pipeline.recording.reader import read_recording

    q = np.array([m["joint_positions"] for m in read_recording(tmp_path / "out.mcap").messages["/measure/point"]])
    np.testing.assert_allclose(q, np.delete(truth["q_stops"], 2, axis=0), atol=1e-12)


# ----- bad input: one line naming file, topic and record -----------------------------------------
def _import(tmp_path: Path, upath: Path, bag: Path, *extra) -> object:
    return run_cli("import", "ros2", bag, *robot_args(upath), "--out", tmp_path / "out.mcap", *extra)


@pytest.mark.parametrize("layout,args,needles", [
    (BagLayout(drop_joint="j3"), (), ("topic /joint_states: record 0", "chain joint(s) j3 missing")),
    (BagLayout(rename={f"j{i}": f"joint_{i}" for i in range(1, 7)}), (),
     ("topic /joint_states", "match none of the URDF chain's", "joint_1")),
    (BagLayout(joint_topic=None), (), ("no sensor_msgs/msg/JointState topic", "/tracker/point")),
    (BagLayout(), ("--joint-topic", "/tracker/point"),
     ("topic /tracker/point", "is geometry_msgs/msg/PointStamped, expected sensor_msgs/msg/JointState")),
    (BagLayout(), ("--measure-topic", "/joint_states"),
     ("topic /joint_states", "is sensor_msgs/msg/JointState, expected geometry_msgs/msg/PointStamped")),
    (BagLayout(), ("--measure", "pose"), ("topic /tracker/point", "has no orientation")),
    (BagLayout(corrupt=("/joint_states", 7)), (), ("topic /joint_states: record 7", "CDR does not decode")),
    (BagLayout(corrupt=("/tracker/point", 2)), (), ("topic /tracker/point: record 2", "CDR does not decode")),
])
def test_bad_bag_is_one_line(tmp_path, robot, layout, args, needles):
    upath, desc = robot
    bag_of(tmp_path, desc, n=6, seed=3, layout=layout)
    proc = _import(tmp_path, upath, tmp_path / "bag", *args)
    assert_one_line_error(proc, str(tmp_path / "bag"), *needles)
    assert not (tmp_path / "out.mcap").exists()


def test_not_a_bag_and_all_moving_are_one_line(tmp_path, robot):
    upath, desc = robot
    (tmp_path / "junk.db3").write_bytes(b"SQLite format 3\x00" + b"\x00" * 200)
    assert_one_line_error(_import(tmp_path, upath, tmp_path / "junk.db3"), "junk.db3", "cannot read as a ROS 2 bag")
    bag_of(tmp_path, desc, n=4, seed=3, layout=BagLayout(moving=(0, 1, 2, 3)))
    assert_one_line_error(_import(tmp_path, upath, tmp_path / "bag"), "topic /tracker/point",
                          "none of the 4 measurements", "4 moving")


# ----- the pairing itself ---------------------------------------------------------------------
def _reference(t, q, tm, w, vmax):
    """Plain loops over measurements and samples: the rule of `standstill` as written in its docstring."""
    out = []
    for x in tm:
        lo, hi = x - w / 2, x + w / 2
        inside = [k for k in range(len(t)) if lo <= t[k] <= hi]
        span = [k for k in range(len(t) - 1) if t[k + 1] >= lo and t[k] <= hi]
        ok = bool(inside) and t[0] <= lo and t[-1] >= hi and max(t[k + 1] - t[k] for k in span) <= w
        if not ok:
            out.append(("uncovered", None))
            continue
        v = max((q[inside, j].max() - q[inside, j].min()) / w for j in range(q.shape[1]))
        out.append(("still" if v <= vmax else "moving", q[inside].mean(0)))
    return out


@pytest.mark.parametrize("seed", range(5))
def test_standstill_agrees_with_a_plain_reference(seed):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.choice([0.01, 0.02, 0.7], 600, p=[0.9, 0.08, 0.02]))  # 100 Hz with dropped samples and long gaps
    q = np.cumsum(rng.normal(0, 1, (600, 3)) * (rng.random((600, 1)) < 0.02) * 0.01, axis=0)  # holds, then steps
    tm = rng.uniform(t[0] - 1, t[-1] + 1, 80)
    p = standstill.pair(t, q, tm, 0.3, 0.02)
    for i, (kind, qm) in enumerate(_reference(t, q, tm, 0.3, 0.02)):
        assert (p.still[i], p.moving[i], p.uncovered[i]) == (kind == "still", kind == "moving", kind == "uncovered")
        if kind == "still":
            np.testing.assert_allclose(p.q[i], qm, atol=1e-12)
    assert p.still.any() and p.moving.any() and p.uncovered.any()


def test_standstill_excludes_a_creep_above_the_threshold():
    t = np.arange(0, 10, 0.01)
    q = np.where(t[:, None] < 5, 0.0, (t[:, None] - 5) * 0.02)  # still, then 0.02 rad/s
    p = standstill.pair(t, q, np.array([2.0, 7.0]), 0.5, 0.01)
    assert p.still.tolist() == [True, False] and p.moving.tolist() == [False, True]
    assert abs(p.speed[1] - 0.02) < 1e-9


# ----- the real robots' URDFs ------------------------------------------------------------------
@needs_real
@pytest.mark.parametrize("which", ["panda", "ur10"])
def test_real_urdf_through_a_synthetic_bag(tmp_path, which):
    """The Panda's URDF (with its two finger joints in the JointState, as a Panda publishes them) and
    the UR10e's (names in the driver's alphabetical order) driven through a bag, calibrated to noise."""
    if which == "panda":
        path, root, tip = REAL / "mukca_panda/urdf/panda.urdf", "panda_link0", "ball_link"
        extra = {"panda_finger_joint1": 0.04, "panda_finger_joint2": 0.04}
    else:
        path, root, tip = REAL / "figaroh_ur10_pose/ur10_robot.urdf", "base_link", "tool0"
        extra = {}
    if not path.is_file():
        pytest.skip(f"{path} is absent")
    desc = urdf.read(path, root, tip)
    order = tuple(int(i) for i in np.argsort(desc.joint_names))
    truth = bag_of(tmp_path, desc, n=40, seed=5, noise_m=NOISE_M,
                   layout=BagLayout(noise_q_rad=1e-5, name_order=order, extra_joints=extra, moving=(7,)))
    proc = run_cli("run", tmp_path / "bag", "--urdf", path, "--root", root, "--tip", tip, "--out", tmp_path / "run",
                   "--stages", FAST)
    assert proc.returncode == 0, proc.stderr
    assert "39 paired, 1 taken while moving" in proc.stderr
    res = json.loads((tmp_path / "run" / "results.json").read_text())["summary"]
    assert res["n_measurements"] == 39 and res["holdout_rms_m"] < 2.0 * NOISE_M, res
    assert len(truth["q_stops"][0]) == len(desc.joint_names)
