"""Posture groups of an evaluated recording relative to the training postures (`pipeline.evaluate.postures`).

Properties over random training sets: a training posture, or one moved by less than the repeat tolerance on
every joint, is `repeated`; a posture with a joint beyond the training range by more than the margin is
`out_of_range`; a posture inside the range and farther than the tolerance from every training posture is
`new`.  The grouping reproduces FIGAROH's published counts on its TIAGo sessions (tests/test_physics_choice.py).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.evaluate.postures import GROUPS, RANGE_MARGIN, REPEAT_TOL, labels, posture_groups


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 40), st.integers(1, 8))
def test_groups_follow_their_definition(seed, m, joints):
    rng = np.random.default_rng(seed)
    q_train = rng.uniform(-2.0, 2.0, (m, joints))
    lo, hi = q_train.min(0), q_train.max(0)
    # a training posture moved by less than the tolerance on every joint: repeated
    near = q_train + rng.uniform(-0.9, 0.9, q_train.shape) * REPEAT_TOL
    assert np.all(posture_groups(q_train, q_train) == 0) and np.all(posture_groups(q_train, near) == 0)
    # one joint beyond the widened range: out of range
    far = q_train[rng.integers(0, m, 10)].copy()
    j = rng.integers(0, joints, 10)
    side = rng.choice([-1.0, 1.0], 10)
    far[np.arange(10), j] = np.where(side > 0, hi[j], lo[j]) + side * (RANGE_MARGIN + rng.uniform(1e-3, 0.5, 10))
    assert np.all(posture_groups(q_train, far) == 2)
    # inside the range, every joint of it more than the tolerance from every training posture on some joint
    q = rng.uniform(lo, hi, (200, joints))
    d = np.abs(q[:, None, :] - q_train[None]).max(axis=2).min(axis=1)
    g = posture_groups(q_train, q)
    assert np.all(g[d > REPEAT_TOL] == 1) and np.all(g[d <= REPEAT_TOL] == 0)
    assert set(labels(q_train, q)) <= set(GROUPS)


def test_joint_count_mismatch_and_no_training_postures_are_errors():
    with pytest.raises(ValueError, match="joints"):
        posture_groups(np.zeros((3, 6)), np.zeros((2, 7)))
    with pytest.raises(ValueError, match="no training postures"):
        posture_groups(np.zeros((0, 6)), np.zeros((2, 6)))


def test_blocks_give_the_same_groups_as_one_comparison():
    """More postures than one block (256): the blockwise search equals the whole pairwise comparison."""
    rng = np.random.default_rng(3)
    q_train = rng.uniform(-1, 1, (50, 3))
    q = np.vstack([q_train[rng.integers(0, 50, 300)] + rng.normal(0, 0.004, (300, 3)), rng.uniform(-1.2, 1.2, (300, 3))])
    d = np.abs(q[:, None, :] - q_train[None]).max(axis=2).min(axis=1)
    inside = np.all((q >= q_train.min(0) - RANGE_MARGIN) & (q <= q_train.max(0) + RANGE_MARGIN), axis=1)
    assert np.array_equal(posture_groups(q_train, q), np.where(d <= REPEAT_TOL, 0, np.where(inside, 1, 2)))
