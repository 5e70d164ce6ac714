"""A robot with several tips in rerun, through rerun's URDF support: every link of both arms by name and
their frames read back from the .rrd with rerun's own reader (rerun.chunk.RrdReader), checked against
yourdfpy's forward kinematics of the URDF the independent humanoid generator writes (dual arm, coupled
torso driven by the others; no robocal code)."""

from __future__ import annotations

import numpy as np
import pytest
import rerun as rr

import independent_humanoid as hu
from test_rerun_rrd import _read


@pytest.fixture(scope="module")
def drawn(tmp_path_factory):
    from pipeline.models import urdf
    from pipeline.models.urdf_tree import UrdfTree
    from pipeline.visualize.robot import log_robot

    d = tmp_path_factory.mktemp("tree_rrd")
    joints, links = hu.humanoid()
    text = hu.urdf_text(joints, links)
    (d / "humanoid.urdf").write_text(text)
    tips = ("left_hand", "right_hand")
    descs = tuple(urdf.parse(text, "base", t, source="humanoid") for t in tips)
    coupled = (("torso_j3", (("torso_j1", -1.0), ("torso_j2", -1.0)), 0.0),)
    tree = UrdfTree(descs, coupled=coupled)
    q = np.column_stack([v for v in hu.postures(np.random.default_rng(4), 5).values()])
    assert tree.joint_names == hu.READ
    rec = rr.RecordingStream("robocal-test-tree")
    rec.save(str(d / "tree.rrd"))
    x = tree.nominal_vector()
    paths = log_robot(rec, tree, {"nominal": x, "calibrated": x}, q, np.arange(5) * 1_000_000_000)
    rec.flush()
    rec.disconnect()
    return d, paths, _read(d / "tree.rrd"), q


def test_every_tip_has_its_chain(drawn):
    _, paths, rrd, _ = drawn
    for which in ("nominal", "calibrated"):
        links = {e.split("/")[3] for e in rrd if e.startswith(f"world/robot_{which}/visual_geometries/")}
        assert {"left_hand", "right_hand", "base"} <= links, links
        joints = {e.split("/")[3] for e in rrd if e.startswith(f"world/robot_{which}/joints/")}
        assert {"torso_j1", "torso_j2", "torso_j3"} | {f"right_j{i}" for i in range(1, 7)} <= joints


def test_links_are_where_yourdfpy_places_them(drawn):
    yourdfpy = pytest.importorskip("yourdfpy")
    from rrd_frames import pose, read_frames

    d, _, _, q = drawn
    u = yourdfpy.URDF.load(str(d / "humanoid.urdf"), load_meshes=False)
    static, timed = read_frames(d / "tree.rrd")
    checked = 0
    for i in range(len(q)):
        cfg = dict(zip(hu.READ, q[i]))
        cfg["torso_j3"] = -cfg["torso_j1"] - cfg["torso_j2"]
        u.update_cfg(cfg)
        for link in ("left_hand", "right_hand"):
            got = pose(static, timed, f"calibrated/{link}", "tf#/world", i)
            np.testing.assert_allclose(got[:3, 3], u.get_transform(link, "base")[:3, 3], atol=1e-5)
            checked += 1
    assert checked == 2 * len(q)
