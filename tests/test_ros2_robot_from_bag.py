"""`robocal import ros2` without --urdf: the robot read from the bag's own /robot_description (latched by
robot_state_publisher while recording), or from a .xacro expanded by the xacro package; and the bag
opened once, each message decoded once (rosbags' Reader.open and deserialize_cdr counted).  Bags written
by rosbags' own Writer from a simulated 6R robot."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from conftest import run_cli
from pipeline.models import urdf
from pipeline.simulate.ros2_bag import BagLayout, simulate_bag
from test_urdf_simulate import R6T

XACRO = R6T.replace('<robot name="', '<robot xmlns:xacro="http://www.ros.org/wiki/xacro" name="', 1)


def _xacro(text: str) -> str:
    """The URDF written as xacro: its first joint origin's z through a property, its tcp joint through a macro."""
    import re

    m = re.search(r'<origin xyz="([-\d.e]+) ([-\d.e]+) ([-\d.e]+)"', text)
    x, y, z = m.groups()
    text = text.replace(m.group(0), f'<origin xyz="{x} {y} ${{base_height}}"', 1)
    return text.replace("<link ", f'<xacro:property name="base_height" value="{z}"/>\n  <link ', 1)


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    d = tmp_path_factory.mktemp("robotbag")
    desc = urdf.parse(R6T, "b", "tcp")
    simulate_bag(d / "with", desc, n=8, seed=2, layout=BagLayout(rate_hz=50.0, description=R6T))
    simulate_bag(d / "without", desc, n=8, seed=2, layout=BagLayout(rate_hz=50.0))
    (d / "r6.urdf").write_text(R6T)
    (d / "r6.urdf.xacro").write_text(_xacro(XACRO))
    return d


def _table(rec):
    from pipeline.recording.reader import read_recording

    r = read_recording(rec)
    return r.metadata["robocal.urdf"], r.messages["/measure/point"]


def test_the_robot_comes_from_the_bags_robot_description(bags, tmp_path):
    p = run_cli("import", "ros2", bags / "with", "--root", "b", "--tip", "tcp", "--out", tmp_path / "a.mcap")
    assert p.returncode == 0, p.stderr
    assert "imported 8 point measurements of 6 joints (b → tcp)" in p.stderr
    p = run_cli("import", "ros2", bags / "with", "--urdf", bags / "r6.urdf", "--root", "b", "--tip", "tcp",
                "--out", tmp_path / "b.mcap")
    assert p.returncode == 0, p.stderr
    (ua, ma), (ub, mb) = _table(tmp_path / "a.mcap"), _table(tmp_path / "b.mcap")
    assert ua["urdf"] == ub["urdf"] == R6T and ua["source"].endswith("#/robot_description")
    assert ma == mb


def test_no_description_and_no_urdf_is_one_line(bags, tmp_path):
    p = run_cli("import", "ros2", bags / "without", "--root", "b", "--tip", "tcp", "--out", tmp_path / "a.mcap")
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "has no /robot_description" in p.stderr and "--urdf" in p.stderr
    assert not (tmp_path / "a.mcap").exists()


def test_a_xacro_gives_the_urdf_it_expands_to(bags, tmp_path):
    p = run_cli("import", "ros2", bags / "without", "--urdf", bags / "r6.urdf.xacro", "--root", "b", "--tip", "tcp",
                "--out", tmp_path / "x.mcap")
    assert p.returncode == 0, p.stderr
    run_cli("import", "ros2", bags / "without", "--urdf", bags / "r6.urdf", "--root", "b", "--tip", "tcp",
            "--out", tmp_path / "u.mcap", check=True)
    (ux, mx), (uu, mu) = _table(tmp_path / "x.mcap"), _table(tmp_path / "u.mcap")
    a, b = urdf.parse(ux["urdf"], "b", "tcp"), urdf.parse(uu["urdf"], "b", "tcp")
    for ja, jb in zip(a.joints, b.joints):
        np.testing.assert_array_equal(ja.origin, jb.origin)
    assert mx == mu and "xacro:property" not in ux["urdf"]
    (bags / "bad.urdf.xacro").write_text(XACRO.replace("<link ", '<xacro:include filename="nowhere.xacro"/><link ', 1))
    p = run_cli("import", "ros2", bags / "without", "--urdf", bags / "bad.urdf.xacro", "--root", "b", "--tip", "tcp",
                "--out", tmp_path / "bad.mcap")
    assert p.returncode == 2 and "Traceback" not in p.stderr and "xacro cannot expand it" in p.stderr


