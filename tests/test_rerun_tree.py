"""A robot with several tips in rerun: every chain of the tree drawn, read back from the .rrd with
rerun's own reader (rerun.chunk.RrdReader) and checked against yourdfpy's forward kinematics of the
URDF the independent humanoid generator writes (dual arm, coupled torso; no robocal code)."""

from __future__ import annotations

import numpy as np
import pytest
import rerun as rr
from scipy.spatial.transform import Rotation

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
        for tip in ("left_hand", "right_hand"):
            for part in ("links", "joints", "tool"):
                assert f"world/robot/{which}/{tip}/{part}" in rrd, (which, tip, part)
    # the torso both chains share is drawn once, with the first chain
    left = rrd["world/robot/calibrated/left_hand/joints"]["static"]["Points3D:labels"]
    right = rrd["world/robot/calibrated/right_hand/joints"]["static"]["Points3D:labels"]
    assert {"torso_j1", "torso_j2", "torso_j3"} <= set(left) and not {"torso_j1", "torso_j3"} & set(right)
    assert {f"right_j{i}" for i in range(1, 7)} <= set(right)


def test_capsules_join_the_links_yourdfpy_places(drawn):
    yourdfpy = pytest.importorskip("yourdfpy")
    d, _, rrd, q = drawn
    u = yourdfpy.URDF.load(str(d / "humanoid.urdf"), load_meshes=False)
    checked = 0
    for tip in ("left_hand", "right_hand"):
        e = rrd[f"world/robot/calibrated/{tip}/links"]
        labels = e["static"]["Capsules3D:labels"]
        n, m = len(q), len(labels)
        tr = np.array(e["rows"]["Capsules3D:translations"], float).reshape(n, m, 3)
        qt = np.array(e["rows"]["Capsules3D:quaternions"], float).reshape(n, m, 4)
        L = np.array(e["rows"]["Capsules3D:lengths"], float).reshape(n, m)
        end = tr + Rotation.from_quat(qt.reshape(-1, 4)).apply([0, 0, 1]).reshape(n, m, 3) * L[..., None]
        order = np.argsort(e["index"]["time"])
        for i, k in enumerate(order):
            cfg = dict(zip(hu.READ, q[i]))
            cfg["torso_j3"] = -cfg["torso_j1"] - cfg["torso_j2"]
            u.update_cfg(cfg)
            for c, lab in enumerate(labels):
                a, b = lab.split(" → ")
                if b == "tool":
                    continue
                np.testing.assert_allclose(tr[k, c], u.get_transform(a, "base")[:3, 3], atol=1e-9)
                np.testing.assert_allclose(end[k, c], u.get_transform(b, "base")[:3, 3], atol=1e-6)
                checked += 1
        assert any(lab.endswith(f"→ {tip}") for lab in labels), labels
    assert checked > 40
