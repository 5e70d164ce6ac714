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


def test_meshes_where_package_paths_resolve_primitives_otherwise(tmp_path, monkeypatch):
    """A link whose package:// mesh is found under --mesh-path (or ROS_PACKAGE_PATH) is drawn with that mesh
    (rerun's Asset3D / Mesh3D from the STL); one whose mesh is not found, as primitives (cylinder, sphere)."""
    from rrd_frames import read_frames

    from pipeline.models import urdf
    from pipeline.models.urdf_arm import UrdfArm
    from pipeline.visualize.robot import log_robot

    stl = tmp_path / "pkgs" / "demo" / "meshes" / "l1.stl"
    stl.parent.mkdir(parents=True)
    stl.write_text("solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 0.1 0 0\n   vertex 0 0.1 0\n"
                   "  endloop\n endfacet\nendsolid t\n")
    text = """<robot name="two"><link name="base"/><link name="l1"><visual><geometry>
      <mesh filename="package://demo/meshes/l1.stl"/></geometry></visual></link>
      <link name="l2"><visual><geometry><mesh filename="package://missing/l2.stl"/></geometry></visual></link>
      <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
        <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
      <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.4 0 0"/><axis xyz="0 1 0"/>
        <limit lower="-3" upper="3" effort="1" velocity="1"/></joint></robot>"""
    arm = UrdfArm(urdf.parse(text, "base", "l2"))
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    for name, kw in (("found", {"mesh_path": [tmp_path / "pkgs"]}), ("missing", {})):
        rec = rr.RecordingStream(f"robocal-test-mesh-{name}")
        rec.save(str(tmp_path / f"{name}.rrd"))
        x = arm.nominal_vector()
        log_robot(rec, arm, {"calibrated": x}, np.zeros((2, 2)), np.arange(2) * 1_000_000_000, **kw)
        rec.flush()
        rec.disconnect()
        rrd = _read(tmp_path / f"{name}.rrd")
        l1 = {k: v for k, v in rrd.items() if k.startswith("world/robot_calibrated/visual_geometries/l1/")}
        comps = {c for v in l1.values() for c in v["static"]}
        if name == "found":
            assert any(c.startswith(("Asset3D:", "Mesh3D:")) for c in comps), comps
        else:
            assert any(c.startswith("Cylinders3D:") for c in comps), comps
        l2 = {c for k, v in rrd.items() if k.startswith("world/robot_calibrated/visual_geometries/l2/") for c in v["static"]}
        assert any(c.startswith("Ellipsoids3D:") or c.startswith("Cylinders3D:") for c in l2), l2
        static, timed = read_frames(tmp_path / f"{name}.rrd")
        assert timed["calibrated/l2"][0] == "calibrated/l1"