def count_bag_reads(monkeypatch) -> tuple[list[int], Counter]:
    """From now on, count rosbags' bag opens ([n]) and CDR decodes per message type (Counter)."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys.store import Typestore

    opens, decodes = [0], Counter()
    open0, deser0 = Reader.open, Typestore.deserialize_cdr

    def counting_open(self, *a, **k):
        opens[0] += 1
        return open0(self, *a, **k)

    def counting_deserialize(self, raw, typename, *a, **k):
        decodes[typename] += 1
        return deser0(self, raw, typename, *a, **k)

    monkeypatch.setattr(Reader, "open", counting_open)
    monkeypatch.setattr(Typestore, "deserialize_cdr", counting_deserialize)
    return opens, decodes


def test_the_bag_is_opened_once_and_each_message_decoded_once(bags, tmp_path, monkeypatch):
    """One import of a bag carrying its robot: rosbags opens it once; the JointStates, the points and the one
    /robot_description message are each decoded once."""
    from rosbags.rosbag2 import Reader

    from pipeline.ros2.importer import Robot, import_bag

    opens, decodes = count_bag_reads(monkeypatch)
    done = import_bag(bags / "with", Robot(None, "b", "tcp"), tmp_path / "c.mcap")
    with Reader(bags / "with") as r:
        held = {c.msgtype: c.msgcount for c in r.connections}
    assert opens[0] == 1 + 1  # the import's one open, and the count just above
    assert dict(decodes) == held and done.n == 8


def test_an_effort_bag_goes_through_the_one_import_entry(tmp_path, monkeypatch):
    """`--measure effort` through the same entry as every bag import (`import_bag`): the robot from the bag's
    /robot_description, the bag opened once, each JointState and the description decoded once (the point
    topic not at all), the recording's encoder stream the bag's positions and efforts in the chain's order
    (the bag names them in another order, with an extra joint)."""
    from pipeline.importers.effort_recording import EffortSpec
    from pipeline.ingest.streams import joint_stream
    from pipeline.recording.reader import read_recording
    from pipeline.ros2.importer import Robot, import_bag
    from pipeline.ros2.points import BagSpec
    from pipeline.simulate.ros2_bag import write_bag

    desc = urdf.parse(R6T, "b", "tcp")
    J = len(desc.joint_names)
    rng = np.random.default_rng(7)
    t = np.arange(40) * 0.02
    q = 0.5 * np.sin(0.5 * t[:, None] + rng.uniform(-np.pi, np.pi, J))  # a motion the joints' speed limits allow
    e = rng.normal(0, 5, (40, J))
    layout = BagLayout(description=R6T, name_order=tuple(reversed(range(J))), extra_joints={"gripper": 0.01})
    write_bag(tmp_path / "eff", desc.joint_names, t, q, np.array([0.1]), np.zeros((1, 3)), None, layout, effort=e)
    opens, decodes = count_bag_reads(monkeypatch)
    lines = []
    done = import_bag(tmp_path / "eff", Robot(None, "b", "tcp"), tmp_path / "e.mcap", BagSpec(measure="effort"),
                      effort=EffortSpec(units="Nm"), say=lines.append)
    assert opens[0] == 1 and dict(decodes) == {"sensor_msgs/msg/JointState": 40, "std_msgs/msg/String": 1}
    assert done.kind == "effort" and done.n == 40 and done.robot_from.endswith("#/robot_description")
    s = joint_stream(read_recording(tmp_path / "e.mcap"))
    np.testing.assert_array_equal(s.q, q)
    np.testing.assert_array_equal(s.effort, e)
    assert lines and lines[-1].startswith("imported 40 samples of 6 joints' position and effort")
    with pytest.raises(Exception, match="apply to --measure effort only"):
        import_bag(tmp_path / "eff", Robot(None, "b", "tcp"), tmp_path / "p.mcap", effort=EffortSpec(units="Nm"))
    # `robocal run BAG --measure effort` imports through the same entry, with the effort declaration's options
    p = run_cli("run", tmp_path / "eff", "--root", "b", "--tip", "tcp", "--measure", "effort", "--effort-units", "Nm",
                "--out", tmp_path / "run", "--stages", "ingest")
    assert p.returncode == 0, p.stderr
    assert "imported 40 samples of 6 joints' position and effort" in p.stderr
    campaign = read_recording(tmp_path / "run" / "import" / "recording.mcap").metadata["robocal.campaign"]
    assert campaign["measure"] == "effort" and campaign["effort"]["unit"] == "N·m"
