"""Rank test: dependent and ineffective parameters are found, named and fixed."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.identify.identifiability import analyse


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), scale=st.floats(1e-3, 1e3))
def test_exact_dependency_and_zero_column(seed, scale):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(60, 5))
    J = np.column_stack([A, 2 * A[:, 1] - A[:, 3], np.zeros(60)]) * scale  # col 5 dependent, col 6 dead
    names = [f"p{i}" for i in range(7)]
    res = analyse(J, names, priority=np.array([0, 0, 0, 0, 0, 1, 0]))
    assert res.free.tolist() == [True] * 5 + [False, False]
    assert res.reasons[6].startswith("no effect")
    assert res.reasons[5].startswith("dependent: p5 ≈") and "p1" in res.reasons[5] and "p3" in res.reasons[5]


def test_priority_decides_which_member_is_kept():
    rng = np.random.default_rng(1)
    a = rng.normal(size=40)
    J = np.column_stack([a, -a, rng.normal(size=40)])
    assert analyse(J, ["a", "b", "c"], priority=np.array([1, 0, 0])).free.tolist() == [False, True, True]
    assert analyse(J, ["a", "b", "c"], priority=np.array([0, 1, 0])).free.tolist() == [True, False, True]


def test_user_fixed_parameters_are_reported():
    J = np.random.default_rng(2).normal(size=(30, 3))
    res = analyse(J, ["a", "b", "c"], fixed=np.array([False, True, False]))
    assert res.free.tolist() == [True, False, True] and res.reasons[1] == "fixed by the user"
