"""Whole-tree gravity (Pinocchio) against the independent humanoid generator's own recursion."""

from __future__ import annotations

import numpy as np
import pytest

import independent_humanoid as hu
from pipeline.errors import RobocalError
from pipeline.physics.gravity import gravity_load, has_inertials

pytest.importorskip("pinocchio")


def _setup(n=6, seed=5):
    joints, links = hu.humanoid()
    rng = np.random.default_rng(seed)
    q = {j.name: rng.uniform(*j.limit, n) for j in joints if j.kind != "fixed"}
    for name, comb in hu.COUPLED.items():
        q[name] = sum(c * q[k] for k, c in comb.items())
    return joints, links, q


def test_axial_and_lateral_load_match_the_generator():
    joints, links, q = _setup()
    urdf = hu.urdf_text(joints, links)
    load = gravity_load(urdf, hu.READ, np.column_stack([q[k] for k in hu.READ]), coupled=hu.COUPLED)
    frames = hu.link_frames(joints, q)
    M, axes = hu.gravity_moments(joints, links, frames), hu.joint_axes(joints, frames)
    for k, name in enumerate(hu.READ):
        z, e1, e2 = axes[name]
        np.testing.assert_allclose(load.axial[:, k], np.einsum("ni,ni->n", z, M[name]), atol=1e-9)
        np.testing.assert_allclose(load.lateral[:, k, 0], np.einsum("ni,ni->n", e1, M[name]), atol=1e-9)
        np.testing.assert_allclose(load.lateral[:, k, 1], np.einsum("ni,ni->n", e2, M[name]), atol=1e-9)
    # the lowest torso joint carries both arms and the head: its load is not the chain's alone
    assert np.abs(load.axial[:, 0]).max() > 20


def test_payload_on_a_hand_loads_the_torso():
    joints, links, q = _setup()
    urdf = hu.urdf_text(joints, links)
    Q = np.column_stack([q[k] for k in hu.READ])
    bare = gravity_load(urdf, hu.READ, Q, coupled=hu.COUPLED)
    loaded = gravity_load(urdf, hu.READ, Q, coupled=hu.COUPLED, payload=[(2.0, "left_hand", np.zeros(3))])
    M = hu.gravity_moments(joints, links, hu.link_frames(joints, q), payload={"left_hand": (2.0, (0, 0, 0))})
    z = hu.joint_axes(joints, hu.link_frames(joints, q))["torso_j1"][0]
    np.testing.assert_allclose(loaded.axial[:, 0], np.einsum("ni,ni->n", z, M["torso_j1"]), atol=1e-9)
    assert not np.allclose(loaded.axial[:, 0], bare.axial[:, 0])
    with pytest.raises(RobocalError, match="nowhere"):
        gravity_load(urdf, hu.READ, Q, coupled=hu.COUPLED, payload=[(1.0, "nowhere", np.zeros(3))])


def test_inertials_detected():
    joints, links = hu.humanoid()
    assert has_inertials(hu.urdf_text(joints, links))
    assert not has_inertials(hu.urdf_text(joints, [hu.Link(lk.name) for lk in links]))
