"""A chain's constant steps folded all at once (`chain._step_matrices`, the per-chain walk plan) give the
transforms an independent product of 4×4 matrices gives — rotations from SciPy's rotation vectors, about any
axis — and a real robot's chain at its URDF values gives Pinocchio's forward kinematics of that URDF."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from pipeline.models import chain as ch
from real_data import REAL

URDF = REAL / "figaroh_tiago_mocap" / "tiago_48_schunk.urdf"


def independent(steps: list[tuple], x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The end frame (4×4) of `steps` at parameters x and one row of joint values q, step by step."""
    T = np.eye(4)
    for st_ in steps:
        M = np.eye(4)
        if st_[0] == ch.CONST:
            M = np.asarray(st_[1], float)
        else:
            kind, axis, p, j = st_
            a = np.asarray(axis, float) / np.linalg.norm(axis)
            v = (x[p] if p >= 0 else 0.0) + (q[j] if j >= 0 else 0.0)
            if kind == ch.ROT:
                M[:3, :3] = Rotation.from_rotvec(a * v).as_matrix()
            else:
                M[:3, 3] = a * v
        T = T @ M
    return T


@st.composite
def chains(draw):
    """Random chains: constant frames, rotations and translations about any axis (frame axes too), some
    with a parameter, some with a joint, runs of several parameter steps between joints."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    steps, n_params, n_joints = [], 0, 0
    for _ in range(int(rng.integers(3, 25))):
        kind = int(rng.choice([ch.CONST, ch.ROT, ch.TRANS], p=[0.2, 0.5, 0.3]))
        if kind == ch.CONST:
            M = np.eye(4)
            M[:3, :3], M[:3, 3] = Rotation.random(random_state=rng).as_matrix(), rng.normal(0, 0.3, 3)
            steps.append((ch.CONST, M))
            continue
        axis = np.eye(3)[rng.integers(3)] if rng.random() < 0.5 else rng.normal(size=3)
        p = n_params if rng.random() < 0.7 else -1
        j = n_joints if rng.random() < 0.3 else -1
        n_params, n_joints = n_params + (p >= 0), n_joints + (j >= 0)
        steps.append((kind, axis, p, j))
    x = rng.normal(0, 0.5, n_params)
    q = rng.uniform(-3, 3, (4, n_joints))
    return steps, n_params, n_joints, x, q


@settings(max_examples=60, deadline=None)
@given(chains())
def test_the_folded_chain_matches_an_independent_product(case):
    steps, n_params, n_joints, x, q = case
    chain = ch.Chain.build(steps, n_params, n_joints)
    R, p = ch.forward(chain, x, q)
    T = np.array([independent(steps, x, qi) for qi in q])
    np.testing.assert_allclose(R, T[:, :3, :3], atol=1e-12)
    np.testing.assert_allclose(p, T[:, :3, 3], atol=1e-12)
    for s, e in chain.runs():  # each run of constant steps folded: the same product, its axes and origins
        if chain.joint[s] >= 0:
            continue
        P, ax, org = ch._constant_run(chain, x, s, e)
        Q = np.eye(4)
        for k in range(s, e):
            np.testing.assert_allclose(org[k - s], Q[:3, 3], atol=1e-12)
            np.testing.assert_allclose(ax[k - s], Q[:3, :3] @ chain.axis[k], atol=1e-12)
            Q = Q @ independent([steps[k]], x, np.zeros(n_joints))
        np.testing.assert_allclose(P, Q, atol=1e-12)


@pytest.mark.skipif(not URDF.is_file(), reason="../shared/real-data/figaroh_tiago_mocap is absent (the real TIAGo "
                    "data are not shipped with the repository)")
def test_a_real_urdf_chain_matches_pinocchio():
    pin = pytest.importorskip("pinocchio")
    from pipeline.models.urdf import read
    from pipeline.models.urdf_arm import UrdfArm

    arm = UrdfArm(read(URDF, "base_footprint", "wrist_ft_tool_link"))
    model = pin.buildModelFromUrdf(str(URDF))
    data = model.createData()
    rng = np.random.default_rng(3)
    q = rng.uniform(arm.lower, arm.upper, (20, arm.n_joints))
    R, p = arm.forward(arm.vector(), q)
    base, tip = model.getFrameId("base_footprint"), model.getFrameId("wrist_ft_tool_link")
    for i, qi in enumerate(q):
        full = pin.neutral(model)
        for name, v in zip(arm.joint_names, qi):
            full[model.joints[model.getJointId(name)].idx_q] = v
        pin.framesForwardKinematics(model, data, full)
        T = data.oMf[base].actInv(data.oMf[tip])
        np.testing.assert_allclose(p[i], T.translation, atol=1e-12)
        np.testing.assert_allclose(R[i], T.rotation, atol=1e-12)
