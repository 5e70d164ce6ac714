"""The independent humanoid generator is checked against two libraries that share no code with it:
yourdfpy's forward kinematics of the URDF it writes, and Pinocchio's generalised gravity of that URDF."""

from __future__ import annotations

import numpy as np
import pytest

import independent_humanoid as hu


@pytest.fixture(scope="module")
def robot(tmp_path_factory):
    d = tmp_path_factory.mktemp("humanoid")
    joints, links = hu.humanoid()
    path = d / "humanoid.urdf"
    path.write_text(hu.urdf_text(joints, links))
    return path, joints, links


def _q(joints, n, seed):
    rng = np.random.default_rng(seed)
    return {j.name: rng.uniform(*j.limit, n) for j in joints if j.kind != "fixed"}


def test_forward_kinematics_matches_yourdfpy(robot):
    yourdfpy = pytest.importorskip("yourdfpy")
    path, joints, _ = robot
    urdf = yourdfpy.URDF.load(str(path), load_meshes=False, build_scene_graph=True)
    q = _q(joints, 5, 1)
    frames = hu.link_frames(joints, q)
    for i in range(5):
        urdf.update_cfg({k: v[i] for k, v in q.items()})
        for tip in ("left_hand", "right_hand", "head"):
            np.testing.assert_allclose(frames[tip][i], urdf.get_transform(tip, "base"), atol=1e-12)


def test_whole_tree_gravity_matches_pinocchio(robot):
    pin = pytest.importorskip("pinocchio")
    path, joints, links = robot
    model = pin.buildModelFromUrdf(str(path))
    model.gravity.linear = hu.G  # Pinocchio's default is 9.81 m/s²
    data = model.createData()
    q = _q(joints, 4, 2)
    frames = hu.link_frames(joints, q)
    M = hu.gravity_moments(joints, links, frames)
    axes = hu.joint_axes(joints, frames)
    for i in range(4):
        qp = np.zeros(model.nq)
        for j in joints:
            if j.kind != "fixed":
                qp[model.joints[model.getJointId(j.name)].idx_q] = q[j.name][i]
        g = pin.computeGeneralizedGravity(model, data, qp)
        for j in joints:
            if j.kind == "fixed":
                continue
            ours = axes[j.name][0][i] @ M[j.name][i]  # gravity's torque on the subtree about the axis
            theirs = -g[model.joints[model.getJointId(j.name)].idx_v]  # the torque a motor must hold
            assert ours == pytest.approx(theirs, abs=1e-9), j.name


def test_equilibrium_converges_and_bends_down(robot):
    _, joints, links = robot
    t = hu.default_truth(np.random.default_rng(0), geometry=False)
    q = _q(joints, 50, 3)
    qd, tilt, M, step = hu.equilibrium(joints, links, q, t.compliance, t.lateral)
    assert step < 1e-9
    # gravity does positive work on the bending (τᵀCτ ≥ 0): the robot's potential energy falls
    def potential(frames):
        return sum(lk.mass * (frames[lk.name] @ np.append(lk.com, 1.0))[:, 2] for lk in links if lk.mass > 0)
    drop = potential(hu.link_frames(joints, q)) - potential(hu.link_frames(joints, qd, tilt))
    assert np.all(drop > 0)
    moved = np.linalg.norm(hu.link_frames(joints, q)["left_hand"][:, :3, 3]
                           - hu.link_frames(joints, qd, tilt)["left_hand"][:, :3, 3], axis=1)
    assert 1e-3 < moved.max() < 0.05  # millimetres to centimetres at the hand
